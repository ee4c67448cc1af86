"""The tick loop: py_trees' ``BehaviourTree``, ticked when something happens.

The tree is ticked once at start, then whenever a message arrives (a result, an
event, an answer) or a leaf asked to be woken (timeouts, waits), and at least every
``period`` seconds. A chain of calls therefore runs at the speed of the messages.
What is watched while it runs is py_trees visitors (the status history for tests, the
coverage of the test kit, the status changes that observers such as the display get).
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Set, Tuple

import py_trees
from py_trees.common import Status

from comm.nodelife import BURST
from coordinator.context import WAKE, CallRecord, RunContext, late_answer_text
from coordinator.nodes.task import WithCleanup
from coordinator.reasons import FailureExplainer
from coordinator.runevents import (  # noqa: F401 - Display and NoticeLines: where they were
    Change,
    Display,
    Notice,
    NoticeLines,
    RunObserver,
    StatusWatcher,
    notify,
    status_word,
)
from coordinator.running import while_running

__all__ = ["Display", "NoticeLines", "RunResult", "StatusHistory", "TreeRunner", "Visited", "call_line",
           "cleanup_lines", "cleanup_stop_label", "late_line", "short_json", "shown_status", "stop_label",
           "summary_lines"]


@dataclass
class RunResult:
    status: Status
    duration: float
    calls: List[CallRecord]
    blackboard: Dict[str, Any]
    ticks: int
    reason: str = ""
    history: Dict[Any, List[Status]] = field(default_factory=dict)
    started: float = 0.0  # the clock's time at the first tick (call times are on the same clock)
    failed_call: Optional[CallRecord] = None  # the call of the failure the reason names (its inputs are shown)
    stopped_at: Optional[float] = None  # when it was stopped from outside (Ctrl-C, max_duration), clock time
    # a tree with ``cleanup:``: how root ended (succeeded, failed, stopped), how the cleanup ended (None: it
    # has none, or it never started), why it failed or was cut short, its calls, when it started (clock time)
    ended: str = ""
    cleanup_status: Optional[Status] = None
    cleanup_reason: str = ""
    cleanup_calls: List[CallRecord] = field(default_factory=list)
    cleanup_started: Optional[float] = None
    cleanup_duration: Optional[float] = None
    cleanup_cut_calls: List[CallRecord] = field(default_factory=list)  # those the cut of the cleanup halted

    @property
    def succeeded(self) -> bool:
        return self.status == Status.SUCCESS

    @property
    def cleanup_failed(self) -> bool:
        """The tree's cleanup did not succeed (failed, hit its time limit, was cut short)."""
        return self.cleanup_status is not None and self.cleanup_status != Status.SUCCESS


class StatusHistory(py_trees.visitors.VisitorBase):
    """The statuses each ticked behaviour went through, in order (``run.statuses(name)``), a repeat
    of the same status once; a halt (a RUNNING behaviour stopped: py_trees sets it INVALID) is
    ``INVALID``: ``["RUNNING", "INVALID", "RUNNING", "SUCCESS"]`` for a leaf halted and restarted.
    A finished behaviour that py_trees resets (INVALID after SUCCESS or FAILURE) is no halt: not
    recorded. A visitor sees the behaviours a tick visits; the halts, which the tick does not visit
    (a parent stops its children), come from the status changes of the tick (:meth:`halted`)."""

    def __init__(self) -> None:
        super().__init__(full=False)
        self.history: Dict[Any, List[Status]] = {}

    def run(self, behaviour: py_trees.behaviour.Behaviour) -> None:
        self._add(behaviour, behaviour.status)

    def halted(self, changes: List[Change]) -> None:
        """The behaviours a tick (or a stop from outside) halted: RUNNING before, INVALID now."""
        for b, before, status in changes:
            if status == Status.INVALID and before == Status.RUNNING:
                self._add(b, Status.INVALID)

    def _add(self, behaviour: Any, status: Status) -> None:
        h = self.history.get(behaviour)
        if h is None:
            self.history[behaviour] = [status]
        elif h[-1] != status:
            h.append(status)


class Visited(py_trees.visitors.VisitorBase):
    """The behaviours a tick visited, with their status when visited (for the observers' changes)."""

    def __init__(self) -> None:
        super().__init__(full=False)
        self.visited: List[Tuple[Any, Status]] = []

    def initialise(self) -> None:
        self.visited = []

    def run(self, behaviour: py_trees.behaviour.Behaviour) -> None:
        self.visited.append((behaviour, behaviour.status))


