"""``bmtree run``'s preflight: wait (bounded) until a first call to every module would be taken.

Its cost is about one concurrent round trip per module plus one master query: the
announcements come in one ``getParam``; the publishers of every module's own call topic
are registered with the master all at once (:func:`coordinator.sender.topic_senders`);
each module is pinged as soon as its call topic and its results are connected (a
connection to a call topic wakes the wait at once); a ping's answer on
``/function/output`` proves both directions. Waiting for that answer, not merely for a
connection, is what keeps a first call from being lost to a publisher whose subscriber
is not connected yet (a ROS pitfall).
"""
from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, Callable, Dict, Iterable, List, Mapping, Optional, Set, Tuple

from blackboard.client import blackboard_nodes, silent_blackboards
from comm import TOPIC_CALL, TOPIC_RESULT
from comm.address import node_address_problem, own_address_problem
from comm.addressing import PING_FUNCTION
from comm.errors import EnvironmentProblem
from comm.messages import FunctionCall, new_id
from modules.definition import ModuleDefinition
from modules.discovery import PARAM_ROOT, LiveModule, announced_modules, legacy_announcement, probe_nodes

if TYPE_CHECKING:
    from coordinator.ros_transport import RosTransport

__all__ = ["wait_ready", "diff_definitions", "legacy_nodes", "call_limit_warnings", "first_uses", "PING_EVERY",
           "ANNOUNCEMENTS_EVERY", "PING_PATIENCE"]

PING_EVERY = 0.25  # seconds between pings of a module that has not answered yet
ANNOUNCEMENTS_EVERY = 0.5  # seconds between master queries while modules are missing
PING_PATIENCE = 1.0  # seconds after which a module without its own topics may do with connections alone
NOTIFY_AFTER = 1.0  # seconds of waiting after which the caller is told what is missing
POLL = 0.01  # seconds between looks at the connections (connections to call topics and answers wake it sooner)


def diff_definitions(local: ModuleDefinition, live: ModuleDefinition) -> List[str]:
    """What differs between the definition a tree was checked against and the running module's."""
    out = []
    for name, fn in local.functions.items():
        other = live.functions.get(name)
        if other is None:
            out.append("function %r is not served by the running module" % name)
            continue
        if fn.concurrent != other.concurrent:  # checks and mocks assumed the local one
            out.append("function %r is %sconcurrent here, %sconcurrent in the running module" % (
                name, "" if fn.concurrent else "not ", "" if other.concurrent else "not "))
        for kind, a, b in (("input", fn.inputs, other.inputs), ("output", fn.outputs, other.outputs)):
            if [(p.name, p.rostype) for p in a] != [(p.name, p.rostype) for p in b]:
                out.append("%s %ss differ: here %s, running %s" % (name, kind, ", ".join(
                    "%s:%s" % (p.name, p.rostype) for p in a), ", ".join("%s:%s" % (p.name, p.rostype) for p in b)))
    for name, ev in local.events.items():
        other_ev = live.events.get(name)
        if other_ev is None or [(p.name, p.rostype) for p in ev.params] != [(p.name, p.rostype) for p in other_ev.params]:
            out.append("event %r differs or is missing in the running module" % name)
    return out


