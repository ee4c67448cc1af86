"""What a watcher knows about a run, rebuilt from run-stream records (README, "Run stream").

:class:`WatchState` applies the records of one run (live from topics, from a run log,
or from the run's own stream in-process) and can be caught up at once from a
``snapshot`` record, which the running process publishes latched and periodically
(:class:`SnapshotSink`) so that a watcher that attaches mid-run sees the present
state without the history. Plain data only: the terminal and web views draw it.
"""
from __future__ import annotations

import json
import threading
import time
from typing import Any, Callable, Dict, List, Optional

from coordinator.runstream import VERSION, Sink, to_json

__all__ = ["WatchState", "SnapshotSink", "StateSink", "SNAPSHOT_VERSION"]

SNAPSHOT_VERSION = 1
KEEP = 200  # finished calls, events and control actions kept (the latest)
OUTCOMES = ("SUCCESS", "FAILURE")


class WatchState:
    """One run as seen from outside; every method is thread-safe."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.changed = threading.Condition(self.lock)
        self.version = 0  # bumped on every applied record (the web view polls it)
        self._reset()

    def _reset(self, run: str = "") -> None:
        self._early: List[Dict[str, Any]] = getattr(self, "_early", [])
        self.run = run
        self.tree: Dict[str, Any] = {}
        self.nodes: List[Dict[str, Any]] = []
        self.status: Dict[int, str] = {}
        self.halted: Dict[int, bool] = {}
        self.feedback: Dict[int, str] = {}
        #: each node's last outcome (SUCCESS or FAILURE), kept when py_trees resets it to INVALID
        #: (a selector clears the children it moved past, a stopped tree its finished nodes)
        self.last: Dict[int, str] = {}
        #: tree-blackboard keys, least recently written first (the view keeps the newest when cut)
        self.written: List[str] = []
        self.pending: Dict[str, Dict[str, Any]] = {}
        self.calls: List[Dict[str, Any]] = []
        self.events: List[Dict[str, Any]] = []
        self.control: List[Dict[str, Any]] = []
        self.blackboard: Dict[str, Any] = {}
        self.end: Optional[Dict[str, Any]] = None
        self.paused = False
        self.t = 0.0
        self.tick = 0
        self.tick_t = 0.0  # the run's time of its last tick (or snapshot)
        self.caught_up = False

    # applying ---------------------------------------------------------------------------
    def apply_text(self, text: str) -> None:
        """One record's JSON text; a malformed one is ignored (it must never stop a watcher)."""
        try:
            rec = json.loads(text)
        except ValueError:
            return
        if isinstance(rec, dict):
            self.apply(rec)

    def apply(self, rec: Dict[str, Any]) -> None:
        with self.lock:
            try:
                self._apply(rec)
            except (TypeError, ValueError, KeyError, IndexError, AttributeError):
                return
            self.version += 1
            self.changed.notify_all()

    def _apply(self, rec: Dict[str, Any]) -> None:
        kind = rec.get("type")
        run = str(rec.get("run") or "")
        if kind == "tree":
            if run != self.run or not self.nodes:
                self._reset(run)
            self.tree = {k: v for k, v in rec.items() if k != "nodes"}
            self.nodes = [n for n in rec.get("nodes") or [] if isinstance(n, dict)]
            for key, value in (rec.get("blackboard") or {}).items():
                if str(key) not in self.blackboard:  # the same run's tree again must not undo its writes
                    self._write(str(key), value)
            early, self._early = self._early, []
            for r in early:  # records that came before the tree (topics are not ordered among them)
                if str(r.get("run") or "") == run:
                    self._apply(r)
            return
        if not self.nodes:
            if len(self._early) < 1000:
                self._early.append(rec)
            return
        if run and self.run and run != self.run:
            return  # a record of another run (an old latched one)
        if kind == "snapshot":
            if self.caught_up and int(rec.get("n") or 0) <= self.tick:
                return
            self._load(rec)
            return
        self.t = max(self.t, float(rec.get("t") or 0.0))
        if kind == "tick":
            n = int(rec.get("n") or 0)
            if n and n <= self.tick:
                return  # already in the snapshot
            self.tick = n or self.tick + 1
            self.tick_t = self.t
            for change in rec.get("changes") or []:
                i, new = int(change[0]), str(change[1])
                old = self.status.get(i, "INVALID")
                self.halted[i] = new == "INVALID" and old == "RUNNING"
                self.status[i] = new
                if new in OUTCOMES:
                    self.last[i] = new
                if new != "INVALID" or old not in OUTCOMES:  # a reset keeps why it failed, for "was FAILURE"
                    self.feedback[i] = str(change[2]) if len(change) > 2 else ""
        elif kind == "call_start":
            self.pending[str(rec.get("call_id"))] = rec
        elif kind == "call_end":
            start = self.pending.pop(str(rec.get("call_id")), None)
            if not any(c.get("call_id") == rec.get("call_id") for c in self.calls[-20:]):
                self.calls.append(dict(rec, started=(start or {}).get("t", rec.get("t"))))
                del self.calls[:-KEEP]
        elif kind == "write":
            self._write(str(rec.get("key")), rec.get("value"))
        elif kind in ("event", "notice"):  # a notice: what happened to the ROS graph (the master went away)
            self.events.append(rec)
            del self.events[:-KEEP]
        elif kind == "control":
            self.control.append(rec)
            del self.control[:-KEEP]
            if "paused" in rec:
                self.paused = bool(rec["paused"])
        elif kind == "end":
            self.end = rec
            self.pending.clear()

    def _write(self, key: str, value: Any) -> None:
        self.blackboard[key] = value
        if key in self.written:
            self.written.remove(key)
        self.written.append(key)

    def _load(self, rec: Dict[str, Any]) -> None:
        self.t = float(rec.get("t") or 0.0)
        self.tick = int(rec.get("n") or 0)
        self.tick_t = self.t
        self.status = {int(k): str(v) for k, v in (rec.get("status") or {}).items()}
        self.halted = {int(k): True for k in rec.get("halted") or []}
        self.feedback = {int(k): str(v) for k, v in (rec.get("feedback") or {}).items()}
        self.last = {int(k): str(v) for k, v in (rec.get("last") or {}).items() if v in OUTCOMES}
        self.last.update((k, v) for k, v in self.status.items() if v in OUTCOMES)
        self.pending = {str(c.get("call_id")): c for c in rec.get("pending") or []}
        self.calls = list(rec.get("calls") or [])
        self.events = list(rec.get("events") or [])
        self.control = list(rec.get("control") or [])
        board = rec.get("blackboard") or {}
        order = [str(k) for k in rec.get("written") or [] if k in board]  # a snapshot of an older bmtree has none
        self.blackboard, self.written = {}, []
        for key in [k for k in board if k not in order] + order:
            self._write(str(key), board[key])
        self.paused = bool(rec.get("paused"))
        if rec.get("end"):
            self.end = rec["end"]
        self.caught_up = True

    # reading ----------------------------------------------------------------------------
    def snapshot(self, calls: int = 50, events: int = 50) -> Dict[str, Any]:
        """The present state as a versioned ``snapshot`` record (what a late watcher loads)."""
        with self.lock:
            return {"v": VERSION, "type": "snapshot", "sv": SNAPSHOT_VERSION, "run": self.run, "t": self.t,
                    "n": self.tick, "status": {str(k): v for k, v in self.status.items() if v != "INVALID"},
                    "halted": [k for k, v in self.halted.items() if v],
                    "feedback": {str(k): v for k, v in self.feedback.items() if v},
                    "last": {str(k): v for k, v in self.last.items() if self.status.get(k, "INVALID") == "INVALID"},
                    "pending": list(self.pending.values()), "calls": self.calls[-calls:],
                    "events": self.events[-events:], "control": self.control[-events:],
                    "blackboard": dict(self.blackboard), "written": list(self.written), "paused": self.paused, "end": self.end}

    def view(self) -> Dict[str, Any]:
        """Everything a view draws, as plain data (the web page's JSON)."""
        with self.lock:
            snap = self.snapshot(calls=KEEP, events=KEEP)
            snap.update(tree={k: v for k, v in self.tree.items() if k in ("name", "path", "run", "started", "control")},
                        nodes=self.nodes, version=self.version)
            return snap

    @property
    def steerable(self) -> bool:
        """False when the run said it takes no control commands (started without ``--control``);
        True when it takes them, or did not say (a run of an older bmtree)."""
        return self.tree.get("control") is not False

    def label(self, i: int) -> str:
        """A node's shown status: RUNNING, SUCCESS, FAILURE, HALTED (a running node its parent
        stopped), ``was SUCCESS`` / ``was FAILURE`` (it ended so and was reset since: a selector
        clears the children it moved past, a stopped tree its finished nodes) or '' (never ticked)."""
        s = self.status.get(i, "INVALID")
        if s == "INVALID":
            if self.halted.get(i):
                return "HALTED"
            return "was %s" % self.last[i] if i in self.last else ""
        return s

    def wait(self, predicate: Callable[[WatchState], bool], timeout: float) -> bool:
        """Block until ``predicate(self)`` holds (True) or ``timeout`` passes (False)."""
        end = time.monotonic() + timeout
        with self.lock:
            while not predicate(self):
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self.changed.wait(min(left, 0.5))
            return True


