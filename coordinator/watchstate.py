"""What a watcher knows about a run, rebuilt from run-stream records (README, "Run stream").

:class:`WatchState` applies the records of one run (live from topics, from a run log,
or from the run's own stream in-process) and can be caught up at once from a
``snapshot`` record, which the running process publishes latched and periodically
(:class:`SnapshotSink`) so that a watcher that attaches mid-run sees the present
state without the history. Plain data only: the terminal and web views draw it.

Calls the run's stop from outside halted (Ctrl-C, ``--max-duration``) and those of a tree's cleanup
cut short are shown as ``bmtree run``'s summary and ``bmtree replay`` show them (:meth:`WatchState.call_label`,
:mod:`coordinator.watchstops`), and the top node of a tree with ``cleanup:`` halted so as the run's status.

One master may carry two runs' streams (a forgotten terminal): the state stays on the
first run it shows (or the one ``only`` names, ``watch --run``) and keeps the other runs'
records aside (:class:`OtherRuns`), with a notice of the watch's own for each; the next run's
records that came before its ``tree`` (``watch --follow``) are applied once it comes (:attr:`taken`).

The topics are ordered each on its own, not among them: a snapshot may come after newer records
of another topic, and records it holds may come after it. The live records are kept a while and
those a snapshot does not hold (:class:`coordinator.watchruns.Cover`) applied again over it; those
it holds that come later are left out.

Besides the statuses, it tells per node what the views show on it (:meth:`WatchState.progress`,
:meth:`WatchState.note`): a for_each's element, a retry's attempt (counted from its ticks: a child
that failed while the retry runs on), how long a ``wait`` has waited, and from the control answers
the breakpoints, a node a breakpoint holds and outcomes forced by control.
"""
from __future__ import annotations

import re
import threading
import time
from collections import deque
from typing import Any, Callable, Deque, Dict, List, Optional, Set, Tuple

from coordinator.runevents import IncludeArgs, cleanup_said, status_word
from coordinator.runrecords import parse_record, record_problem, version_problem
from coordinator.runstream import VERSION
from coordinator.watchruns import Cover, OtherRuns, run_matches
from coordinator.watchstops import StopCalls, run_stop_status

__all__ = ["WatchState", "SNAPSHOT_VERSION", "SILENT_AFTER", "SILENCE_NOTES", "HELD", "FORCED", "fill"]

SNAPSHOT_VERSION = 1
#: seconds without an answer from the run's node after which every view says that what it shows may be stale
SILENT_AFTER = 3.0
SILENCE_NOTES = ("run_silent", "run_answers")  # the watch's own notices of it (``what``)
_WHY_SILENT = "its machine unreachable, or its process stopped"
KEEP = 200  # finished calls, events and control actions kept (the latest)
OUTCOMES = ("SUCCESS", "FAILURE")
RECENT = 1000  # live records kept to apply again over a snapshot that came after them (another topic)
HELD = "held at breakpoint"   # a node a breakpoint holds: RUNNING, but it has not started
FORCED = "forced"             # an outcome a ``force`` command gave, not the node's own
#: a retry's own words end in "run 2 of 3"; the viewers call its runs attempts, as its reason does
_RETRY_RUN = re.compile(r"\brun (\d+) of (\d+)")
#: the leaves whose running time the views show (how long it has waited so far)
WAITING_KINDS = ("wait", "wait_event")


def fill(progress: Dict[str, Any], now: float) -> str:
    """A node's progress (:meth:`WatchState.progress`) in words at the run's time ``now``: its ``{s}``,
    the seconds since ``since`` (or until ``until``), as ``0.4 s``."""
    text = str(progress.get("text") or "")
    if "{s}" not in text:
        return text
    if progress.get("until") is not None:
        left = max(0.0, float(progress["until"]) - now)
    else:
        left = max(0.0, now - float(progress.get("since") or now))
    return text.replace("{s}", "%.1f s" % left)


