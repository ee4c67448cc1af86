"""The tick loop: event-driven, one thread, with a display and a final report.

The tree is ticked once at start, then whenever a message arrives (a result, an
event, an answer) or a leaf asked to be woken (timeouts, waits), and at least every
``period`` seconds. A chain of calls therefore runs at the speed of the messages.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, TextIO

import py_trees
from py_trees.common import Status

from coordinator.context import WAKE, CallRecord, RunContext

__all__ = ["RunResult", "TreeRunner", "Display"]


@dataclass
class RunResult:
    status: Status
    duration: float
    calls: List[CallRecord]
    blackboard: Dict[str, Any]
    ticks: int
    reason: str = ""
    history: Dict[Any, List[Status]] = field(default_factory=dict)

    @property
    def succeeded(self) -> bool:
        return self.status == Status.SUCCESS


def _failure_reason(root: py_trees.behaviour.Behaviour) -> str:
    """The feedback of the deepest failed behaviour, the likeliest cause."""
    reason = ""
    for b in root.iterate():
        if b.status == Status.FAILURE and b.feedback_message:
            reason = "%s: %s" % (b.name, b.feedback_message)
    return reason


class Display:
    """Shows the tree with statuses: redrawn in place on a terminal, as changed lines otherwise."""

    def __init__(self, stream: TextIO = sys.stdout, tty: Optional[bool] = None, min_interval: float = 0.1):
        self.stream = stream
        self.tty = stream.isatty() if tty is None else tty
        self.min_interval = min_interval
        self._last: Dict[Any, Status] = {}
        self._drawn = 0.0
        self._lines = 0

    def __call__(self, root: py_trees.behaviour.Behaviour, now: float, final: bool = False) -> None:
        if self.tty:
            if not final and now - self._drawn < self.min_interval:
                return
            self._drawn = now
            text = py_trees.display.unicode_tree(root, show_status=True)
            if self._lines:
                self.stream.write("\x1b[%dA\x1b[J" % self._lines)
            self.stream.write(text + "\n")
            self._lines = text.count("\n") + 1
        else:
            for b in root.iterate():
                before = self._last.get(b.id)
                if before != b.status:
                    if b.status != Status.INVALID:
                        extra = " (%s)" % b.feedback_message if b.status == Status.FAILURE and b.feedback_message else ""
                        self.stream.write("[%7.3fs] %-9s %s%s\n" % (now, b.status.value, b.name, extra))
                    elif before == Status.RUNNING:
                        self.stream.write("[%7.3fs] %-9s %s\n" % (now, "HALTED", b.name))
                    self._last[b.id] = b.status
        self.stream.flush()


class TreeRunner:
    def __init__(self, root: py_trees.behaviour.Behaviour, ctx: RunContext, period: float = 0.25,
                 display: Optional[Callable[..., None]] = None, record_history: bool = False):
        self.root = root
        self.ctx = ctx
        self.period = period
        self.display = display
        self.record_history = record_history
        self.history: Dict[Any, List[Status]] = {}
        self.ticks = 0

    def _tick(self) -> None:
        """One tick; with ``record_history``, note the status of every node it visited."""
        if not self.record_history:
            self.root.tick_once()
            return
        for b in self.root.tick():
            h = self.history.get(b)
            if h is None:
                self.history[b] = [b.status]
            elif h[-1] != b.status:
                h.append(b.status)

    def run(self, max_duration: Optional[float] = None) -> RunResult:
        ctx = self.ctx
        self.ctx.transport.connect(ctx.inbox.put)
        self.root.setup_with_descendants()
        start = ctx.clock.now()
        reason = ""
        try:
            while True:
                self._tick()
                self.ticks += 1
                if self.display is not None:
                    self.display(self.root, ctx.clock.now() - start)
                if self.root.status in (Status.SUCCESS, Status.FAILURE):
                    break
                if max_duration is not None and ctx.clock.now() - start >= max_duration:
                    self.root.stop(Status.INVALID)
                    reason = "stopped after %gs" % max_duration
                    break
                item = ctx.clock.wait(ctx.inbox, self.period)
                while item is not None:
                    if item is not WAKE:
                        ctx.dispatch(item)
                    try:
                        item = ctx.inbox.get_nowait()
                    except Exception:
                        item = None
        except BaseException:
            self.root.stop(Status.INVALID)
            raise
        if self.display is not None:
            self.display(self.root, ctx.clock.now() - start, final=True)
        if self.root.status == Status.FAILURE:
            reason = _failure_reason(self.root)
        return RunResult(status=self.root.status, duration=ctx.clock.now() - start, calls=list(ctx.calls),
                         blackboard=dict(ctx.blackboard), ticks=self.ticks, reason=reason, history=self.history)
