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
import math
import os
import re
import time
import uuid
from typing import Any, Dict, List, Optional, Sequence, Tuple

import py_trees
from py_trees.common import Status

from coordinator.context import plain
from coordinator.runevents import Change, RunObserver

__all__ = ["VERSION", "CHANNELS", "RunStream", "Sink", "node_table", "preorder", "to_json", "NONFINITE"]

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


#: a float JSON has no number for (NaN, ±infinity: a sensor's std_msgs/Float64, a tree's ``.nan``) is
#: written as relaxed MongoDB Extended JSON writes it, ``{"$numberDouble": "NaN"}`` (``"Infinity"``,
#: ``"-Infinity"``): Python's bare ``NaN`` is no JSON, and a browser's ``JSON.parse``, ``jq`` and
#: roslibjs refuse the whole record; ``null`` would lose what the value was
NONFINITE = "$numberDouble"
_NONFINITE_TEXT = {"NaN": float("nan"), "Infinity": float("inf"), "-Infinity": float("-inf")}


def _nonfinite_text(value: float) -> str:
    return "NaN" if value != value else "Infinity" if value > 0 else "-Infinity"


def _finite(value: Any) -> Any:
    """``value`` with each non-finite float (also in a dict's keys, lists and tuples) as :data:`NONFINITE`."""
    if isinstance(value, float):
        return value if math.isfinite(value) else {NONFINITE: _nonfinite_text(value)}
    if isinstance(value, dict):
        return {_nonfinite_text(k) if isinstance(k, float) and not math.isfinite(k) else k: _finite(v)
                for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def _default_finite(value: Any) -> Any:
    return _finite(_default(value))


def to_json(record: Dict[str, Any]) -> str:
    """A record as one line of JSON (values that JSON lacks become plain data or text; a NaN or an
    infinity :data:`NONFINITE`'s object, which :func:`parse_record` reads back as the float). A lone
    surrogate in a text is written as its ``\\udXXX`` escape: UTF-8 has no encoding of it, so the
    log's writer and ROS would refuse the record. The one way records and the web page's data leave
    Python: the run stream's topics, the run log, the snapshots and ``watch --web``/``replay --web``."""
    try:
        text = json.dumps(record, default=_default, separators=(",", ":"), ensure_ascii=False, allow_nan=False)
    except ValueError:  # a NaN or an infinity somewhere (rare: the common record pays nothing for it)
        text = json.dumps(_finite(record), default=_default_finite, separators=(",", ":"), ensure_ascii=False,
                          allow_nan=False)
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

    def __init__(self, sinks: Sequence[Sink], meta: Optional[Dict[str, Any]] = None, run_id: str = "",
                 linger: bool = False):
        self.linger = linger   # after the end record, notices until close(): late answers to its cancels
        self._lingering = self._closed = False
        self.sinks = list(sinks)
        self.meta = dict(meta or {})
        self.run_id = run_id or "%s-%s" % (time.strftime("%Y%m%d-%H%M%S"), uuid.uuid4().hex[:6])
        self._ids: Dict[Any, int] = {}
        self._loops: List[Tuple[Any, int]] = []  # (for_each, retry or repeat behaviour, its id)
        self._at: Dict[int, Tuple[int, int]] = {}  # its id -> (element, attempt or run; of) last written
        self._resume: Dict[int, float] = {}  # a retry's id -> when its next attempt starts, last written
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
        from coordinator.nodes.decorators import Retry
        from coordinator.nodes.loops import ForEach, Repeat

        self._loops = [(b, i) for b, i in self._ids.items() if isinstance(b, (ForEach, Retry, Repeat))]
        self._at, self._resume = {}, {}
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
        waits = self._waiting() if self._loops else []
        if changes or loops or waits:
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
            if waits:
                record["waits"] = waits
            self._emit("status", record)
        self.flush()

    def _moved(self) -> List[List[int]]:
        """``[id, element, of]`` of each running for_each now at another element than last told, and of
        each running retry (repeat) at another attempt (run), counted from 1; one that stopped is told
        again when it runs again."""
        out = []
        for b, i in self._loops:
            items = getattr(b, "items", None)
            times = getattr(b, "times", None)
            at: Optional[Tuple[int, int]] = None
            if b.status is Status.RUNNING and items:
                at = (int(getattr(b, "i", 0)) + 1, len(items))
            elif b.status is Status.RUNNING and isinstance(times, int) and not isinstance(times, bool) and times > 0:
                at = (min(int(getattr(b, "runs", 0)) + 1, times), times)
            if at is not None:
                if self._at.get(i) != at:
                    self._at[i] = at
                    out.append([i, at[0], at[1]])
            else:
                self._at.pop(i, None)
        return out

    def _waiting(self) -> List[List[Any]]:
        """``[id, t]`` of each retry that began waiting its delay since last told: the run time its next
        attempt starts (the viewers count down to it)."""
        out: List[List[Any]] = []
        for b, i in self._loops:
            resume = getattr(b, "resume_at", None)
            if b.status is Status.RUNNING and isinstance(resume, (int, float)):
                if self._resume.get(i) != resume:
                    self._resume[i] = resume
                    out.append([i, self._t(resume)])
            else:
                self._resume.pop(i, None)
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
        if self._open or self._lingering:
            record = {"v": VERSION, "type": "notice", "run": self.run_id, "t": self._t(now),
                      "what": notice.what, "text": notice.text}
            if getattr(notice, "call_id", ""):
                record["call_id"] = notice.call_id
            self._emit("events", record)
            if self._lingering:   # no tick flushes it now
                self.flush()

    def on_control(self, record: Any, now: float) -> None:
        if self._open:
            self._emit("control", dict(record, v=VERSION, type="control", run=self.run_id, t=self._t(now)))

    def on_end(self, result: Any) -> None:
        if not self._open:
            return
        record = {"v": VERSION, "type": "end", "run": self.run_id, "t": self._t(self._clock.now()),
                  "status": result.status.value, "reason": result.reason, "ticks": result.ticks,
                  "duration": round(result.duration, 6), "calls": len(result.calls)}
        if getattr(result, "failed_at", ""):   # where the failure the reason names is written
            record["at"] = result.failed_at
        if getattr(result, "steered", None):   # what bmtree control changed
            record["steered"] = list(result.steered)
        if getattr(result, "ended", ""):   # a tree with cleanup: how root ended, how its cleanup did
            cleanup = getattr(result, "cleanup_status", None)
            record["cleanup"] = {"ended": result.ended, "status": cleanup.value if cleanup is not None else None,
                                 "reason": result.cleanup_reason, "calls": len(result.cleanup_calls),
                                 "duration": round(result.cleanup_duration or 0.0, 6)}
            if getattr(result, "cleanup_failed_at", ""):
                record["cleanup"]["at"] = result.cleanup_failed_at
        self._emit("end", record)
        self._open = False
        if self.linger:
            self._lingering = True
            self.flush()
        else:
            self.close()

    def close(self) -> None:
        """The end of the records: after the end record, those that came while the run still took them in
        (the answers to its cancels, a master or Blackboard node back), then the sinks are closed."""
        if self._open or self._closed:
            return   # the run has not ended (its end record comes first), or this was done
        self._lingering, self._closed = False, True
        for s in self.sinks:
            s.flush()
            s.close()

    def flush(self) -> None:
        for s in self.sinks:
            s.flush()