def short_json(value: Any, width: int = 60) -> str:
    """``value`` as compact JSON, cut to ``width`` characters: inputs on a summary line stay one line."""
    text = json.dumps(value, ensure_ascii=False, separators=(",", ":"), default=str)
    return text if len(text) <= width else text[:width - 1] + "…"


def call_line(started: float, target: Any, status: Any, duration: Optional[float], error: Any,
              inputs: Any = None) -> str:
    """One call of an end-of-run summary (the live one and ``bmtree replay``'s print the same lines);
    ``inputs`` are given for the failing call: what it was asked is half of why it failed."""
    dur = "%.3fs" % duration if duration is not None else "-"
    line = "  +%7.3fs  %-26s %-11s %8s  %s" % (started, target, status, dur, error or "")
    if inputs is not None:
        line += "%sinputs %s" % ("  " if error else "", short_json(inputs))
    return line.rstrip()


def late_line(text: str) -> str:
    """Under its call in an end-of-run summary (live and ``bmtree replay``): the answer that came after
    the call had ended (``text``: its notice, which says when). Not a call's line: no ``+`` time."""
    return " " * 14 + "late answer: " + text


def stop_label(interrupted: bool, reason: str) -> Tuple[str, str]:
    """(status, error) shown for a call halted because the run was stopped from outside, instead of
    the call's own "halted by the tree": ``interrupted`` for Ctrl-C, the limit for ``max_duration``."""
    if interrupted:
        return "interrupted", ""
    return "halted", reason.split(" while ", 1)[0] or "the run was stopped"


def cleanup_stop_label(reason: str) -> Tuple[str, str]:
    """(status, error) shown for a call of a tree's cleanup halted when the cleanup was cut short,
    instead of the call's own "halted by the tree": ``interrupted`` for a Ctrl-C, else its time limit
    (``halted  did not end within 30 s (cleanup_timeout)``)."""
    if reason.startswith("interrupted"):
        return "interrupted", ""
    return "halted", reason.split(" while ", 1)[0] or "the cleanup was cut short"


def shown_status(result: RunResult, c: CallRecord, cleanup: Optional[Set[int]] = None,
                 cut: Optional[Set[int]] = None) -> Tuple[str, str]:
    """(status, error) of call ``c`` as an end-of-run summary shows it (and the kit's ``run.label``): a
    call the stop from outside halted says so (:func:`stop_label`), and so does one halted when the
    cleanup was cut short (:func:`cleanup_stop_label`: the calls :meth:`WithCleanup.end_cleanup` halted,
    as ``bmtree replay`` finds them: halted after the tick before the one that halted the cleanup).
    ``cleanup``, ``cut``: the ids of the cleanup's calls and of the cut ones, when known already."""
    status, error = str(c.status), c.error
    if status != "halted" or c.ended is None:
        return status, error
    if id(c) in (cut if cut is not None else {id(k) for k in result.cleanup_cut_calls}):
        return cleanup_stop_label(result.cleanup_reason)
    cleanup = cleanup if cleanup is not None else {id(k) for k in result.cleanup_calls}
    if result.stopped_at is not None and c.ended >= result.stopped_at and id(c) not in cleanup:
        return stop_label(result.status == Status.INVALID, result.reason)
    return status, error


def summary_lines(result: RunResult, tree_name: str) -> List[str]:
    """The end-of-run summary: result (``INTERRUPTED`` for a run stopped by Ctrl-C), reason, every call
    (the failing one with its inputs; those the stop from outside, or the end of a cut cleanup, halted
    said so)."""
    lines = ["", "%s: %s in %.2f s (%d ticks)" % (tree_name, status_word(result.status), result.duration,
                                                   result.ticks)]
    if result.reason and not result.succeeded:
        lines.append("reason: %s" % result.reason)
    lines.append("calls:")
    cleanup = {id(c) for c in result.cleanup_calls}
    cut = {id(c) for c in result.cleanup_cut_calls}
    for c in [c for c in result.calls if id(c) not in cleanup] + [None] + list(result.cleanup_calls):
        if c is None:
            lines.extend(cleanup_lines(result))
            continue
        status, error = shown_status(result, c, cleanup, cut)
        lines.append(call_line(c.started - result.started, c.target, status, c.duration, error,
                               c.inputs if c is result.failed_call else None))
        if c.late_at is not None:
            lines.append(late_line(late_answer_text(c, result.started)))
    return lines