class _Preflight:
    """The state of one :func:`wait_ready`."""

    def __init__(self, tr: RosTransport, definitions: Optional[Mapping[str, ModuleDefinition]]):
        self.tr = tr
        self.definitions = definitions or {}
        self.pinged: Dict[str, float] = {}
        self.first_ping: Dict[str, float] = {}
        self._diffs: Dict[str, Tuple[ModuleDefinition, List[str]]] = {}  # module -> (live definition, problems)
        # this process's own address, when the others cannot reach it: what a missing connection is then
        self.own = own_address_problem()   # said once, before the problems it causes

    def definition_problems(self, live: LiveModule) -> List[str]:
        """Computed once per announced definition, not once per look."""
        local = self.definitions.get(live.name)
        if local is None:
            return []
        known = self._diffs.get(live.name)
        if known is None or known[0] is not live.definition:
            known = self._diffs[live.name] = (live.definition, diff_definitions(local, live.definition))
        return known[1]

    def announced_problems(self, live: LiveModule, answered: bool, now: float, results: Set[str]) -> List[str]:
        """Why ``live`` cannot be called yet (nothing once it answered a ping).

        A module announced without its own topics (a bmtree module older than pings
        answers one ``rejected``) is also taken once connected both ways and
        :data:`PING_PATIENCE` seconds without an answer, as an original module is. ``results``:
        the URIs of the nodes whose results reach this process.
        """
        tr, name = self.tr, live.name
        diff = self.definition_problems(live)
        if diff:
            return ["module %r runs with another definition: %s" % (name, "; ".join(diff))]
        if answered:
            return []
        call_pub = tr._route(name)
        if live.uri not in results or not call_pub.impl.has_connection(live.node):
            return ["module %r (node %s) is not connected to %s and %s yet" % (
                name, live.node, call_pub.resolved_name, TOPIC_RESULT)]
        if name not in tr._routes and now - self.first_ping.setdefault(name, now) >= PING_PATIENCE:
            return []
        if now - self.pinged.get(name, -1e9) >= PING_EVERY:
            ping = FunctionCall(name, PING_FUNCTION, [], names=[], call_id=new_id())
            with tr._cond:
                tr._pings[ping.call_id or ""] = name
            call_pub.publish(tr._String(ping.encode()))
            self.pinged[name] = now
        if live.not_ready:   # it says why it does not answer (a bridge whose C++ node is not running)
            return ["module %r (node %s) is not ready: %s" % (name, live.node, live.not_ready)]
        return ["module %r (node %s) has not answered a ping on %s" % (name, live.node, call_pub.resolved_name)]


