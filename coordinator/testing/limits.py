"""Every test run ends: the tick limits of ``TreeTest.run`` and of ``bmtree test`` scenarios.

A tree whose loops restart one another at once, against mocks that answer at once, ticks for ever
at one simulated instant; one whose clock only creeps (a ``wait: 0.001`` in a loop) nearly so.
:class:`TickGuard` counts the ticks of a run and, as the runner's ``stop_when``, stops it at the
first limit; the kit then raises :class:`TickLimitError` (a tick limit reached fails the test, or
the scenario, whatever it expects).
"""
from __future__ import annotations

from typing import Any, Optional

from py_trees.common import Status

from coordinator.runevents import RunObserver

__all__ = ["DEFAULT_MAX_DURATION", "DEFAULT_MAX_TICKS", "DEFAULT_MAX_TICKS_PER_INSTANT", "KIT_RAISE_WITH",
           "SCENARIO_RAISE_WITH", "TickGuard", "TickLimitError"]

DEFAULT_MAX_DURATION = 3600.0
"""Simulated seconds a run may take (scenario key ``max_duration``, ``t.run(max_duration=…)``)."""
DEFAULT_MAX_TICKS = 100000
"""Ticks a run may take in all (``max_ticks``): an hour of waiting is 14400 ticks of 0.25 s."""
DEFAULT_MAX_TICKS_PER_INSTANT = 10000
"""Ticks in a row at one simulated instant (``max_ticks_per_instant``): more is a livelock."""

SCENARIO_RAISE_WITH = "raise the scenario key '{key}'"
"""How the limit reached is said to be raised in ``bmtree test`` (``{key}``: the limit's name)."""
KIT_RAISE_WITH = "raise it with t.run({key}=...)"
"""… and in the pytest kit."""


class TickGuard(RunObserver):
    """Counts the ticks of a run; as the runner's ``stop_when`` it ends a run that ticks ``max_ticks``
    times in all, or ``max_ticks_per_instant`` times without the simulated clock moving (loops
    restarting one another at once: a livelock). ``hit`` says which, and how to raise it
    (``raise_with``, ``{key}`` the limit's name)."""

    def __init__(self, max_ticks: int = DEFAULT_MAX_TICKS, max_ticks_per_instant: int = DEFAULT_MAX_TICKS_PER_INSTANT,
                 raise_with: str = SCENARIO_RAISE_WITH):
        self.max_ticks, self.max_ticks_per_instant = max_ticks, max_ticks_per_instant
        self.raise_with = raise_with
        self.hit = ""
        self.ticks = 0
        self._instant: Optional[float] = None
        self._same = 0

    def on_tick(self, root: Any, changes: Any, now: float) -> None:
        self.ticks += 1
        if now == self._instant:
            self._same += 1
        else:
            self._instant, self._same = now, 1
        if root.status != Status.RUNNING or self.hit:
            return
        if self.ticks >= self.max_ticks:
            self.hit = ("stopped after %d ticks (max_ticks) at simulated time %g s; %s if this tree needs more"
                        % (self.ticks, now, self.raise_with.format(key="max_ticks")))
        elif self._same >= self.max_ticks_per_instant:
            said = self.raise_with.format(key="max_ticks_per_instant")
            self.hit = ("stopped after %d ticks at simulated time %g s without the clock advancing "
                        "(max_ticks_per_instant): a livelock, loops restarting at once? %s if this tree needs more"
                        % (self._same, now, said[:1].upper() + said[1:]))

    def __call__(self) -> str:
        """The runner's ``stop_when``: why to stop, or nothing."""
        return self.hit


class TickLimitError(AssertionError):
    """A run stopped by a tick limit (:class:`TickGuard`): it fails the test whatever the test expects.
    ``hit``: the limit's text; ``run``: the run (a ``TreeRun``) as far as it went; the message adds
    which node was running."""

    def __init__(self, message: str, hit: str, run: Any):
        super().__init__(message)
        self.hit, self.run = hit, run