class StateSink(Sink):
    """Feeds the run's own records to a :class:`WatchState` (the run's terminal view)."""

    def __init__(self, state: WatchState):
        self.state = state

    def write(self, channel: str, text: str) -> None:
        self.state.apply_text(text)


class SnapshotSink(StateSink):
    """Keeps the run's state and publishes it as a ``snapshot`` record through ``publish``
    (a latched topic) at the end of a tick, at most every ``interval`` seconds, and at the end.

    A tick that comes too soon after the last snapshot is published ``interval`` later by a
    timer: the engine is event-driven, so while a long call runs there may be no next tick, and
    the latched snapshot must not stay behind the run (a watcher attaching then would load it).

    A snapshot is stamped with the run's time when it is taken (``clock`` is the run's clock:
    its ``tree`` record, on the ``tree`` channel, is the run's time 0), not with its last record's:
    a watcher attaching 3 s into a 5 s wait sees the state of that moment."""

    def __init__(self, publish: Callable[[str], None], interval: float = 0.5,
                 clock: Callable[[], float] = time.monotonic):
        super().__init__(WatchState())
        self.publish = publish
        self.interval = interval
        self.clock = clock
        self._zero: Optional[float] = None  # clock() at the run's tree record (its t 0)
        self._last = 0.0
        self._lock = threading.Lock()
        self._timer: Optional[threading.Timer] = None
        self._closed = False

    def snapshot(self) -> Dict[str, Any]:
        """The run's state now, as a ``snapshot`` record whose ``t`` is the run's time now
        (the time of the end for an ended run)."""
        with self.state.lock:
            snap = self.state.snapshot()
            if self._zero is not None and self.state.end is None:
                snap["t"] = max(float(snap["t"]), round(self.clock() - self._zero, 6))
            return snap

    def write(self, channel: str, text: str) -> None:
        if channel == "tree":
            self._zero = self.clock()
        super().write(channel, text)
        if channel == "control":  # while paused there are no ticks: publish now
            with self._lock:
                self._last = 0.0
            self.flush()

    def _publish_now(self) -> None:  # with self._lock held
        self._last = time.monotonic()
        self.publish(to_json(self.snapshot()))

    def flush(self) -> None:
        with self._lock:
            if self._closed:
                return
            wait = self._last + self.interval - time.monotonic()
            if wait <= 0:
                self._publish_now()
            elif self._timer is None:
                self._timer = threading.Timer(wait, self._trailing)
                self._timer.daemon = True
                self._timer.start()

    def _trailing(self) -> None:
        with self._lock:
            self._timer = None
            if not self._closed:
                self._publish_now()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            self._publish_now()