def wait_ready(tr: RosTransport, modules: Iterable[str], timeout: float,
               definitions: Optional[Mapping[str, ModuleDefinition]] = None, blackboard: bool = False,
               legacy: Optional[Mapping[str, str]] = None, notify: Optional[Callable[[str], None]] = None,
               where: Optional[Mapping[str, str]] = None) -> None:
    """:meth:`RosTransport.wait_ready <coordinator.ros_transport.RosTransport.wait_ready>` (documented there)."""
    tr.open()
    wanted = sorted(set(modules))
    with tr._cond:  # a fresh proof each time: a module may have restarted since
        tr._ponged.difference_update(wanted)
    state = _Preflight(tr, definitions)
    start = time.monotonic()
    end = start + timeout
    given = {m: n for m, n in (legacy or {}).items() if m in wanted}
    announced: Dict[str, LiveModule] = {}
    originals: Dict[str, Tuple[str, str]] = {}
    blackboards: List[str] = []
    silent: Dict[str, Tuple[str, str]] = {}  # Blackboard nodes registered that do not answer here
    next_look = 0.0
    while True:
        now = time.monotonic()
        with tr._cond:
            answered = set(tr._ponged)
        if now >= next_look and set(wanted) - answered:
            every = announced_modules()
            announced = {n: m for n, m in every.items() if not m.legacy and n not in given}
            originals = {n: (m.node, m.uri) for n, m in every.items() if m.legacy and n in wanted and n not in given}
            originals.update(legacy_nodes([n for n in wanted if n not in announced and n not in originals
                                           and n not in given]))
            originals.update(_given_nodes(given))
            blackboards, silent = blackboard_nodes()
            tr._set_routes([announced[n] for n in wanted if n in announced])
            next_look = now + ANNOUNCEMENTS_EVERY
        problems: Dict[str, List[str]] = {}
        # once per look, not once per module (rospy's has_connection walks every connection)
        results = {c.endpoint_id for c in list(tr._subs[0].impl.connections)}
        for name in wanted:
            if name in announced:
                found = state.announced_problems(announced[name], name in answered, now, results)
            elif name in originals:
                found = _legacy_problems(tr, name, *originals[name])
            elif name in given:
                found = ["the node %s given for module %r (--legacy) is not running or does not listen on %s"
                         % (given[name], name, TOPIC_CALL)]
            else:
                found = ["module %r is not running (no bmtree module announced it, and no node /%s listens on %s "
                         "as an original module's would; an original module's node of another name: --legacy %s=/node)"
                         % (name, name, TOPIC_CALL, name)]
            if found:
                problems[name] = found
        if blackboard and (tr._pubs["request"].get_num_connections() < 1 or tr._subs[2].get_num_connections() < 1):
            problems[""] = [(not blackboards and silent_blackboards(silent))
                            or "the Blackboard node is not running or not connected"]
        # a Blackboard node learns the pending calls from /master/output (to store original
        # modules' results under their call): it must hear the first call too
        for bb in blackboards:
            if not tr._shared("call").impl.has_connection(bb):
                problems["~" + bb] = ["waiting for the Blackboard node %s to connect to %s" % (bb, TOPIC_CALL)]
        if not problems:
            tr.node_modules = {m.node: n for n, m in announced.items() if n in wanted}
            tr.node_modules.update({node: n for n, (node, _uri) in originals.items()})
            _announce_legacy({n: node for n, (node, _uri) in originals.items()}, definitions or {})
            return
        if notify is not None and start + NOTIFY_AFTER <= time.monotonic() <= end - NOTIFY_AFTER / 2:
            _explain(problems, announced)  # killed, or misaddressed, not slow
            notify("waiting up to %.3g s more (--wait): %s%s ..." % (
                max(0.0, end - time.monotonic()), "%s; so: " % state.own if state.own is not None else "",
                "; ".join(p for name in sorted(problems) for p in problems[name])))
            notify = None
        if time.monotonic() >= end:
            _explain(problems, announced)
            hint = str(state.own or "")
            at = where or {}
            said = "; ".join("%s: %s" % (at[name], p) if name in at else p
                             for name in sorted(problems) for p in problems[name])
            # this process's own address first, once: it is why the others are not connected (it was said
            # after each of them, a line of 1,500 characters for four modules)
            raise EnvironmentProblem("%s; so: %s" % (hint, said) if hint else said)
        with tr._cond:
            tr._cond.wait(POLL)


def _explain(problems: Dict[str, List[str]], announced: Mapping[str, LiveModule]) -> None:
    """Say in ``problems`` which of the modules and Blackboard nodes waited for are gone, and which
    cannot be reached because of their address, rather than not connected yet."""
    problems.update(_dead([announced[n] for n in problems if n in announced]))
    problems.update(_misaddressed_blackboards([n[1:] for n in problems if n.startswith("~")]))


def _misaddressed_blackboards(nodes: List[str]) -> Dict[str, List[str]]:
    """The Blackboard nodes waited for whose registered address cannot be reached (a wrong ROS_IP on
    their machine): keyed as in :func:`wait_ready`'s problems."""
    if not nodes:
        return {}
    import rosgraph

    from comm.rpc import master_api

    master = master_api("/bmtree_ready")
    uris = {}
    for node in nodes:
        try:
            uris[node] = master.lookupNode(node)
        except (rosgraph.masterapi.Error, OSError):
            continue
    out = {}
    for (node, uri), failure in zip(uris.items(), probe_nodes(list(uris.values()), 1.0)):
        why = node_address_problem(node, uri, failure)
        if why:
            out["~" + node] = ["the Blackboard node cannot be reached: %s" % why]
    return out


