"""Reading the run stream's records back (run logs, ``bmtree watch``, the page): each record decoded
within bounds and its shape checked in this one place, so a reader skips what it cannot use instead
of half applying it; :func:`coordinator.runstream.to_json` writes them."""
from __future__ import annotations

import json
import re
from typing import Any, Collection, Dict, List, Optional, Tuple

from coordinator.runstream import _LONE, _NONFINITE_TEXT, NONFINITE, VERSION

__all__ = ["parse_record", "record_problem", "version_problem", "nonfinite_floats", "MAX_RECORD_BYTES", "STATUSES"]

# The shape of each record, checked in this one place by every reader (run logs, ``watch``): a record
# that does not fit is skipped (a log's reader says which line), never half applied.
STATUSES = ("INVALID", "RUNNING", "SUCCESS", "FAILURE")
MAX_SECONDS = 1e9            # a run's times and durations: some 30 years
LAST_START = 253402214400.0  # 9999-12-31, the last start time a clock can show
MAX_TREE_DEPTH = 200
MAX_DEPTH = 100              # nesting of a record (comm.limits': a value nested deeper is no robot's)
MAX_RECORD_BYTES = 16 << 20  # one record (a line of a log, a message of the stream)


def _text(v: Any) -> bool:
    return isinstance(v, str)


