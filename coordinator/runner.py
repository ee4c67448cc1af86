"""The tick loop: py_trees' ``BehaviourTree``, ticked when something happens.

The tree is ticked once at start, then whenever a message arrives (a result, an
event, an answer) or a leaf asked to be woken (timeouts, waits), and at least every
``period`` seconds. A chain of calls therefore runs at the speed of the messages.
What is watched while it runs is py_trees visitors (the status history for tests, the
coverage of the test kit, the status changes that observers such as the display get).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import py_trees
from py_trees.common import Status

from comm.nodelife import BURST
from coordinator.context import WAKE, CallRecord, RunContext
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
from coordinator.runlines import (  # noqa: F401 - where they were
    call_line,
    cleanup_lines,
    cleanup_stop_label,
    late_line,
    short_json,
    shown_status,
    stop_label,
    summary_lines,
)
from coordinator.running import while_running

__all__ = ["Display", "NoticeLines", "RunResult", "StatusHistory", "TreeRunner", "Visited", "call_line",
           "cleanup_lines", "cleanup_stop_label", "late_line", "short_json", "shown_status", "stop_label",
           "summary_lines"]

#: seconds ``bmtree run`` waits after the run for the modules to answer the cancels of the calls it stopped (a
#: module's runtime answers once the code returned, or after its 1 s grace when it does not)
CANCEL_CONFIRM = 1.5

KILL_AFTER = 1e-6
"""How long after ``kill_at`` a killed run ends (so that what came at ``kill_at`` itself is ticked)."""


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
    # where the failure the reason (cleanup_reason) names is written: ``FILE:LINE:COLUMN`` [``in INCLUDE``]
    failed_at: str = ""
    cleanup_failed_at: str = ""
    #: what ``bmtree control`` changed (forced outcomes, blackboard writes): ``3.10s 'grasp' forced to SUCCESS``
    steered: List[str] = field(default_factory=list)

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
        self._halts = [v for v in visitors if hasattr(v, "halted")]   # told the halts, as the history is

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
        for v in ([self._history] if self._history is not None else []) + self._halts:
            v.halted(changes)
        if self.ctx.observers:
            notify(self.ctx.observers, "on_tick", self.root, changes, self.ctx.clock.now())

    def run(self, max_duration: Optional[float] = None, stop_when: Optional[Callable[[], str]] = None,
            guard: Optional[Callable[[], str]] = None, kill_at: Optional[float] = None) -> RunResult:
        """Tick until the root ends, ``max_duration`` seconds of its clock pass, or ``stop_when()`` or
        ``guard()`` gives a reason (asked after each tick), or the gate takes a stop (``bmtree control
        stop``: asked before each tick); stopped is FAILURE.

        With ``cleanup:`` (the root behaviour is a :class:`WithCleanup`) the cleanup runs once after
        root ended, also when it was stopped (root halted first), bounded by its own time limit; a
        stop signal (KeyboardInterrupt) during it ends it at once. The result is root's. ``guard``
        (the test kit's tick limits) is asked during the cleanup too, and cuts it short: on a
        simulated clock a livelock never reaches the cleanup's time limit. ``kill_at`` (seconds from the
        start; a scenario of a run whose process was killed) ends the run there as the kill did: nothing
        is ticked after what came at that time, a running root or cleanup is halted, and a cleanup not
        begun never runs."""
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
                if kill_at is not None and ctx.clock.now() - start > kill_at:  # what came at kill_at was ticked
                    reason, stopped_at = self._killed(task, main, kill_at, reason, stopped_at)
                    break
                ticking = self.gate is None or self.gate.may_tick()
                asked = self._asked_stop()  # a control stop: no tick after it, also while paused
                if ticking and not asked:
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
                    if asked:
                        reason = asked
                    elif max_duration is not None and ctx.clock.now() - start >= max_duration:
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
                self._wait(self._until(start, max_duration, task, kill_at))
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

    def _asked_stop(self) -> str:
        """The reason of a stop the gate accepted (``bmtree control stop``), or '': root is stopped with it
        as with ``max_duration`` (FAILURE, the cleanup runs with ``ended`` = stopped)."""
        take = getattr(self.gate, "take_stop", None)
        return take() if take is not None else ""

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
        result.steered = ["%.2fs %s" % (t - start, text) for t, text in getattr(self.gate, "steered", ())]
        if status == Status.FAILURE and stopped_at is None:
            result.failed_at = self.explainer.failed_at(task.root if task is not None else self.root,
                                                        under=task is not None)
        if task is not None:
            self._cleanup_said(task)
            under = set(task.cleanup.iterate())
            result.ended = task.ended
            result.cleanup_status, result.cleanup_reason = task.cleanup_status, task.cleanup_reason
            if task.cleanup_status == Status.FAILURE:
                result.cleanup_failed_at = self.explainer.failed_at(task.cleanup, under=True)
            result.cleanup_calls = [c for c in result.calls if c.owner in under]
            result.cleanup_started = task.cleanup_started
            result.cleanup_cut_calls = list(task.cut_calls)
            if task.cleanup_started is not None:
                result.cleanup_duration = (task.cleanup_ended if task.cleanup_ended is not None else now) \
                    - task.cleanup_started
        return result

    def _until(self, start: float, max_duration: Optional[float], task: Optional[WithCleanup],
               kill_at: Optional[float] = None) -> float:
        """How long to wait for something to happen: the period, or less to wake at a limit."""
        wait = self.period
        now = self.ctx.clock.now()
        if kill_at is not None:  # wake just after it: everything at kill_at is ticked first
            wait = min(wait, max(0.0, start + kill_at + KILL_AFTER - now))
        if task is not None and task.phase == "cleanup" and task.cleanup_started is not None:
            return min(wait, max(0.0, task.cleanup_started + task.limit - now))
        if max_duration is not None:  # wake at the limit, not at the next period after it
            wait = min(wait, max(0.0, start + max_duration - now))
        return wait

    def _killed(self, task: Optional[WithCleanup], main: Any, kill_at: float, reason: str,
                stopped_at: Optional[float]) -> Tuple[str, Optional[float]]:
        """The run ended by ``kill_at`` (its root or its cleanup runs): halted, without a cleanup after
        root; the run's reason and stop time."""
        killed = "killed after %g s" % kill_at
        if task is not None and task.phase == "cleanup":
            self._end_cleanup(task, Status.INVALID, killed + while_running(task.cleanup))
            return reason, stopped_at
        reason, stopped_at = killed + while_running(main), self.ctx.clock.now()
        self.root.stop(Status.INVALID)
        self._tell([])
        return reason, stopped_at

    def confirm_cancels(self, wait: float = CANCEL_CONFIRM) -> List[CallRecord]:
        """After the run: wait up to ``wait`` seconds for the answers to the cancels of the calls the tree
        stopped (a module answers at once, or after its cancel's grace when the call's code goes on); the
        calls that may still run on their module (``maybe_running``), which the summary says."""
        ctx = self.ctx
        end = ctx.clock.now() + wait
        while True:
            waiting = [c for c in ctx.calls if c.cancel_sent and not c.cancel_answer and c.late_status is None]
            left = end - ctx.clock.now()
            if not waiting or left <= 0:
                break
            self._wait(min(0.05, left))
        return [c for c in ctx.calls if c.maybe_running]

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
        unpause = getattr(self.gate, "unpause", None)
        if unpause is not None:  # paused, the cleanup would not be ticked until its time limit
            unpause("interrupted: the pause ends, so that the cleanup runs")
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
        # a call that succeeded is not the failure's (a call leaf whose next call could not be built: no record)
        return made[-1] if made and made[-1].status != "succeeded" else None
