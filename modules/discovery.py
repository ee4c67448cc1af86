"""Which modules run now: each module node announces itself on the parameter server.

A module writes ``/bmtree/modules/<name>`` = ``{"node": ..., "definition": <JSON>,
"uri": <its XML-RPC URI>, "call_topic": ..., "cancel_topic": ...}`` when it starts
and removes it when it stops cleanly (``uri`` and the topics are absent in the
announcements of older bmtree modules). A module killed hard leaves its parameter
behind, so a listing also pings the node's XML-RPC API, every node at once: a module
whose node does not answer is not listed, unless the reason is its address (a wrong
``ROS_IP`` on its machine, :func:`comm.address.node_address_problem`): it runs, but
cannot be reached from here (:func:`listed_modules`).
"""
from __future__ import annotations

import json
import logging
import math
import socket
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Dict, Iterable, List, Mapping, Optional, Tuple

import rosgraph

from comm.address import node_address_problem, reach
from comm.addressing import valid_topic
from comm.errors import ProtocolError
from comm.limits import check_depth
from comm.rpc import MASTER_TIMEOUT, master_api, node_alive
from modules.definition import DefinitionError, ModuleDefinition, parse_definition

__all__ = ["PARAM_ROOT", "LiveModule", "live_modules", "listed_modules", "announced_modules", "announcement",
           "legacy_announcement", "node_alive", "probe_nodes"]

PARAM_ROOT = "/bmtree/modules"

log = logging.getLogger("bmtree.discovery")


@dataclass
class LiveModule:
    name: str
    node: str
    uri: str
    definition: ModuleDefinition
    call_topic: Optional[str] = None  # None: the module takes calls only on /master/output
    cancel_topic: Optional[str] = None
    legacy: bool = False  # an original module, announced on its behalf by ``bmtree run``
    call_limit: Optional[float] = None  # seconds after which the module itself fails a call (a bridge's --call-timeout)
    not_ready: str = ""  # why it cannot take a call now, as it announces (a bridge whose C++ node is not running)


def announcement(node: str, definition: ModuleDefinition, instance: str = "",
                 topics: Optional[Mapping[str, str]] = None, uri: Optional[str] = None,
                 call_limit: Optional[float] = None) -> Dict[str, Any]:
    """The parameter a module node sets; ``instance`` tells two processes of one node name apart;
    ``topics``: its ``call_topic`` and ``cancel_topic``; ``uri``: its node's XML-RPC URI;
    ``call_limit``: seconds after which the node itself fails a call (a coordinator warns of a
    call that would wait longer)."""
    out: Dict[str, Any] = {"node": node, "definition": json.dumps(definition.to_dict())}
    if instance:
        out["instance"] = instance
    out.update(topics or {})
    if uri:
        out["uri"] = uri
    if call_limit:
        out["call_limit"] = float(call_limit)
    return out


def legacy_announcement(node: str, definition: ModuleDefinition) -> Dict[str, Any]:
    """What ``bmtree run`` writes for an original module (which does not announce itself)."""
    return dict(announcement(node, definition), legacy=True)


_PARSED: Dict[str, ModuleDefinition] = {}  # announcement text -> definition, so that waiting re-reads cheaply


def _definition(text: Any, node: str) -> ModuleDefinition:
    if not isinstance(text, str):
        raise ValueError("the announcement's definition is not text")
    found = _PARSED.get(text)
    if found is None:
        check_depth(text)
        found = parse_definition(json.loads(text), "live:%s" % node)
        if len(_PARSED) >= 512:
            _PARSED.clear()
        _PARSED[text] = found
    return found


def _topic(entry: Dict[str, Any], key: str) -> Optional[str]:
    value = entry.get(key)
    return value if valid_topic(value) else None


def _not_ready(value: Any) -> str:
    """An announcement's ``not_ready`` (bounded: it is said in a run's start-up problems), '' if none."""
    return value[:400] if isinstance(value, str) else ""


def _limit(value: Any) -> Optional[float]:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0
    return float(value) if ok else None


def announced_modules(master_uri: Optional[str] = None, timeout: float = MASTER_TIMEOUT) -> Dict[str, LiveModule]:
    """Every module announced on the master, alive or not: one master query (plus one per
    announcement of an older bmtree, which lacks ``uri``), each bounded by ``timeout`` seconds.
    Raises OSError-like errors if there is no master, ``socket.timeout`` (an OSError) saying so
    if it does not answer (its process stopped, its machine off the network)."""
    uri = master_uri or rosgraph.get_master_uri()
    master = master_api("/bmtree_discovery", timeout, uri)
    try:
        return _announced(master)
    except socket.timeout as exc:
        raise socket.timeout("the ROS master at %s did not answer within %g s (is its process stopped, or its "
                             "machine off the network?)" % (uri, timeout)) from exc