def _seconds(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and -MAX_SECONDS <= v <= MAX_SECONDS  # (not NaN)


def _when(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v <= LAST_START


def _count(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 1 << 53


def _mapping(v: Any) -> bool:
    return isinstance(v, dict)


def _list(v: Any) -> bool:
    return isinstance(v, list)


def _flag(v: Any) -> bool:
    return isinstance(v, bool)


_WHAT = {_text: "text", _seconds: "a number of seconds", _when: "a Unix time", _count: "a whole number",
         _mapping: "a mapping", _list: "a list", _flag: "true or false"}
_CALL = (("call_id", _text, True), ("target", _text, False), ("inputs", _mapping, False), ("timeout", _seconds, False),
         ("status", _text, False), ("error", _text, False), ("outputs", _mapping, False), ("answer", _text, False),
         ("duration", _seconds, False), ("started", _seconds, False))
_KEYS = {  # type -> (key, check, required); None: every record. A key that is null counts as absent.
    None: (("t", _seconds, False), ("run", _text, False)),
    "tree": (("name", _text, False), ("path", _text, False), ("started", _when, False), ("pid", _count, False),
             ("inputs", _mapping, False), ("blackboard", _mapping, False), ("nodes", _list, True),
             ("max_duration", _seconds, False), ("control", _flag, False), ("sim", _mapping, False),
             ("modules", _list, False)),
    "tick": (("n", _count, False), ("changes", _list, True), ("loops", _list, False), ("waits", _list, False)),
    "call_start": _CALL, "call_answer": _CALL, "call_end": _CALL[:4] + (("status", _text, True),) + _CALL[5:],
    "event": (("module", _text, False), ("event", _text, False), ("params", _mapping, False)),
    "notice": (("what", _text, True), ("text", _text, False), ("call_id", _text, False)),
    "control": (("command", _text, False), ("args", _mapping, False), ("ok", _flag, False), ("answer", _text, False),
                ("by", _text, False), ("paused", _flag, False)),
    "write": (("key", _text, True),),
    "recall": (("values", _list, False),),
    "end": (("status", _text, True), ("reason", _text, False), ("duration", _seconds, False), ("ticks", _count, False),
            ("calls", _count, False), ("cleanup", _mapping, False), ("at", _text, False),
            ("steered", _list, False)),
    "snapshot": (("n", _count, False), ("tick_t", _seconds, False), ("ncalls", _count, False),
                 ("status", _mapping, False), ("feedback", _mapping, False), ("last", _mapping, False),
                 ("loops", _mapping, False), ("blackboard", _mapping, False), ("args", _mapping, False),
                 ("end", _mapping, False), ("halted", _list, False), ("pending", _list, False), ("calls", _list, False),
                 ("events", _list, False), ("control", _list, False), ("written", _list, False),
                 ("stopped", _list, False), ("cut", _list, False), ("paused", _flag, False)),
}


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else type(value).__name__


def parse_record(text: str) -> Tuple[Optional[Dict[str, Any]], str]:
    """One record's JSON text decoded: (the record, '') or (None, why not), bounded before any parsing
    (its size, its nesting); a lone surrogate in a text (no UTF-8 can hold it) becomes U+FFFD. Its
    shape is :func:`record_problem`'s to check."""
    from comm.errors import ProtocolError
    from comm.limits import check_depth

    if len(text) > MAX_RECORD_BYTES:
        return None, "a record of %d characters, more than the %d one may have" % (len(text), MAX_RECORD_BYTES)
    try:
        check_depth(text, MAX_DEPTH)
        rec = json.loads(text)
    except ProtocolError:
        return None, "a record nested deeper than %d levels, too deep to be bmtree's" % MAX_DEPTH
    except (ValueError, RecursionError) as exc:
        return None, "not a JSON record: %s" % exc
    if _ESCAPED_SURROGATE.search(text):
        rec = _no_surrogates(rec)
    if _TAGGED in text:
        rec = nonfinite_floats(rec)
    return rec, ""


_ESCAPED_SURROGATE = re.compile(r"\\u[dD][89a-fA-F]")
_TAGGED = '"%s"' % NONFINITE


def nonfinite_floats(value: Any) -> Any:
    """A decoded record (or value) with each :data:`NONFINITE` object (``{"$numberDouble": "NaN"}``) the
    float it stands for, as :func:`to_json` wrote it; a log of an older bmtree has bare ``NaN``s, which
    ``json.loads`` reads as they are."""
    if isinstance(value, dict):
        if len(value) == 1 and isinstance(value.get(NONFINITE), str) and value[NONFINITE] in _NONFINITE_TEXT:
            return _NONFINITE_TEXT[value[NONFINITE]]
        return {k: nonfinite_floats(v) for k, v in value.items()}
    if isinstance(value, list):
        return [nonfinite_floats(v) for v in value]
    return value


def _no_surrogates(value: Any) -> Any:
    if isinstance(value, str):
        return _LONE.sub("\ufffd", value)
    if isinstance(value, list):
        return [_no_surrogates(v) for v in value]
    if isinstance(value, dict):
        return {_no_surrogates(k): _no_surrogates(v) for k, v in value.items()}
    return value


def version_problem(v: Any) -> Optional[str]:
    """Why a record of format version ``v`` cannot be read, or None for this bmtree's own."""
    if v == VERSION and not isinstance(v, bool):
        return None
    if isinstance(v, int) and not isinstance(v, bool) and v > VERSION:
        return "written by a newer bmtree (format version %d); this bmtree reads version %d: update bmtree to read it" % (
            v, VERSION)
    return "format version %s is not one bmtree writes (this bmtree reads version %d)" % (_shown(v), VERSION)


def _keys(rec: Dict[str, Any], keys: Any, kind: str) -> Optional[str]:
    for key, check, required in _KEYS.get(keys, ()):
        value = rec.get(key)
        if value is None:
            if required:
                return "the %s record has no %r" % (kind, key)
        elif not check(value):
            return "%r of the %s record must be %s, got %s" % (key, kind, _WHAT[check], _shown(value))
    return None


def _node(v: Any, ids: Optional[Collection[int]]) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and (ids is None or v in ids)


def _nodes_problem(nodes: List[Any]) -> Optional[str]:
    """The tree record's ``nodes``: each with a whole-number ``id``, its parent listed before it, one root."""
    depth: Dict[int, int] = {}
    for k, n in enumerate(nodes):
        if not isinstance(n, dict) or not _node(n.get("id"), None) or n["id"] in depth:
            return "node %d of the tree record is not a node with an id of its own" % k
        parent = n.get("parent")
        if (parent is None) != (k == 0) or (parent is not None and not _node(parent, depth)):
            return "node %d of the tree record: its parent %s is not a node listed before it" % (k, _shown(parent))
        for key, check in (("name", _text), ("kind", _text), ("shape", _text), ("file", _text), ("target", _text),
                           ("line", _count), ("column", _count), ("memory", _flag)):
            if n.get(key) is not None and not check(n[key]):
                return "node %d of the tree record: %r must be %s, got %s" % (k, key, _WHAT[check], _shown(n[key]))
        depth[n["id"]] = depth[parent] + 1 if parent is not None else 0
        if depth[n["id"]] > MAX_TREE_DEPTH:
            return "the recorded tree is deeper than %d levels" % MAX_TREE_DEPTH
    return None


def _rows_problem(rec: Dict[str, Any], ids: Optional[Collection[int]]) -> Optional[str]:
    """A tick's ``changes`` ([id, status] or [id, status, why]), ``loops`` ([id, element, of]) and ``waits``
    ([id, t]: a retry's next attempt)."""
    for row in rec["changes"]:
        if not (isinstance(row, list) and 2 <= len(row) <= 3 and _node(row[0], ids) and row[1] in STATUSES
                and (len(row) == 2 or row[2] is None or isinstance(row[2], str))):
            return "a change of the tick record is not [node id, status, why?] of a node of the tree: %s" % _shown(row)
    for row in rec.get("loops") or []:
        if not (isinstance(row, list) and len(row) == 3 and _node(row[0], ids) and _count(row[1]) and _count(row[2])):
            return "a loop of the tick record is not [node id, element, of]: %s" % _shown(row)
    for row in rec.get("waits") or []:
        if not (isinstance(row, list) and len(row) == 2 and _node(row[0], ids) and _seconds(row[1])):
            return "a wait of the tick record is not [node id, seconds]: %s" % _shown(row)
    return None


def _snapshot_problem(rec: Dict[str, Any], ids: Optional[Collection[int]]) -> Optional[str]:
    for key in ("status", "feedback", "last", "loops", "args"):
        for k, v in (rec.get(key) or {}).items():
            if not (str(k).isdigit() and _node(int(k), ids)) or (key == "loops" and not (
                    isinstance(v, list) and len(v) == 2 and _count(v[0]) and _count(v[1]))) or (
                    key == "args" and not _mapping(v)) or (key in ("status", "last") and v not in STATUSES):
                return "%r of the snapshot names %s, not a node of the tree, or %s" % (key, _shown(k), _shown(v))
    if not all(_node(i, ids) for i in rec.get("halted") or []):
        return "'halted' of the snapshot is not a list of nodes of the tree"
    for key, kind in (("pending", "call_start"), ("calls", "call_end"), ("events", "event"), ("control", "control")):
        for item in rec.get(key) or []:
            problem = record_problem(dict(item, type=item.get("type", kind)), ids) if isinstance(item, dict) else \
                "not a record"
            if problem is not None:
                return "%r of the snapshot: %s" % (key, problem)
    end = rec.get("end")
    return None if end is None else record_problem(dict(end, type="end"), ids)


def record_problem(rec: Any, ids: Optional[Collection[int]] = None) -> Optional[str]:
    """Why ``rec`` (a decoded record) is not one a reader can use, or None. ``ids``: the node ids of its
    run's tree (a change or call of another node is refused), None when not known. Keys and record types
    it does not know are left alone (a newer bmtree's additions)."""
    if not isinstance(rec, dict) or not isinstance(rec.get("type"), str):
        return "not a record (a JSON object with a 'type')"
    kind = rec["type"]
    if "v" in rec or kind == "tree":
        problem = version_problem(rec.get("v"))
        if problem is not None:
            return "a %s record %s" % (kind, problem)
    problem = _keys(rec, None, kind) or _keys(rec, kind, kind)
    if problem is not None:
        return problem
    if kind == "tree":
        return _nodes_problem(rec["nodes"])
    if kind == "tick":
        return _rows_problem(rec, ids)
    if kind.startswith("call_") and rec.get("node") is not None and not _node(rec["node"], ids):
        return "the %s record's node %s is not a node of the tree" % (kind, _shown(rec["node"]))
    if kind == "recall" and not all(isinstance(v, dict) for v in rec.get("values") or []):
        return "'values' of the recall record must be a list of mappings"
    if kind == "end" and rec.get("cleanup") is not None:
        said = rec["cleanup"]
        for key, check in (("ended", _text), ("status", _text), ("reason", _text), ("calls", _count),
                           ("duration", _seconds), ("at", _text)):
            if said.get(key) is not None and not check(said[key]):
                return "'cleanup' of the end record: %r must be %s, got %s" % (key, _WHAT[check], _shown(said[key]))
    if kind == "snapshot":
        return _snapshot_problem(rec, ids)
    return None