def cleanup_lines(result: RunResult) -> List[str]:
    """The cleanup's line of an end-of-run summary (its calls follow it): how it ended, after which ending
    of root; nothing for a tree without ``cleanup:``."""
    if result.cleanup_status is None and not result.ended:
        return []
    if result.cleanup_status is None:
        return ["cleanup (root %s): did not run" % result.ended]
    said = {"SUCCESS": "succeeded", "FAILURE": "FAILED", "INVALID": "cut short"}[result.cleanup_status.value]
    took = " in %.2f s" % result.cleanup_duration if result.cleanup_duration is not None else ""
    why = ": %s" % result.cleanup_reason if result.cleanup_reason and result.cleanup_failed else ""
    return ["cleanup (root %s): %s%s%s" % (result.ended, said, took, why)]


class TreeRunner:
    """Ticks ``root`` on a py_trees ``BehaviourTree`` until it ends.

    Args:
        visitors: more py_trees visitors for every tick (the test kit's coverage).
        observers: RunObservers (``coordinator.runevents``); they are also given to ``ctx``.
        display: an observer shown the tree as it runs (kept apart for callers that name it).
        tree: the loaded TreeFile, passed to ``on_start``.
    """

    def __init__(self, root: py_trees.behaviour.Behaviour, ctx: RunContext, period: float = 0.25,
                 display: Optional[RunObserver] = None, record_history: bool = False,
                 visitors: Sequence[py_trees.visitors.VisitorBase] = (),
                 observers: Sequence[RunObserver] = (), tree: Any = None, gate: Any = None):
        self.root = root
        self.gate = gate  # may_tick() -> bool: the steering of run --control (coordinator.control)
        self.result: Optional[RunResult] = None  # once run() ended, also when it was interrupted
        self.ctx = ctx
        self.period = period
        self.tree_file = tree
        self.tree = py_trees.trees.BehaviourTree(root)
        self.explainer = FailureExplainer()  # always: the run's reason names the root cause
        self.observers: List[RunObserver] = list(observers) + ([display] if display is not None else [])
        self.observers.append(self.explainer)
        for o in self.observers:
            if o not in ctx.observers:
                ctx.observers.append(o)
        self._history = StatusHistory() if record_history else None
        self._visited = Visited() if ctx.observers or record_history else None
        self._watcher = StatusWatcher()
        for v in [self._history, self._visited, *visitors]:
            if v is not None:
                self.tree.add_visitor(v)

    @property
    def history(self) -> Dict[Any, List[Status]]:
        return self._history.history if self._history is not None else {}

    @property
    def ticks(self) -> int:
        return self.tree.count

    def tick(self) -> None:
        """One tick, its status changes told to the observers (a step of :meth:`run`; benchmarks)."""
        with self.ctx.transport.hold():
            self.ctx.ticks_done += 1
            self.tree.tick()
        if self._visited is not None:
            self._tell(self._visited.visited)

    def _tell(self, visited: List[Tuple[Any, Status]]) -> None:
        """Observers get the status changes (after a tick, or after a stop outside a tick: ``[]``); the
        status history its halts."""
        if self._visited is None:
            return
        changes = self._watcher.changes(visited)
        if self._history is not None:
            self._history.halted(changes)
        if self.ctx.observers:
            notify(self.ctx.observers, "on_tick", self.root, changes, self.ctx.clock.now())

    def run(self, max_duration: Optional[float] = None, stop_when: Optional[Callable[[], str]] = None,
            guard: Optional[Callable[[], str]] = None) -> RunResult:
        """Tick until the root ends, ``max_duration`` seconds of its clock pass, or ``stop_when()`` or
        ``guard()`` gives a reason (asked after each tick); stopped is FAILURE.

        With ``cleanup:`` (the root behaviour is a :class:`WithCleanup`) the cleanup runs once after
        root ended, also when it was stopped (root halted first), bounded by its own time limit; a
        stop signal (KeyboardInterrupt) during it ends it at once. The result is root's. ``guard``
        (the test kit's tick limits) is asked during the cleanup too, and cuts it short: on a
        simulated clock a livelock never reaches the cleanup's time limit."""
        ctx = self.ctx
        ctx.transport.connect(ctx.inbox.put)
        self.tree.setup()
        start = ctx.started = ctx.clock.now()  # the notices of late answers say times from here
        if ctx.observers:
            notify(ctx.observers, "on_start", self.tree_file, self.root, ctx)
        task = self.root if isinstance(self.root, WithCleanup) else None
        main = task.root if task is not None else self.root
        reason = ""
        stopped_at: Optional[float] = None
        failed_call: Optional[CallRecord] = None
        try:
            while True:
                if self.gate is None or self.gate.may_tick():
                    self.tick()
                if task is None and self.root.status in (Status.SUCCESS, Status.FAILURE):
                    break
                if task is not None and task.done:
                    break
                if task is not None and task.phase == "between":  # root ended by itself: its reason, then cleanup
                    if task.root_status == Status.FAILURE:
                        reason = self.explainer.reason(main, under=True)
                        failed_call = self._failed_call(main)
                    self._begin_cleanup(task, "succeeded" if task.root_status == Status.SUCCESS else "failed",
                                        reason)
                    continue
                if task is None or task.phase == "root":
                    if max_duration is not None and ctx.clock.now() - start >= max_duration:
                        reason = "stopped after %g s" % max_duration
                    elif stop_when is not None:
                        reason = stop_when()
                    if not reason and guard is not None:
                        reason = guard()
                    if reason:
                        reason += while_running(main)
                        stopped_at = ctx.clock.now()
                        if task is None:
                            self.root.stop(Status.INVALID)
                            self._tell([])
                            break
                        task.stop_root()
                        self._tell([])
                        self._begin_cleanup(task, "stopped", reason)
                        continue
                elif self._cleanup_over_time(task) or self._cleanup_guarded(task, guard):
                    break
                self._wait(self._until(start, max_duration, task))
        except BaseException as exc:
            cut = task is not None and isinstance(exc, KeyboardInterrupt) and not task.done
            if cut and task is not None and task.phase == "cleanup":  # root had ended: the cleanup ends at once
                self._end_cleanup(task, Status.INVALID, "interrupted" + while_running(task.cleanup))
                return self._finish(start, task, reason, failed_call, stopped_at)
            why = "interrupted" + while_running(main)
            stopped_at = ctx.clock.now()
            if cut and task is not None and task.phase in ("root", "between"):
                self._cleanup_after_stop(task, why)
            else:
                self.root.stop(Status.INVALID)
                self._tell([])
            self.result = self._result(Status.INVALID, start, why, None, stopped_at, task)
            if ctx.observers:
                notify(ctx.observers, "on_end", self.result)
            raise
        return self._finish(start, task, reason, failed_call, stopped_at)

    def _finish(self, start: float, task: Optional[WithCleanup], reason: str, failed_call: Optional[CallRecord],
                stopped_at: Optional[float]) -> RunResult:
        """The result of a run that ended (the root's ending; stopped by max_duration: FAILURE)."""
        status = task.root_status if task is not None else self.root.status
        if reason and stopped_at is not None:  # stopped by max_duration: the task did not get done
            status = Status.FAILURE
        elif status == Status.FAILURE and task is None:
            reason = self.explainer.reason(self.root)
            failed_call = self._failed_call()
        result = self._result(status, start, reason, failed_call, stopped_at, task)
        self.result = result
        if self.ctx.observers:
            notify(self.ctx.observers, "on_end", result)
        return result

    def _result(self, status: Status, start: float, reason: str, failed_call: Optional[CallRecord],
                stopped_at: Optional[float], task: Optional[WithCleanup]) -> RunResult:
        ctx = self.ctx
        now = ctx.clock.now()
        result = RunResult(status=status, duration=now - start, calls=list(ctx.calls),
                           blackboard=dict(ctx.blackboard), ticks=self.ticks, reason=reason, history=self.history,
                           started=start, failed_call=failed_call, stopped_at=stopped_at)
        if task is not None:
            self._cleanup_said(task)
            under = set(task.cleanup.iterate())
            result.ended = task.ended
            result.cleanup_status, result.cleanup_reason = task.cleanup_status, task.cleanup_reason
            result.cleanup_calls = [c for c in result.calls if c.owner in under]
            result.cleanup_started = task.cleanup_started
            result.cleanup_cut_calls = list(task.cut_calls)
            if task.cleanup_started is not None:
                result.cleanup_duration = (task.cleanup_ended if task.cleanup_ended is not None else now) \
                    - task.cleanup_started
        return result

    def _until(self, start: float, max_duration: Optional[float], task: Optional[WithCleanup]) -> float:
        """How long to wait for something to happen: the period, or less to wake at a limit."""
        wait = self.period
        now = self.ctx.clock.now()
        if task is not None and task.phase == "cleanup" and task.cleanup_started is not None:
            return min(wait, max(0.0, task.cleanup_started + task.limit - now))
        if max_duration is not None:  # wake at the limit, not at the next period after it
            wait = min(wait, max(0.0, start + max_duration - now))
        return wait

    def _wait(self, wait: float) -> None:
        """Wait up to ``wait`` seconds for messages, then hand over all that came."""
        ctx = self.ctx
        item = ctx.clock.wait(ctx.inbox, wait)
        while item is not None:
            if item is not WAKE:
                ctx.dispatch(item)
            try:
                item = ctx.inbox.get_nowait()
            except Exception:
                item = None

    # the cleanup ------------------------------------------------------------------------
    def _notice(self, what: str, text: str) -> None:
        if self.ctx.observers:
            notify(self.ctx.observers, "on_notice", Notice(what, text), self.ctx.clock.now())

    def _begin_cleanup(self, task: WithCleanup, ended: str, reason: str, signalled: bool = False) -> None:
        task.begin_cleanup(ended, reason)
        if ended == "stopped":  # the operator waits for the run to end: say why it goes on
            self._notice("cleanup", "%s: running the cleanup (at most %g s%s)" % (
                reason or "stopped", task.limit, "; Ctrl-C again ends it at once" if signalled else ""))

    def _end_cleanup(self, task: WithCleanup, status: Status, reason: str) -> None:
        """The cleanup cut short (its time limit, a second stop): halted, its calls cancelled."""
        task.cleanup_cut = True
        task.end_cleanup(status, reason)
        self._tell([])

    def _cleanup_said(self, task: WithCleanup) -> None:
        """Once: a cleanup that failed by itself gets its reason (the root cause in it, as a run's); one that
        failed or was cut short is told (a notice: the display, the run stream and log, watch, replay)."""
        if task.cleanup_status in (None, Status.SUCCESS) or task.cleanup_told:
            return
        task.cleanup_told = True
        if task.cleanup_status == Status.FAILURE and not task.cleanup_cut:
            task.cleanup_reason = self.explainer.reason(task.cleanup, under=True) or task.cleanup_reason
        self._notice("cleanup_failed", "the cleanup %s (root %s): %s; the run's result stays root's" % (
            "failed" if task.cleanup_status == Status.FAILURE else "was cut short", task.ended,
            task.cleanup_reason or "no reason given"))

    def _cleanup_over_time(self, task: WithCleanup) -> bool:
        """True (the cleanup halted) once the cleanup ran its time limit."""
        if task.phase != "cleanup" or task.cleanup_started is None:
            return False
        if self.ctx.clock.now() - task.cleanup_started < task.limit:
            return False
        self._end_cleanup(task, Status.FAILURE, "did not end within %g s (cleanup_timeout)%s"
                          % (task.limit, while_running(task.cleanup)))
        return True

    def _cleanup_guarded(self, task: WithCleanup, guard: Optional[Callable[[], str]]) -> bool:
        """True (the cleanup halted) once ``guard`` gives a reason while the cleanup runs."""
        why = guard() if guard is not None and task.phase == "cleanup" else ""
        if why:
            self._end_cleanup(task, Status.FAILURE, why + while_running(task.cleanup))
        return bool(why)

    def _cleanup_after_stop(self, task: WithCleanup, why: str) -> None:
        """A run stopped by a signal (KeyboardInterrupt): root halted, then the cleanup ticked until it
        ends or runs its time limit; a second stop (not one of the same burst, within ``BURST`` s) ends
        it at once."""
        stopped = time.monotonic()
        while not task.done:
            try:
                if task.phase in ("root", "between"):  # (again, if a signal of the burst cut this short)
                    task.stop_root()
                    self._tell([])
                    self._begin_cleanup(task, "stopped", why, signalled=True)
                    continue
                if self.gate is None or self.gate.may_tick():
                    self.tick()
                if task.done or self._cleanup_over_time(task):
                    break
                self._wait(self._until(0.0, None, task))
            except KeyboardInterrupt:
                if time.monotonic() - stopped < BURST:  # the same stop, signalled again (a process group)
                    continue
                if task.phase in ("root", "between"):
                    task.stop_root()
                    task.begin_cleanup("stopped", why)
                self._end_cleanup(task, Status.INVALID, "interrupted again" + while_running(task.cleanup))

    def _failed_call(self, top: Any = None) -> Optional[CallRecord]:
        """The latest call made at or under the node where the failure the reason names started
        (the failed call itself, or the call a timeout halted) before that failure (``top``: only a
        failure at or under it, the root of a tree with a cleanup)."""
        o = self.explainer.root_cause() if top is None else self.explainer.root_cause_under(top)
        if o is None:
            return None
        under = set(o.behaviour.iterate())
        made = [c for c in self.ctx.calls if c.owner in under and c.started <= o.time]
        return made[-1] if made else None
