"""The run stream: what happens in a run as versioned JSON records, for topics and logs.

One :class:`RunStream` observer turns the run's callbacks into records (format in
the README, "Run stream") and hands each record's JSON text to its sinks with the
record's channel; at the end of every tick the sinks are flushed (the run log makes
that its durable point). The ROS sink lives in the ROS transport, the log sink in
:mod:`coordinator.runlog`; this module talks to neither ROS nor files.
"""
from __future__ import annotations

import abc
import json
import os
import re
import time
import uuid
from typing import Any, Collection, Dict, List, Optional, Sequence, Tuple

import py_trees
from py_trees.common import Status

from coordinator.context import plain
from coordinator.runevents import Change, RunObserver

__all__ = ["VERSION", "CHANNELS", "RunStream", "Sink", "node_table", "preorder", "to_json", "parse_record",
           "record_problem", "version_problem", "MAX_RECORD_BYTES"]

VERSION = 1
CHANNELS = ("tree", "status", "calls", "events", "blackboard", "end", "control")
_LONE = re.compile("[\ud800-\udfff]")  # a lone surrogate (a module's text decoded with surrogateescape)


class Sink(abc.ABC):
    """Where records go: ``write`` a record's text, ``flush`` at the end of a tick, ``close`` at the end."""

    @abc.abstractmethod
    def write(self, channel: str, text: str) -> None:
        """Take one record."""

    def flush(self) -> None:  # noqa: B027 - optional, no-op default
        """End of a tick."""

    def close(self) -> None:  # noqa: B027 - optional, no-op default
        """End of the run."""


def _default(value: Any) -> Any:
    v = plain(value)
    if v is value:
        if isinstance(value, (bytes, bytearray)):
            return list(value)
        if isinstance(value, (set, frozenset, tuple)):
            return list(value)
        return str(value)
    return v


def to_json(record: Dict[str, Any]) -> str:
    """A record as one line of JSON (values that JSON lacks become plain data or text). A lone surrogate
    in a text is written as its ``\\udXXX`` escape: UTF-8 has no encoding of it, so the log's writer and
    ROS would refuse the record."""
    text = json.dumps(record, default=_default, separators=(",", ":"), ensure_ascii=False)
    return _LONE.sub(lambda m: "\\u%04x" % ord(m.group()), text) if _LONE.search(text) else text


def _shape(b: Any) -> str:
    if isinstance(b, py_trees.composites.Sequence):
        return "sequence"
    if isinstance(b, py_trees.composites.Selector):
        return "selector"
    if isinstance(b, py_trees.composites.Parallel):
        return "parallel"
    if isinstance(b, py_trees.decorators.Decorator):
        return "decorator"
    if isinstance(b, py_trees.composites.Composite):
        return "composite"  # another composite (switch): its children are drawn under it all the same
    return "leaf"


def preorder(root: Any) -> List[Any]:
    """Every behaviour, parents before children (the ids of the run stream are these indexes)."""
    out = []
    todo = [root]
    while todo:
        b = todo.pop()
        out.append(b)
        todo.extend(reversed(b.children))
    return out


def node_table(root: Any) -> List[Dict[str, Any]]:
    """The tree's nodes depth first: id (the index), parent id, kind, shape, name, where written."""
    ids = {b: i for i, b in enumerate(preorder(root))}
    out = []
    for b, i in ids.items():
        node = getattr(b, "bmtree_node", None) or getattr(b, "node", None)
        if not hasattr(node, "kind") or not hasattr(node, "pos"):
            node = None
        shape = _shape(b)
        row: Dict[str, Any] = {"id": i, "parent": ids.get(b.parent), "kind": node.kind if node else shape,
                               "shape": shape, "name": b.name}
        if node is not None:
            row.update(file=node.pos.file, line=node.pos.line, column=node.pos.column)
            target = getattr(node.spec, "target", None)  # call and wait_event: "module.member"
            if isinstance(target, str):
                row["target"] = target
        if shape in ("sequence", "selector"):
            row["memory"] = bool(getattr(b, "memory", False))
        out.append(row)
    return out


