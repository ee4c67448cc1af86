"""The tick loop: py_trees' ``BehaviourTree``, ticked when something happens.

The tree is ticked once at start, then whenever a message arrives (a result, an
event, an answer) or a leaf asked to be woken (timeouts, waits), and at least every
``period`` seconds. A chain of calls therefore runs at the speed of the messages.
What is watched while it runs is py_trees visitors (the status history for tests, the
coverage of the test kit, the status changes that observers such as the display get).
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, TextIO, Tuple

import py_trees
from py_trees.common import Status

from coordinator.context import WAKE, CallRecord, RunContext, late_answer_text
from coordinator.reasons import FailureExplainer
from coordinator.runevents import Change, RunObserver, StatusWatcher, control_line, notify
from coordinator.running import while_running

__all__ = ["Display", "NoticeLines", "RunResult", "StatusHistory", "TreeRunner", "Visited", "call_line", "late_line",
           "short_json", "stop_label", "summary_lines"]


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

    @property
    def succeeded(self) -> bool:
        return self.status == Status.SUCCESS


class StatusHistory(py_trees.visitors.VisitorBase):
    """The statuses each ticked behaviour went through, in order (``run.statuses(name)``)."""

    def __init__(self) -> None:
        super().__init__(full=False)
        self.history: Dict[Any, List[Status]] = {}

    def run(self, behaviour: py_trees.behaviour.Behaviour) -> None:
        h = self.history.get(behaviour)
        if h is None:
            self.history[behaviour] = [behaviour.status]
        elif h[-1] != behaviour.status:
            h.append(behaviour.status)


class Visited(py_trees.visitors.VisitorBase):
    """The behaviours a tick visited, with their status when visited (for the observers' changes)."""

    def __init__(self) -> None:
        super().__init__(full=False)
        self.visited: List[Tuple[Any, Status]] = []

    def initialise(self) -> None:
        self.visited = []

    def run(self, behaviour: py_trees.behaviour.Behaviour) -> None:
        self.visited.append((behaviour, behaviour.status))


class NoticeLines(RunObserver):
    """Without the display (``-q``, ``run.launch``): the notices about the ROS graph (the master
    went away and came back, another run started) still reach the operator, on stderr."""

    def __init__(self, stream: TextIO = sys.stderr):
        self.stream = stream
        self._start = 0.0

    def on_start(self, tree: Any, root: Any, ctx: Any) -> None:
        self._start = ctx.clock.now()

    def on_notice(self, notice: Any, now: float) -> None:
        self.stream.write("[%7.3fs] NOTICE    %s\n" % (now - self._start, notice.text))
        self.stream.flush()


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


def summary_lines(result: RunResult, tree_name: str) -> List[str]:
    """The end-of-run summary: result, reason, every call (the failing one with its inputs; those the
    stop from outside halted said so)."""
    lines = ["", "%s: %s in %.2f s (%d ticks)" % (tree_name, result.status.value, result.duration, result.ticks)]
    if result.reason and not result.succeeded:
        lines.append("reason: %s" % result.reason)
    lines.append("calls:")
    for c in result.calls:
        status, error = c.status, c.error
        if (result.stopped_at is not None and str(status) == "halted" and c.ended is not None
                and c.ended >= result.stopped_at):
            status, error = stop_label(result.status == Status.INVALID, result.reason)
        lines.append(call_line(c.started - result.started, c.target, status, c.duration, error,
                               c.inputs if c is result.failed_call else None))
        if c.late_at is not None:
            lines.append(late_line(late_answer_text(c, result.started)))
    return lines


class Display(RunObserver):
    """Shows the tree with statuses: redrawn in place on a terminal, as changed lines otherwise."""

    def __init__(self, stream: TextIO = sys.stdout, tty: Optional[bool] = None, min_interval: float = 0.1):
        self.stream = stream
        self.tty = stream.isatty() if tty is None else tty
        self.min_interval = min_interval
        self.root: Optional[py_trees.behaviour.Behaviour] = None
        self._drawn: Optional[float] = None
        self._lines = 0
        self._start = 0.0
        self._note = ""  # the latest control answer or notice, under the tree on a terminal

    def on_start(self, tree: Any, root: Any, ctx: Any) -> None:
        self.root = root
        self._start = ctx.clock.now()

    def on_tick(self, root: Any, changes: List[Change], now: float) -> None:
        self.root = root
        now -= self._start          # shown as seconds since the start
        if self.tty:
            if self._drawn is None or now - self._drawn >= self.min_interval:
                self._draw(now)
            return
        for b, before, status in changes:
            if status != Status.INVALID:
                extra = " (%s)" % b.feedback_message if status == Status.FAILURE and b.feedback_message else ""
                self.stream.write("[%7.3fs] %-9s %s%s\n" % (now, status.value, b.name, extra))
            elif before == Status.RUNNING:
                self.stream.write("[%7.3fs] %-9s %s\n" % (now, "HALTED", b.name))
        self.stream.flush()

    def on_control(self, record: Any, now: float) -> None:
        self._line(now, "CONTROL", control_line(record), "control: ")

    def on_notice(self, notice: Any, now: float) -> None:
        self._line(now, "NOTICE", notice.text)

    def _line(self, now: float, kind: str, text: str, label: str = "") -> None:
        """A line between the status changes; on a terminal the latest stays under the tree."""
        if self.tty:
            self._note = label + text
            if self.root is not None:
                self._draw(now - self._start)
            return
        self.stream.write("[%7.3fs] %-9s %s\n" % (now - self._start, kind, text))
        self.stream.flush()

    def on_end(self, result: Any) -> None:
        if self.tty and self.root is not None:
            self._draw(result.duration)

    def _draw(self, now: float) -> None:
        self._drawn = now
        text = py_trees.display.unicode_tree(self.root, show_status=True)
        if self._note:
            text += "\n" + self._note
        if self._lines:
            self.stream.write("\x1b[%dA\x1b[J" % self._lines)
        self.stream.write(text + "\n")
        self._lines = text.count("\n") + 1
        self.stream.flush()


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
        self._visited = Visited() if ctx.observers else None
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
        """Observers get the status changes (after a tick, or after a stop outside a tick: ``[]``)."""
        if self._visited is not None and self.ctx.observers:
            notify(self.ctx.observers, "on_tick", self.root, self._watcher.changes(visited), self.ctx.clock.now())

    def run(self, max_duration: Optional[float] = None, stop_when: Optional[Callable[[], str]] = None) -> RunResult:
        """Tick until the root ends, ``max_duration`` seconds of its clock pass, or ``stop_when()``
        gives a reason (asked after each tick; the test kit's tick limits); stopped is FAILURE."""
        ctx = self.ctx
        ctx.transport.connect(ctx.inbox.put)
        self.tree.setup()
        start = ctx.started = ctx.clock.now()  # the notices of late answers say times from here
        if ctx.observers:
            notify(ctx.observers, "on_start", self.tree_file, self.root, ctx)
        reason = ""
        stopped_at: Optional[float] = None
        failed_call: Optional[CallRecord] = None
        try:
            while True:
                if self.gate is None or self.gate.may_tick():
                    self.tick()
                if self.root.status in (Status.SUCCESS, Status.FAILURE):
                    break
                if max_duration is not None and ctx.clock.now() - start >= max_duration:
                    reason = "stopped after %g s" % max_duration
                elif stop_when is not None:
                    reason = stop_when()
                if reason:
                    reason += while_running(self.root)
                    stopped_at = ctx.clock.now()
                    self.root.stop(Status.INVALID)
                    self._tell([])
                    break
                wait = self.period
                if max_duration is not None:  # wake at the limit, not at the next period after it
                    wait = min(wait, max(0.0, start + max_duration - ctx.clock.now()))
                item = ctx.clock.wait(ctx.inbox, wait)
                while item is not None:
                    if item is not WAKE:
                        ctx.dispatch(item)
                    try:
                        item = ctx.inbox.get_nowait()
                    except Exception:
                        item = None
        except BaseException:
            why = "interrupted" + while_running(self.root)
            stopped_at = ctx.clock.now()
            self.root.stop(Status.INVALID)
            self._tell([])
            self.result = RunResult(status=Status.INVALID, duration=ctx.clock.now() - start, calls=list(ctx.calls),
                                    blackboard=dict(ctx.blackboard), ticks=self.ticks, reason=why,
                                    history=self.history, started=start, stopped_at=stopped_at)
            if ctx.observers:
                notify(ctx.observers, "on_end", self.result)
            raise
        status = self.root.status
        if reason:  # stopped by max_duration: the task did not get done
            status = Status.FAILURE
        elif status == Status.FAILURE:
            reason = self.explainer.reason(self.root)
            failed_call = self._failed_call()
        result = RunResult(status=status, duration=ctx.clock.now() - start, calls=list(ctx.calls),
                           blackboard=dict(ctx.blackboard), ticks=self.ticks, reason=reason, history=self.history,
                           started=start, failed_call=failed_call, stopped_at=stopped_at)
        self.result = result
        if ctx.observers:
            notify(ctx.observers, "on_end", result)
        return result

    def _failed_call(self) -> Optional[CallRecord]:
        """The latest call made at or under the node where the failure the reason names started
        (the failed call itself, or the call a timeout halted) before that failure."""
        o = self.explainer.root_cause()
        if o is None:
            return None
        under = set(o.behaviour.iterate())
        made = [c for c in self.ctx.calls if c.owner in under and c.started <= o.time]
        return made[-1] if made else None
