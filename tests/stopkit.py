"""Stopping a test-kit run from outside, as ``bmtree run``'s Ctrl-C does, and keeping what it ended with."""
from __future__ import annotations

from typing import Any, List

from coordinator.runevents import RunObserver

__all__ = ["CtrlC", "Kept", "GO_ROOT", "GO_CLEANUP"]

# a drive then a report; with GO_CLEANUP a cleanup that says how root ended and asks where the robot is
GO_ROOT = """format: 1
name: go
root:
  sequence:
    - call: navigation.go_to
      inputs: {place: kitchen}
    - call: speech.say
      inputs: {text: arrived}
"""
GO_CLEANUP = """cleanup:
  sequence:
    - call: speech.say
      inputs: {text: "{ended}"}
    - call: navigation.where_am_i
cleanup_timeout: 4
"""


class CtrlC(RunObserver):
    """Ctrl-C (KeyboardInterrupt in the ticking thread, as ``bmtree run``'s handler raises it) after the
    first tick at or after each of these times since the run started (once each, in order)."""

    def __init__(self, *at: float):
        self.at = list(at)
        self.start = 0.0

    def on_start(self, tree: Any, root: Any, ctx: Any) -> None:
        self.start = ctx.clock.now()

    def on_tick(self, root: Any, changes: Any, now: float) -> None:
        if self.at and now - self.start >= self.at[0]:
            self.at.pop(0)
            raise KeyboardInterrupt


class Kept(RunObserver):
    """The run's result (also of a run that raised) and its notices, in order."""

    def __init__(self) -> None:
        self.result: Any = None
        self.seen: List[Any] = []

    def on_end(self, result: Any) -> None:
        self.result = result
        self.seen.append(result)

    def on_notice(self, notice: Any, now: float) -> None:
        self.seen.append(notice)