def _dead(modules: List[LiveModule]) -> Dict[str, List[str]]:
    """Which announced modules are not running at all (a node killed hard leaves its announcement
    behind: its connections are refused), and which run but cannot be reached because of the
    address their node registered (a wrong ROS_IP on its machine, :func:`comm.address.node_address_problem`),
    all asked at once."""
    out: Dict[str, List[str]] = {}
    for m, failure in zip(modules, probe_nodes([m.uri for m in modules], 1.0)):
        why = node_address_problem(m.node, m.uri, failure)
        if why:
            out[m.name] = ["module %r cannot be reached: %s" % (m.name, why)]
        elif failure:
            out[m.name] = ["module %r is not running (node %s announced it but does not answer)" % (m.name, m.node)]
    return out


def _legacy_problems(tr: RosTransport, name: str, node: str, uri: str) -> List[str]:
    if tr._shared("call").impl.has_connection(node) and tr._subs[0].impl.has_connection(uri):
        return []
    return ["original module %r (node %s) is not connected to %s and %s yet" % (name, node, TOPIC_CALL, TOPIC_RESULT)]


def _system_state() -> Tuple[Any, Any]:
    from comm.rpc import master_api

    master = master_api("/bmtree_ready")  # bounded: a master that does not answer raises OSError
    _, subs, _ = master.getSystemState()
    return master, subs


def _given_nodes(given: Mapping[str, str]) -> Dict[str, Tuple[str, str]]:
    """Nodes named with ``--legacy MODULE=/node`` that run and listen on the call topic (node and URI)."""
    if not given:
        return {}
    import rosgraph

    master, subs = _system_state()
    listeners = next((n for t, n in subs if t == TOPIC_CALL), [])
    found = {}
    for module, node in given.items():
        try:
            if node in listeners:
                found[module] = (node, master.lookupNode(node))
        except rosgraph.masterapi.MasterError:
            pass
    return found


def _announce_legacy(found: Mapping[str, str], definitions: Mapping[str, ModuleDefinition]) -> None:
    import rospy

    for module, node in found.items():
        if module in definitions:
            rospy.set_param("%s/%s" % (PARAM_ROOT, module), legacy_announcement(node, definitions[module]))


def legacy_nodes(names: List[str]) -> Dict[str, Tuple[str, str]]:
    """Original modules do not announce themselves; they are found by node name.

    A node called ``/<module>`` (in any namespace) that subscribes to
    ``/master/output`` is taken as that module, the convention of the original
    template modules. Gives the node and its URI.
    """
    if not names:
        return {}
    import rosgraph

    master, subs = _system_state()
    listeners = next((n for t, n in subs if t == TOPIC_CALL), [])
    found = {}
    for name in names:
        for node in listeners:
            if node.rsplit("/", 1)[-1] == name:
                try:
                    found[name] = (node, master.lookupNode(node))
                except rosgraph.masterapi.MasterError:
                    continue
    return found


def call_limit_warnings(tree: Any, limits: Dict[str, float], default_timeout: float) -> List[str]:
    """Call leaves that would wait longer than their module itself does (a bridge's --call-timeout):
    the call would fail then, blaming the module, before the tree's timeout."""
    from coordinator.treeast import top_of, walk

    out = []
    for n in walk(top_of(tree)):
        fn = getattr(n.spec, "function", None) if n.nodekind.name == "call" else None
        limit = limits.get(fn.module) if fn is not None else None
        if fn is None or not limit:
            continue
        timeout = n.spec.timeout if n.spec.timeout is not None else default_timeout
        if isinstance(timeout, (int, float)) and timeout > limit:
            out.append("warning: %s: call %s waits up to %g s, but module %r gives up a call after %g s (a "
                       "bridge's --call-timeout): the call would fail then; give the module a longer limit"
                       % (n.value_pos or n.pos, fn.qualified, timeout, fn.module, limit))
    return out


def first_uses(tree: Any) -> Dict[str, str]:
    """Each module the tree uses -> where it is first used (``file:line:column``), for errors."""
    from coordinator.treeast import top_of, walk

    out: Dict[str, str] = {}
    for n in walk(top_of(tree)):
        for m in n.nodekind.modules(n):
            out.setdefault(m, str(n.value_pos or n.pos))
    return out
