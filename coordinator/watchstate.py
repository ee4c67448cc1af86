"""What a watcher knows about a run, rebuilt from run-stream records (README, "Run stream").

:class:`WatchState` applies the records of one run (live from topics, from a run log,
or from the run's own stream in-process) and can be caught up at once from a
``snapshot`` record, which the running process publishes latched and periodically
(:class:`SnapshotSink`) so that a watcher that attaches mid-run sees the present
state without the history. Plain data only: the terminal and web views draw it.

What the views show of it is read through two mixins kept in their own modules: each node's shown
status, name and the calls as shown (:class:`coordinator.watchlabels.WatchLabels`: the calls the run's
stop from outside halted as ``bmtree run``'s summary shows them), and what the ticks and control answers
say of single nodes besides their statuses: a loop's or a retry's progress, the steering marks
(:class:`coordinator.watchmarks.WatchMarks`).

One master may carry two runs' streams (a forgotten terminal): the state stays on the
first run it shows (or the one ``only`` names, ``watch --run``) and keeps the other runs'
records aside (:class:`OtherRuns`), with a notice of the watch's own for each; the next run's
records that came before its ``tree`` (``watch --follow``) are applied once it comes (:attr:`taken`).

The topics are ordered each on its own, not among them: a snapshot may come after newer records
of another topic, and records it holds may come after it. The live records are kept a while and
those a snapshot does not hold (:class:`coordinator.watchruns.Cover`) applied again over it; those
it holds that come later are left out.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any, Callable, Deque, Dict, List, Optional, Set, Tuple

from coordinator.runevents import IncludeArgs, cleanup_said
from coordinator.runrecords import parse_record, record_problem, version_problem
from coordinator.runstream import VERSION
from coordinator.watchlabels import WatchLabels
from coordinator.watchmarks import FORCED, HELD, OUTCOMES, WatchMarks, fill
from coordinator.watchmarks import WAITING_KINDS as WAITING_KINDS  # (importable from here, as before)
from coordinator.watchruns import Cover, OtherRuns, run_matches
from coordinator.watchstops import StopCalls

__all__ = ["WatchState", "SNAPSHOT_VERSION", "SILENT_AFTER", "SILENCE_NOTES", "HELD", "FORCED", "fill"]

SNAPSHOT_VERSION = 1
#: seconds without an answer from the run's node after which every view says that what it shows may be stale
SILENT_AFTER = 3.0
SILENCE_NOTES = ("run_silent", "run_answers")  # the watch's own notices of it (``what``)
_WHY_SILENT = "its machine unreachable, or its process stopped"
KEEP = 200  # finished calls, events and control actions kept (the latest)
RECENT = 1000  # live records kept to apply again over a snapshot that came after them (another topic)


class WatchState(WatchMarks, WatchLabels):
    """One run as seen from outside; every method is thread-safe. Its state is all here; the mixins
    (:class:`WatchMarks`, :class:`WatchLabels`) only hold methods, kept in their own modules."""

    def __init__(self, only: str = "", recent: int = RECENT) -> None:
        self.lock = threading.RLock()
        #: how many live records are kept to apply again over a snapshot that comes after them (0: none, for
        #: a state that never loads one: the run's own, a replay's)
        self.recent = recent
        self.changed = threading.Condition(self.lock)
        self.version = 0  # bumped on every applied record (the web view polls it)
        #: the run to show (``watch --run``: its id or the id's last part); '' the first one seen
        self.only = only
        #: the runs on the same stream that are not shown, their records kept aside
        self.others = OtherRuns()
        #: why the run to show cannot be (its stream is of a format this bmtree does not read), or ''
        self.refused = ""
        self.skipped = 0  # records left out: not of a shape this bmtree reads
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
        #: calls in flight (``call_start`` records); after the answer came while the run was paused,
        #: ``answered`` (its time) and ``answer``; after the watch's own end of a run that is gone,
        #: ``maybe_running`` (the module may still be running it: nobody cancelled it)
        self.pending: Dict[str, Dict[str, Any]] = {}
        #: the finished calls (``call_end`` records with ``started`` and the ``inputs`` of their start)
        self.calls: List[Dict[str, Any]] = []
        self.ncalls = 0  # calls finished in the run, also the ones before a late watch and past KEEP
        #: for_each nodes' positions (id -> [element, of]), from the ticks' ``loops``
        self.loops: Dict[int, List[int]] = {}
        #: the watch's own notices (another run started on this master, its node silent): not the run's records
        self.notes: List[Dict[str, Any]] = []
        self.notes_made = 0  # how many, also those past KEEP (``--plain`` prints each once)
        #: the run's node and when it last answered the watch's question (or was first asked), monotonic
        self.asked: Optional[Tuple[str, float]] = None
        self.silent = False  # it has not answered for SILENT_AFTER s (said once, until it answers)
        self.events: List[Dict[str, Any]] = []
        self.control: List[Dict[str, Any]] = []
        self.blackboard: Dict[str, Any] = {}
        #: the values each include's arguments had (its label says them: ``fetch_item(item="milk")``)
        self.args = IncludeArgs({})
        self._reset_marks()  # retries' attempts, running times, steering marks (:class:`WatchMarks`)
        #: the run's live records since it was shown (the latest), applied again over a snapshot that
        #: came after them without them (topics are ordered each on its own)
        self._recent: Deque[Dict[str, Any]] = deque(maxlen=self.recent)
        self._replaying = False
        #: the snapshots loaded (the latest few; ``--plain`` says the first one it sees)
        self.loaded: List[Dict[str, Any]] = []
        self._cover: Optional[Cover] = None  # what the latest one holds (a record that comes later may be in it)
        #: the records of the run kept until its tree came and applied then (``--plain`` says them after it)
        self.taken: List[Dict[str, Any]] = []
        self._cleanup: Optional[Set[int]] = None  # the ids of the tree's cleanup (cached)
        self._parts: Optional[Tuple[Any, Any, Any]] = None  # its with_cleanup top, root, the cleanup's top (cached)
        self.stops = StopCalls()  # the calls the stop from outside halted, and those of a cut cleanup
        self.end: Optional[Dict[str, Any]] = None
        self.paused = False
        self.t = 0.0
        self._seen = time.monotonic()  # when ``t`` last moved on (to tell the run's time between records)
        self.tick = 0
        self.tick_t = 0.0  # the run's time of its last tick
        self.caught_up = False

    # applying ---------------------------------------------------------------------------
    def apply_text(self, text: str) -> None:
        """One record's JSON text; a malformed one is ignored (it must never stop a watcher)."""
        rec, _why = parse_record(text)
        if rec is not None:
            self.apply(rec)

    def apply(self, rec: Any) -> None:
        """One record; one not of a shape this bmtree reads (:func:`coordinator.runrecords.record_problem`,
        as a run log's reader checks it) is left out, never half applied; the tree record of a newer
        bmtree's run to show makes :attr:`refused` say so."""
        with self.lock:
            if not self._usable(rec):
                self.skipped += 1
                return
            try:
                self._apply(rec)
            except (TypeError, ValueError, KeyError, IndexError, AttributeError):
                return
            self.version += 1
            self.changed.notify_all()

    def _usable(self, rec: Any) -> bool:
        run = str(rec.get("run") or "") if isinstance(rec, dict) else ""
        if isinstance(rec, dict) and rec.get("type") == "tree" and version_problem(rec.get("v")) is not None:
            if not self.nodes and not self.refused and (not self.only or run_matches(run, self.only)):
                self.refused = "the run %s%s on the run stream was %s" % (
                    run or "?", " (%s)" % rec["name"] if isinstance(rec.get("name"), str) else "",
                    version_problem(rec.get("v")))
                self.changed.notify_all()
            return False
        mine = self.nodes and (not run or run == self.run)
        return record_problem(rec, {n.get("id") for n in self.nodes} if mine else None) is None

    def _apply(self, rec: Dict[str, Any]) -> None:
        kind = rec.get("type")
        run = str(rec.get("run") or "")
        if kind == "tree":
            if not self._shows(run):
                self._aside(run, rec)
                return
            if run != self.run or not self.nodes:
                self._reset(run)
            self.tree = {k: v for k, v in rec.items() if k != "nodes"}
            self.nodes = [n for n in rec.get("nodes") or [] if isinstance(n, dict)]
            self.args, self._cleanup, self._parts = IncludeArgs.of_nodes(self.nodes), None, None
            for key, value in (rec.get("blackboard") or {}).items():
                if str(key) not in self.blackboard:  # the same run's tree again must not undo its writes
                    self._write(str(key), value)
            early, self._early = self._early, []
            kept = self.others.take(run)  # a run shown after another one ended (--follow)
            taken = []
            for r in early + kept:  # records that came before the tree (topics are not ordered among them)
                other = str(r.get("run") or "")
                if other == run:
                    taken.append(r)
                    self._apply(r)
                elif other:
                    self.others.keep(other, r)
            self.taken = taken
            return
        if not self.nodes:
            if len(self._early) < 1000:
                self._early.append(rec)
            return
        if run and self.run and run != self.run:
            self.others.keep(run, rec)  # another run's (shown if this one ends first, with --follow)
            return
        if kind == "snapshot":
            if self.caught_up and int(rec.get("n") or 0) <= self.tick:
                return
            self._load(rec)
            return
        if not self._replaying:
            if self._cover is not None and self._cover.covers(rec):
                return  # sent before the snapshot was taken, come after it (another topic, another queue)
            if self.recent:
                self._recent.append(rec)
        self._advance(float(rec.get("t") or 0.0))
        if kind == "tick":
            n = int(rec.get("n") or 0)
            if n and n <= self.tick:
                return  # already in the snapshot
            self.tick = n or self.tick + 1
            before, self.tick_t = self.tick_t, float(rec.get("t") or self.t)
            self.args.tick(rec.get("changes") or [], self.tick_t)
            for row in rec.get("loops") or []:  # for_each nodes that moved to another element
                self.loops[int(row[0])] = [int(row[1]), int(row[2])]
            for row in rec.get("waits") or []:  # (a newer run's) retries waiting: when the next attempt starts
                self.waits[int(row[0])] = float(row[1])
            failed_under: List[int] = []   # retries whose attempt failed in this tick
            for change in rec.get("changes") or []:
                i, new = int(change[0]), str(change[1])
                old = self.status.get(i, "INVALID")
                self.halted[i] = new == "INVALID" and old == "RUNNING"
                self.status[i] = new
                if new in OUTCOMES:
                    self.last[i] = new
                if new != "INVALID" or old not in OUTCOMES:  # a reset keeps why it failed, for "was FAILURE"
                    self.feedback[i] = self._said(i, str(change[2]) if len(change) > 2 and change[2] else "")
                self._changed(i, old, new, failed_under)
            self._attempted(failed_under)
            self._let_go()
            top, root, clean = self.parts()
            self.stops.tick({int(c[0]) for c in rec.get("changes") or [] if str(c[1]) == "INVALID"},
                            root if top is not None else self._top(), clean, before, self.tick_t)
        elif kind == "call_start":
            self.pending[str(rec.get("call_id"))] = rec
        elif kind == "call_answer":  # answered while the run is paused: its leaf takes it at the next tick
            cid = str(rec.get("call_id"))
            if cid in self.pending:
                self.pending[cid] = dict(self.pending[cid], answered=rec.get("t"), answer=rec.get("answer"))
        elif kind == "call_end":
            start = self.pending.pop(str(rec.get("call_id")), None)
            if not any(c.get("call_id") == rec.get("call_id") for c in self.calls[-20:]):
                done = dict(rec, started=(start or {}).get("t", rec.get("t")))
                if start is not None and "inputs" not in done:
                    done["inputs"] = start.get("inputs")
                self.calls.append(done)
                del self.calls[:-KEEP]
                self.ncalls += 1
                if rec.get("status") == "halted":
                    self.stops.halted(str(rec.get("call_id")), rec.get("node") in self.cleanup_ids,
                                      float(rec.get("t") or 0.0))
        elif kind == "write":
            self._write(str(rec.get("key")), rec.get("value"))
            self.args.write(str(rec.get("key")), rec.get("value"), float(rec.get("t") or 0.0))
        elif kind in ("event", "notice"):  # a notice: what happened to the ROS graph (the master went away)
            if not any(e is rec for e in self.events[-20:]):
                self.events.append(rec)
                del self.events[:-KEEP]
        elif kind == "control":
            if not any(c is rec or c == rec for c in self.control[-20:]):  # (applied again over a snapshot)
                self.control.append(rec)
                del self.control[:-KEEP]
            if "paused" in rec:
                self.paused = bool(rec["paused"])
            self._steered(rec)
        elif kind == "end":
            self.end = rec
            self.paused = False   # an ended run is not paused (a breakpoint in its cleanup left it so)
            self.held.clear()
            if rec.get("gone"):  # nobody stopped them: the modules may still be running them
                self.pending = {k: dict(c, maybe_running=True) for k, c in self.pending.items()}
            else:
                self.pending.clear()

    def _advance(self, t: float) -> None:
        if t > self.t:
            self.t = t
            self._seen = time.monotonic()

    # the runs shown, the watch's own notices, snapshots -----------------------------------------
    def _shows(self, run: str) -> bool:
        """Whether a tree record of ``run`` is (or becomes) the one shown: the one ``only`` names,
        else the first one seen, and another one only once the one shown has ended."""
        if self.only:
            return run_matches(run, self.only) and (not self.nodes or run == self.run or self.end is not None)
        return not self.nodes or run == self.run or self.end is not None

    def _aside(self, run: str, rec: Dict[str, Any]) -> None:
        """A tree record of a run not shown: kept aside, and the first one a notice of the watch's own."""
        if self.others.tree(run, rec) and self.nodes and not self.only:
            self._note("other_run", self.others.notice(run, str(self.tree.get("name") or "?")))

    def _note(self, what: str, text: str) -> None:
        self.notes.append({"v": VERSION, "type": "notice", "what": what, "run": self.run, "t": round(self.now(), 6),
                           "watch": True, "text": text})
        del self.notes[:-KEEP]
        self.notes_made += 1

    def _write(self, key: str, value: Any) -> None:
        self.blackboard[key] = value
        if key in self.written:
            self.written.remove(key)
        self.written.append(key)

    def _load(self, rec: Dict[str, Any]) -> None:
        self.t = float(rec.get("t") or 0.0)
        self._seen = time.monotonic()
        self.tick = int(rec.get("n") or 0)
        # the snapshot's own time is when it was taken; a snapshot of an older bmtree has no tick_t
        self.tick_t = float(rec["tick_t"]) if rec.get("tick_t") is not None else self.t
        self.status = {int(k): str(v) for k, v in (rec.get("status") or {}).items()}
        self.halted = {int(k): True for k in rec.get("halted") or []}
        self.feedback = {int(k): str(v) for k, v in (rec.get("feedback") or {}).items()}
        self.last = {int(k): str(v) for k, v in (rec.get("last") or {}).items() if v in OUTCOMES}
        self.last.update((k, v) for k, v in self.status.items() if v in OUTCOMES)
        self.pending = {str(c.get("call_id")): c for c in rec.get("pending") or []}
        self.calls = list(rec.get("calls") or [])
        self.ncalls = max(int(rec.get("ncalls") or 0), len(self.calls))
        self.loops = {int(k): [int(v[0]), int(v[1])] for k, v in (rec.get("loops") or {}).items()}
        self.events = list(rec.get("events") or [])
        self.control = list(rec.get("control") or [])
        board = rec.get("blackboard") or {}
        order = [str(k) for k in rec.get("written") or [] if k in board]  # a snapshot of an older bmtree has none
        self.blackboard, self.written = {}, []
        for key in [k for k in board if k not in order] + order:
            self._write(str(key), board[key])
        self.paused = bool(rec.get("paused"))
        self.stops = StopCalls(rec.get("stopped") or [], rec.get("cut") or [])
        self.args.values.update((int(k), dict(v)) for k, v in (rec.get("args") or {}).items() if isinstance(v, dict))
        if rec.get("end"):
            self.end = rec["end"]
        self._load_marks(rec)
        self.caught_up = True
        self.loaded = (self.loaded + [rec])[-5:]
        # what came before it on another topic and is newer than it: applied again, on top
        self._cover = Cover(rec)
        later = [r for r in self._recent if not self._cover.covers(r)]
        self._replaying = True
        try:
            for r in later:
                self._apply(r)
        finally:
            self._replaying = False

    def heard(self, node: str, answered: bool, now: Optional[float] = None) -> bool:
        """Whether the run's node answered the watch's question (about once a second,
        :meth:`coordinator.watchlive.RunLiveness.ask`): an idle run sends no records either, only the
        question tells a dropped link or a stopped process from it. True when a silence of
        :data:`SILENT_AFTER` s began or ended: a notice of the watch's own says so."""
        with self.lock:
            now = time.monotonic() if now is None else now
            if self.end is not None or not self.nodes:
                return False
            if self.asked is None or self.asked[0] != node:  # first asked: silent from now on, if it is
                self.asked, self.silent = (node, now), False
                return False
            quiet = now - self.asked[1]
            if answered:
                self.asked = (node, now)
                if not self.silent:
                    return False
                self.silent = False
                self._note("run_answers", "the run's node %s answers again after %d s: what is shown is current "
                                          "again" % (node, quiet))
            elif self.silent or quiet < SILENT_AFTER:
                return False
            else:
                self.silent = True
                self._note("run_silent", "the run's node %s has not answered for %d s (%s): what is shown may be "
                                         "stale" % (node, quiet, _WHY_SILENT))
            self.version += 1
            self.changed.notify_all()
            return True

    def silence(self, now: Optional[float] = None) -> str:
        """While the run's node has not answered for :data:`SILENT_AFTER` s or more (and the run has not
        ended), what every view says, its seconds counting; else ''."""
        with self.lock:
            if not self.silent or self.asked is None or self.end is not None:
                return ""
            quiet = (time.monotonic() if now is None else now) - self.asked[1]
            return "no answer from the run's node %s for %d s (%s): what is shown may be stale" % (
                self.asked[0], quiet, _WHY_SILENT)

    # reading ----------------------------------------------------------------------------
    def snapshot(self, calls: int = 50, events: int = 50) -> Dict[str, Any]:
        """The present state as a versioned ``snapshot`` record (what a late watcher loads)."""
        with self.lock:
            return {"v": VERSION, "type": "snapshot", "sv": SNAPSHOT_VERSION, "run": self.run, "t": self.t,
                    "n": self.tick, "tick_t": self.tick_t, "ncalls": self.ncalls,
                    "loops": {str(k): v for k, v in self.loops.items()},
                    "status": {str(k): v for k, v in self.status.items() if v != "INVALID"},
                    "halted": [k for k, v in self.halted.items() if v],
                    "feedback": {str(k): v for k, v in self.feedback.items() if v},
                    "last": {str(k): v for k, v in self.last.items() if self.status.get(k, "INVALID") == "INVALID"},
                    "pending": list(self.pending.values()), "calls": self.calls[-calls:],
                    "events": self.events[-events:], "control": self.control[-events:],
                    "blackboard": dict(self.blackboard), "written": list(self.written), "paused": self.paused,
                    "end": self.end, "args": {str(k): v for k, v in self.args.values.items()},
                    "stopped": sorted(self.stops.stopped), "cut": sorted(self.stops.cut),
                    **self._marks_snapshot()}  # (newer fields: how long nodes run, retries' attempts, steering marks)

    def view(self) -> Dict[str, Any]:
        """Everything a view draws, as plain data (the web page's JSON): the snapshot, with the
        watch's own notices among the events (``watch``: true), ``calls_total``, the calls as shown
        (:meth:`shown_calls`), each node's shown status (``words``, :meth:`label`) and ``silent``
        (:meth:`silence`)."""
        with self.lock:
            snap = self.snapshot(calls=KEEP, events=KEEP)
            snap.update(tree={k: v for k, v in self.tree.items() if k in ("name", "path", "run", "started", "control")},
                        nodes=self.nodes, version=self.version, events=self.all_events()[-KEEP:],
                        calls=self.shown_calls(), words={str(n.get("id")): self.label(n.get("id")) for n in self.nodes},
                        calls_total=self.calls_total, others=self.others.summary(),
                        labels={str(i): self.name(i) for i in self.args.values if self.name(i) != self._node_name(i)},
                        pending_title=self.pending_title(), silent=self.silence(),
                        progress={str(n.get("id")): p for n in self.nodes for p in [self.progress(n.get("id"))] if p},
                        notes={str(n.get("id")): w for n in self.nodes for w in [self.note(n.get("id"))] if w},
                        steer=self.steerable,
                        cleanup=cleanup_said((self.end or {}).get("cleanup")),
                        now=round(self.now(), 6))   # a page opened in a long call counts from here, not from t
            return snap

    def all_events(self) -> List[Dict[str, Any]]:
        """The run's events and notices with the watch's own notices, by time (in arrival order at one time)."""
        if not self.notes:
            return list(self.events)
        return sorted(self.events + self.notes, key=lambda e: float(e.get("t") or 0.0))

    @property
    def calls_total(self) -> int:
        """How many calls the run finished: also those before a late watch attached and those past
        the KEEP kept; at the end the run's own count (its ``end`` record's ``calls``)."""
        total = max(self.ncalls, len(self.calls))
        if self.end and isinstance(self.end.get("calls"), int) and not self.end.get("gone"):
            total = max(total, int(self.end["calls"]))
        return total

    def now(self) -> float:
        """The run's time now: its last record's, advanced by the wall clock since (a long call
        makes no record until it ends); once it has ended, the time of its end."""
        with self.lock:
            if self.end is not None or not self.nodes:
                return self.t
            return self.t + max(0.0, time.monotonic() - self._seen)

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