class WatchState:
    """One run as seen from outside; every method is thread-safe."""

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
        #: each running ``retry``'s attempt, from the ticks: id -> [attempt (from 1), the run's time its
        #: last attempt failed while it waits to start the next one, else None]
        self.attempts: Dict[int, List[Any]] = {}
        #: a running retry's next attempt time, when the run says it (a tick's ``waits``: [[id, t]])
        self.waits: Dict[int, float] = {}
        #: when each running node went RUNNING (the run's time of that tick)
        self.since: Dict[int, float] = {}
        self.changed_t: Dict[int, float] = {}  # the run's time of each node's last change
        #: steering, from the control answers: the nodes with a breakpoint, those a breakpoint holds
        #: (id -> [its time, when the run was let go on or None]), forces to come (id -> [outcome, time])
        #: and outcomes forced (id -> outcome; until the node runs again)
        self.breaks: Set[int] = set()
        self.held: Dict[int, List[Any]] = {}
        self.forcing: Dict[int, List[Any]] = {}
        self.forced: Dict[int, str] = {}
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

    # what the ticks and the control answers say of single nodes -----------------------------------
    def _kinds(self) -> Tuple[Dict[int, str], Dict[int, Any]]:
        """Each node's kind and parent (cached per tree)."""
        cached = getattr(self, "_kind_cache", None)
        if cached is None or cached[0] is not self.nodes:
            cached = self._kind_cache = (self.nodes, {n.get("id"): str(n.get("kind") or "") for n in self.nodes},
                                         {n.get("id"): n.get("parent") for n in self.nodes})
        return cached[1], cached[2]

    def _said(self, i: int, text: str) -> str:
        """A node's failure as the viewers say it: a retry's ``failed in run 2 of 2`` is its attempt 2 of 2."""
        if text and self._kinds()[0].get(i) == "retry":
            return _RETRY_RUN.sub(r"attempt \1 of \2", text)
        return text

    def _changed(self, i: int, old: str, new: str, failed_under: List[int]) -> None:
        """One change of a tick (at ``tick_t``): since when a node runs, a retry's attempt, a forced outcome,
        a held node that ended (halted) without starting."""
        kinds, parents = self._kinds()
        self.changed_t[i] = self.tick_t
        if new == "RUNNING":
            if old != "RUNNING":
                self.since[i] = self.tick_t
                self.forced.pop(i, None)   # it runs again: its next outcome is its own
                if kinds.get(i) == "retry":
                    self.attempts[i] = [1, None]
                    self.waits.pop(i, None)
        else:
            self.since.pop(i, None)
            if kinds.get(i) == "retry":
                self.attempts.pop(i, None)
                self.waits.pop(i, None)
            if i in self.held and self.tick_t > float(self.held[i][0]):  # halted or forced while held
                del self.held[i]
        if new in OUTCOMES:
            force = self.forcing.get(i)
            if force is not None and force[0] == new and self.tick_t >= float(force[1]):
                self.forced[i] = new
                del self.forcing[i]
        up = parents.get(i)
        if up is not None and kinds.get(up) == "retry":
            if new == "FAILURE":
                failed_under.append(up)
            elif new == "RUNNING" and up in self.attempts:   # the next attempt started
                self.attempts[up][1] = None
                self.waits.pop(up, None)

    def _attempted(self, failed_under: List[int]) -> None:
        """Retries whose child failed in this tick and that still run: their next attempt, now or after
        their delay (the child does not run meanwhile)."""
        _kinds, parents = self._kinds()
        for r in dict.fromkeys(failed_under):
            if self.status.get(r) != "RUNNING" or r not in self.attempts:
                continue
            running = any(self.status.get(c) == "RUNNING" for c, up in parents.items() if up == r)
            self.attempts[r] = [int(self.attempts[r][0]) + 1, None if running else self.tick_t]

    def _let_go(self) -> None:
        """Held nodes whose run went on (resumed, stepped) before the tick just applied: they start now."""
        for i, (_at, gone_on) in list(self.held.items()):
            if gone_on is not None and self.tick_t > float(gone_on):
                del self.held[i]
                if self.status.get(i) == "RUNNING":
                    self.since[i] = self.tick_t

    def named(self, name: Any, every: bool = False) -> List[int]:
        """The ids a control command's ``node`` names, as the run reads it: the nodes so named, else
        ``NAME@ID`` (``@ID``) the node of that id. Several so named: all of them with ``every`` (a clear),
        else the one that is not the top of a tree with ``cleanup:`` (never steered), if one."""
        if not isinstance(name, str):
            return []
        ids = [n.get("id") for n in self.nodes if n.get("name") == name]
        if not ids:
            head, at, num = name.rpartition("@")
            if at and num.isdecimal() and num.isascii() and len(num) <= 9:
                i = int(num)
                if any(n.get("id") == i for n in self.nodes) and (not head or self._node_name(i) == head):
                    return [i]
            return []
        if len(ids) > 1 and not every:
            top = self.parts()[0]
            ids = [i for i in ids if i != top]
            return ids if len(ids) == 1 else []
        return ids

    def _steered(self, rec: Dict[str, Any]) -> None:
        """What a control answer says of single nodes: a breakpoint set or cleared, one that holds a node
        (until the run goes on: a resume, a step, a stop), an outcome to force the next time it is ticked."""
        if not rec.get("ok"):
            return
        what = rec.get("command")
        args = rec.get("args") if isinstance(rec.get("args"), dict) else {}
        t = float(rec.get("t") or 0.0)
        if what in ("break", "breakpoint"):
            for i in self.named(args.get("node")):
                self.breaks.add(i)
                if what == "breakpoint":  # it holds the node (RUNNING: its parent waits) until the run goes on
                    self.held[i] = [t, None]
        elif what == "clear":
            self.breaks.difference_update(self.named(args.get("node"), every=True))
        elif what == "force" and str(args.get("outcome", "")).upper() in OUTCOMES:
            outcome = str(args.get("outcome")).upper()
            for i in self.named(args.get("node")):
                if self.status.get(i) == outcome and self.changed_t.get(i, -1.0) >= t:  # its tick came first
                    self.forced[i] = outcome
                    self.forcing.pop(i, None)
                else:
                    self.forcing[i] = [outcome, t]
        if rec.get("paused") is False or what == "step":  # the run goes on: a held node starts at its next tick
            for held in self.held.values():
                if held[1] is None and t > float(held[0]):
                    held[1] = t
            self._let_go()

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

    def _load_marks(self, rec: Dict[str, Any]) -> None:
        """A snapshot's per-node extras (a newer run's; an older one's steering marks from its control answers)."""
        known = {n.get("id") for n in self.nodes}

        def ids(value: Any) -> Dict[int, Any]:
            items = value.items() if isinstance(value, dict) else ((k, True) for k in value or [])
            return {int(k): v for k, v in items if str(k).lstrip("-").isdigit() and int(k) in known}

        self.since = {k: float(v) for k, v in ids(rec.get("since")).items()}
        self.attempts = {k: [int(v[0]), None if v[1] is None else float(v[1])] for k, v in ids(rec.get("attempts")).items()}
        self.waits = {k: float(v) for k, v in ids(rec.get("waits")).items()}
        self.changed_t = {k: float(v) for k, v in ids(rec.get("changed_t")).items()}
        if "breaks" in rec:
            self.breaks = set(ids(rec.get("breaks")))
            self.held = {k: [float(v[0]), None if v[1] is None else float(v[1])] for k, v in ids(rec.get("held")).items()}
            self.forcing = {k: [str(v[0]), float(v[1])] for k, v in ids(rec.get("forcing")).items()}
            self.forced = {k: str(v) for k, v in ids(rec.get("forced")).items() if v in OUTCOMES}
        else:  # a snapshot of an older bmtree: what its control answers say
            self.breaks, self.held, self.forcing, self.forced = set(), {}, {}, {}
            for c in self.control:
                self._steered(c)
            for i in list(self.forcing):  # forced since (a FAILURE says so)
                if self.feedback.get(i, "").startswith("forced to "):
                    self.forced[i] = self.forcing.pop(i)[0]

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
                    # (newer fields: how long nodes run, retries' attempts, steering marks)
                    "since": {str(k): v for k, v in self.since.items() if self.status.get(k) == "RUNNING"},
                    "changed_t": {str(k): v for k, v in self.changed_t.items() if k in self.forcing},
                    "attempts": {str(k): v for k, v in self.attempts.items()},
                    "waits": {str(k): v for k, v in self.waits.items()},
                    "breaks": sorted(self.breaks), "held": {str(k): v for k, v in self.held.items()},
                    "forcing": {str(k): v for k, v in self.forcing.items()},
                    "forced": {str(k): v for k, v in self.forced.items()}}

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

    @property
    def steerable(self) -> bool:
        """Whether the viewers offer control commands now: a run is shown, it has not ended, and its
        ``tree`` record said it takes them (``--control``; a run of an older bmtree does not say: it may).
        False while no run is shown: nothing would take them."""
        return bool(self.nodes) and self.end is None and self.tree.get("control") is not False

    def no_steering(self) -> str:
        """Why the viewers offer no control commands now ('' when they do)."""
        if not self.nodes:
            return "no run is shown yet: the keys steer a run started with --control once one is shown"
        if self.tree.get("control") is False:
            return "this run takes no commands: it was started without --control"
        if self.end is not None:
            return "the run has ended: it takes no more commands"
        return ""

    def note(self, i: int) -> str:
        """What the run's steering says of a node's shown status: held at a breakpoint (RUNNING, not
        started), or an outcome forced by control (also once reset: ``was SUCCESS``), else ''."""
        with self.lock:
            status = self.status.get(i, "INVALID")
            if i in self.held and status == "RUNNING":
                return HELD
            if i in self.forced and self.label(i) in (self.forced[i], "was " + self.forced[i]):
                return FORCED
            return ""

    def progress(self, i: int) -> Optional[Dict[str, Any]]:
        """Where a running loop or wait is, for the views (``text``, with ``{s}`` the seconds since ``since``
        or until ``until``: :func:`fill`): a for_each's ``item 2 of 3``, a retry's ``attempt 2 of 3`` (or,
        between attempts, ``waiting {s} before attempt 2``, ``next attempt in {s} (2 of 3)``), a repeat's
        ``run 2 of 3`` (when the run says it), a ``wait``/``wait_event``'s ``waited {s}``; None else."""
        with self.lock:
            if self.status.get(i) != "RUNNING" or self.note(i):
                return None
            kind = self._kinds()[0].get(i, "")
            at = self.loops.get(i)
            if kind == "retry" and (at is not None or i in self.attempts):
                n, waiting = (int(at[0]), None) if at is not None else (int(self.attempts[i][0]), self.attempts[i][1])
                of = " of %d" % int(at[1]) if at is not None else ""
                if i in self.waits:
                    return {"text": "next attempt in {s} (%d%s)" % (n, of), "until": self.waits[i]}
                if waiting is not None:
                    return {"text": "waiting {s} before attempt %d%s" % (n, of), "since": waiting}
                return {"text": "attempt %d%s" % (n, of)}
            if at is not None:
                return {"text": "%s %d of %d" % ("run" if kind == "repeat" else "item", at[0], at[1])}
            if kind in WAITING_KINDS and i in self.since:
                return {"text": "waited {s}", "since": self.since[i]}
            return None

    def label(self, i: int) -> str:
        """A node's shown status: RUNNING, SUCCESS, FAILURE, HALTED (a running node its parent
        stopped), ``was SUCCESS`` / ``was FAILURE`` (it ended so and was reset since: a selector
        clears the children it moved past, a stopped tree its finished nodes) or '' (never ticked).
        The top node of a tree with ``cleanup:`` stands for the run: halted (root was stopped from
        outside, then the cleanup ran), it shows the run's status, INTERRUPTED for a Ctrl-C
        (``bmtree run`` and ``replay`` print it so: :func:`coordinator.runevents.halted_word`)."""
        s = self.status.get(i, "INVALID")
        if s == "INVALID":
            if self.halted.get(i):
                top = self.parts()[0]
                stopped = run_stop_status(self.end, self.blackboard) if top is not None and i == top else ""
                return status_word(stopped) if stopped else "HALTED"
            return "was %s" % self.last[i] if i in self.last else ""
        return s

    def call_label(self, c: Dict[str, Any]) -> Tuple[str, str]:
        """A finished call's (status, error) as shown: ``interrupted`` (``halted  stopped after 60 s``)
        for one the stop from outside halted, why the cleanup was cut short for one of its calls halted
        then, as ``bmtree run``'s summary and ``bmtree replay`` say (:mod:`coordinator.watchstops`)."""
        with self.lock:
            return self.stops.label(c, self.end, self.blackboard)

    def call_settled(self, c: Dict[str, Any]) -> bool:
        """Whether :meth:`call_label` of a finished call is final (``--plain`` holds its line until then)."""
        with self.lock:
            return self.stops.settled(c, self.end, self.blackboard, self.tick_t)

    def shown_calls(self) -> List[Dict[str, Any]]:
        """The finished calls kept, each with the status and error :meth:`call_label` shows."""
        with self.lock:
            out = []
            for c in self.calls:
                status, error = self.call_label(c)
                same = status == str(c.get("status")) and error == str(c.get("error") or "")
                out.append(c if same else dict(c, status=status, error=error))
            return out

    def _node_name(self, i: int) -> str:
        names = getattr(self, "_names", None)
        if names is None or names[0] is not self.nodes:
            names = self._names = (self.nodes, {n.get("id"): str(n.get("name", "?")) for n in self.nodes})
        return names[1].get(i, "?")

    def name(self, i: int) -> str:
        """A node's name as shown: an include's with the values its arguments had when it started
        (``fetch_item(item="milk")``, not ``fetch_item(item=$item)``), each value cut to 40 characters."""
        return self.args.name(i, self._node_name(i)) if i in self.args.values else self._node_name(i)

    @property
    def cleanup_ids(self) -> Set[int]:
        """The ids of the tree's cleanup (the second node under its ``with_cleanup`` top node); none
        without ``cleanup:``."""
        with self.lock:
            if self._cleanup is None:
                under: Set[int] = set()
                todo = [self.parts()[2]] if self.parts()[2] is not None else []
                while todo:
                    i = todo.pop()
                    under.add(i)
                    todo.extend(n.get("id") for n in self.nodes if n.get("parent") == i and n.get("id") not in under)
                self._cleanup = under
            return self._cleanup

    def _top(self) -> Any:
        return next((n.get("id") for n in self.nodes if n.get("parent") is None), None)

    def parts(self) -> Tuple[Any, Any, Any]:
        """The ids of a tree's ``with_cleanup`` top node, of its root and of its cleanup's top node;
        (None, None, None) for a tree without ``cleanup:``."""
        with self.lock:
            if self._parts is None:
                top = [n for n in self.nodes if n.get("parent") is None]
                below = [n.get("id") for n in self.nodes if top and n.get("parent") == top[0].get("id")]
                self._parts = ((top[0].get("id"), below[0], below[1]) if top and top[0].get("kind") == "with_cleanup"
                               and len(below) == 2 else (None, None, None))
            return self._parts

    def pending_title(self) -> str:
        """The pending calls' panel title: during a tree's cleanup, whose calls they are (``pending
        calls of the cleanup (root stopped)``)."""
        with self.lock:
            mine = [c for c in self.pending.values() if c.get("node") in self.cleanup_ids]
            if not mine:
                return "pending calls"
            ended = self.blackboard.get("ended")
            how = " (root %s)" % ended if isinstance(ended, str) and ended else ""
            if len(mine) == len(self.pending):
                return "pending calls of the cleanup%s" % how
            return "pending calls (%d of the cleanup%s)" % (len(mine), how)

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