def _announced(master: Any) -> Dict[str, LiveModule]:
    try:
        params = master.getParam(PARAM_ROOT)
    except rosgraph.masterapi.MasterError:
        return {}
    found: Dict[str, LiveModule] = {}
    if not isinstance(params, dict):
        _malformed("", None, "not a mapping of module name to announcement (got %s)" % type(params).__name__)
        return found
    for name, entry in sorted(params.items()):
        if not isinstance(entry, dict):
            _malformed(name, None, "the announcement is not a mapping (got %s)" % type(entry).__name__)
            continue
        if not isinstance(entry.get("node"), str):
            _malformed(name, None, "its key 'node' is not text (got %s)" % type(entry.get("node")).__name__)
            continue
        try:
            definition = _definition(entry.get("definition"), entry["node"])
        except DefinitionError as exc:
            _malformed(name, entry["node"], "its definition is invalid: %s" % "; ".join(exc.problems[:3]))
            continue
        except (ValueError, TypeError, RecursionError, ProtocolError) as exc:
            _malformed(name, entry["node"], "its definition cannot be read (%s: %s)" % (type(exc).__name__, exc))
            continue
        odd = [key for key in ("call_topic", "cancel_topic") if entry.get(key) is not None and _topic(entry, key) is None]
        if odd:  # taken without them: its calls or cancels go to the shared topics
            _malformed(name, entry["node"], "%s: not a topic it may use (%s), so the shared one is used" % (
                " and ".join(odd), ", ".join("%.80r" % (entry[key],) for key in odd)))
        else:
            _WARNED.pop(_announcer(name, entry["node"]), None)  # (said again if it turns bad again)
        uri = entry.get("uri")
        if not isinstance(uri, str) or not uri.startswith("http"):
            try:
                uri = master.lookupNode(entry["node"])
            except rosgraph.masterapi.MasterError:
                continue
        found[name] = LiveModule(name=name, node=entry["node"], uri=uri, definition=definition,
                                 call_topic=_topic(entry, "call_topic"), cancel_topic=_topic(entry, "cancel_topic"),
                                 legacy=entry.get("legacy") is True, call_limit=_limit(entry.get("call_limit")),
                                 not_ready=_not_ready(entry.get("not_ready")))
    return found


_WARNED: Dict[Tuple[str, Optional[str]], str] = {}  # (module, node) -> what was said of its announcement


def _announcer(name: Any, node: Optional[str]) -> Tuple[str, Optional[str]]:
    return str(name)[:200], node


def _malformed(name: Any, node: Optional[str], why: str) -> None:
    """Say once per announcer (module and node) what is wrong with its announcement (skipped, or taken
    without what is wrong), not at every look: a run's preflight reads them twice a second."""
    key = _announcer(name, node)
    if key in _WARNED:
        return
    if len(_WARNED) >= 1000:
        _WARNED.clear()
    _WARNED[key] = why
    log.warning("malformed module announcement %s/%.80s%s: %.500s", PARAM_ROOT, str(name),
                " by node %s" % node if node else "", why)


def probe_nodes(uris: Iterable[str], timeout: float = 1.0) -> List[str]:
    """:func:`comm.address.reach` of every URI, all at once: "" for each node that answers, else why not."""
    uris = list(uris)
    if not uris:
        return []
    with ThreadPoolExecutor(max_workers=min(32, len(uris))) as pool:
        return list(pool.map(lambda uri: reach(uri, timeout), uris))


def listed_modules(master_uri: Optional[str] = None, timeout: float = 1.0
                   ) -> Tuple[Dict[str, LiveModule], Dict[str, Tuple[LiveModule, str]]]:
    """The announced modules whose node answers, and those whose node runs but cannot be reached
    from here because of its address (name -> (module, why): :func:`comm.address.node_address_problem`);
    a module whose node is gone is in neither. Raises OSError-like errors if there is no master."""
    found = announced_modules(master_uri)
    failures = dict(zip(found, probe_nodes([m.uri for m in found.values()], timeout)))
    unreachable: Dict[str, Tuple[LiveModule, str]] = {}
    for name, m in found.items():
        why = node_address_problem(m.node, m.uri, failures[name], master_uri) if failures[name] else ""
        if why:
            unreachable[name] = (m, why)
    return {name: m for name, m in found.items() if not failures[name]}, unreachable


def live_modules(master_uri: Optional[str] = None, timeout: float = 1.0) -> Dict[str, LiveModule]:
    """Modules running now on the master: the announced ones whose node answers, all asked
    at once (raises OSError-like errors if there is no master)."""
    found = announced_modules(master_uri)
    if not found:
        return found
    answers = probe_nodes([m.uri for m in found.values()], timeout)
    return {name: m for (name, m), failure in zip(found.items(), answers) if not failure}