class RunStream(RunObserver):
    """Records of one run, written to ``sinks``.

    Args:
        sinks: where the JSON texts go (a ROS publisher, a log file).
        meta: extra facts for the ``tree`` record (``inputs`` given, ``max_duration``, ``sim`` …).
    """

    def __init__(self, sinks: Sequence[Sink], meta: Optional[Dict[str, Any]] = None, run_id: str = ""):
        self.sinks = list(sinks)
        self.meta = dict(meta or {})
        self.run_id = run_id or "%s-%s" % (time.strftime("%Y%m%d-%H%M%S"), uuid.uuid4().hex[:6])
        self._ids: Dict[Any, int] = {}
        self._loops: List[Tuple[Any, int]] = []  # (for_each behaviour, its id)
        self._at: Dict[int, Tuple[int, int]] = {}  # for_each id -> (element, of) last written
        self._start = 0.0
        self._ticks = 0
        self._open = False
        self._clock: Any = None

    def _emit(self, channel: str, record: Dict[str, Any]) -> None:
        text = to_json(record)
        for s in self.sinks:
            s.write(channel, text)

    def _t(self, now: float) -> float:
        return round(now - self._start, 6)

    def on_start(self, tree: Any, root: Any, ctx: Any) -> None:
        self._start = ctx.clock.now()
        self._open = True
        nodes = node_table(root)
        self._ids = {b: i for i, b in enumerate(preorder(root))}
        from coordinator.nodes.loops import ForEach

        self._loops = [(b, i) for b, i in self._ids.items() if isinstance(b, ForEach)]
        self._at = {}
        self._clock = ctx.clock
        record: Dict[str, Any] = {
            "v": VERSION, "type": "tree", "run": self.run_id, "t": 0.0, "started": time.time(),
            "name": getattr(tree, "name", root.name),
            "path": os.path.abspath(tree.path) if getattr(tree, "path", None) else None,
            "pid": os.getpid(), "blackboard": {k: plain(v) for k, v in ctx.blackboard.items()}, "nodes": nodes}
        record.update(self.meta)
        self._emit("tree", record)
        self.flush()

    def on_tick(self, root: Any, changes: List[Change], now: float) -> None:
        self._ticks += 1
        loops = self._moved() if self._loops else []
        if changes or loops:
            ids = self._ids
            rows: List[list] = []
            for b, _old, new in changes:
                i = ids.get(b)
                if i is None:
                    continue
                if new is Status.FAILURE and b.feedback_message:
                    rows.append([i, new.value, b.feedback_message])
                else:
                    rows.append([i, new.value])
            # the run clock, not ``now``: runners differ on whether ``now`` counts from the start
            record = {"v": VERSION, "type": "tick", "run": self.run_id, "t": self._t(self._clock.now()),
                      "n": self._ticks, "changes": rows}
            if loops:
                record["loops"] = loops
            self._emit("status", record)
        self.flush()

    def _moved(self) -> List[List[int]]:
        """``[id, element, of]`` of each running for_each now at another element than last told
        (element counted from 1); one that stopped is told again when it runs again."""
        out = []
        for b, i in self._loops:
            items = getattr(b, "items", None)
            if b.status is Status.RUNNING and items:
                at = (int(getattr(b, "i", 0)) + 1, len(items))
                if self._at.get(i) != at:
                    self._at[i] = at
                    out.append([i, at[0], at[1]])
            else:
                self._at.pop(i, None)
        return out

    def on_call_start(self, record: Any) -> None:
        if self._open:
            self._emit("calls", {"v": VERSION, "type": "call_start", "run": self.run_id, "t": self._t(record.started),
                                 "call_id": record.call_id, "target": record.target,
                                 "node": self._ids.get(record.owner), "inputs": record.inputs,
                                 "timeout": getattr(record.owner, "timeout", None)})

    def on_call_end(self, record: Any) -> None:
        if self._open:
            result = record.result
            self._emit("calls", {
                "v": VERSION, "type": "call_end", "run": self.run_id, "t": self._t(record.ended),
                "call_id": record.call_id, "target": record.target, "node": self._ids.get(record.owner),
                "status": record.status, "error": record.error,
                "outputs": {k: plain(v) for k, v in record.outputs.items()},
                "answer": result.status if result is not None else None,
                "duration": round(record.duration or 0.0, 6)})

    def on_call_answer(self, record: Any) -> None:
        """The answer to a call came while the run is paused: its leaf takes it at the next tick
        (then the ``call_end``); viewers show the call as answered meanwhile."""
        if self._open and record.answered is not None:
            result = record.result
            self._emit("calls", {"v": VERSION, "type": "call_answer", "run": self.run_id,
                                 "t": self._t(record.answered), "call_id": record.call_id, "target": record.target,
                                 "node": self._ids.get(record.owner),
                                 "answer": result.status if result is not None else None,
                                 "error": getattr(result, "error", "") or ""})

    def on_event(self, event: Any, now: float) -> None:
        if self._open:
            try:
                params = {k: plain(v) for k, v in event.values.items()}
            except Exception:  # an event that breaks its definition is still worth recording
                params = {}
            self._emit("events", {"v": VERSION, "type": "event", "run": self.run_id, "t": self._t(now),
                                  "module": event.basic_mod, "event": event.event, "params": params})

    def on_blackboard_write(self, key: str, value: Any, now: float) -> None:
        if self._open:
            self._emit("blackboard", {"v": VERSION, "type": "write", "run": self.run_id, "t": self._t(now),
                                      "key": key, "value": plain(value)})

    def on_recall(self, values: List[Dict[str, Any]], now: float) -> None:
        if self._open:
            self._emit("blackboard", {"v": VERSION, "type": "recall", "run": self.run_id, "t": self._t(now),
                                      "values": [dict(v, value=plain(v["value"])) for v in values]})

    def on_notice(self, notice: Any, now: float) -> None:
        if self._open:
            record = {"v": VERSION, "type": "notice", "run": self.run_id, "t": self._t(now),
                      "what": notice.what, "text": notice.text}
            if getattr(notice, "call_id", ""):
                record["call_id"] = notice.call_id
            self._emit("events", record)

    def on_control(self, record: Any, now: float) -> None:
        if self._open:
            self._emit("control", dict(record, v=VERSION, type="control", run=self.run_id, t=self._t(now)))

    def on_end(self, result: Any) -> None:
        if not self._open:
            return
        record = {"v": VERSION, "type": "end", "run": self.run_id, "t": self._t(self._clock.now()),
                  "status": result.status.value, "reason": result.reason, "ticks": result.ticks,
                  "duration": round(result.duration, 6), "calls": len(result.calls)}
        if getattr(result, "ended", ""):   # a tree with cleanup: how root ended, how its cleanup did
            cleanup = getattr(result, "cleanup_status", None)
            record["cleanup"] = {"ended": result.ended, "status": cleanup.value if cleanup is not None else None,
                                 "reason": result.cleanup_reason, "calls": len(result.cleanup_calls),
                                 "duration": round(result.cleanup_duration or 0.0, 6)}
        self._emit("end", record)
        self._open = False
        for s in self.sinks:
            s.flush()
            s.close()

    def flush(self) -> None:
        for s in self.sinks:
            s.flush()


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
    "tick": (("n", _count, False), ("changes", _list, True), ("loops", _list, False)),
    "call_start": _CALL, "call_answer": _CALL, "call_end": _CALL[:4] + (("status", _text, True),) + _CALL[5:],
    "event": (("module", _text, False), ("event", _text, False), ("params", _mapping, False)),
    "notice": (("what", _text, True), ("text", _text, False), ("call_id", _text, False)),
    "control": (("command", _text, False), ("args", _mapping, False), ("ok", _flag, False), ("answer", _text, False),
                ("by", _text, False), ("paused", _flag, False)),
    "write": (("key", _text, True),),
    "recall": (("values", _list, False),),
    "end": (("status", _text, True), ("reason", _text, False), ("duration", _seconds, False), ("ticks", _count, False),
            ("calls", _count, False), ("cleanup", _mapping, False)),
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
    return rec, ""


_ESCAPED_SURROGATE = re.compile(r"\\u[dD][89a-fA-F]")


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
    """A tick's ``changes`` ([id, status] or [id, status, why]) and ``loops`` ([id, element, of])."""
    for row in rec["changes"]:
        if not (isinstance(row, list) and 2 <= len(row) <= 3 and _node(row[0], ids) and row[1] in STATUSES
                and (len(row) == 2 or row[2] is None or isinstance(row[2], str))):
            return "a change of the tick record is not [node id, status, why?] of a node of the tree: %s" % _shown(row)
    for row in rec.get("loops") or []:
        if not (isinstance(row, list) and len(row) == 3 and _node(row[0], ids) and _count(row[1]) and _count(row[2])):
            return "a loop of the tick record is not [node id, element, of]: %s" % _shown(row)
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
                           ("duration", _seconds)):
            if said.get(key) is not None and not check(said[key]):
                return "'cleanup' of the end record: %r must be %s, got %s" % (key, _WHAT[check], _shown(said[key]))
    if kind == "snapshot":
        return _snapshot_problem(rec, ids)
    return None
