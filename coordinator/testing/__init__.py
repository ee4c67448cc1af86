"""bmtree's test kit: mocked modules, a simulated clock, tree runs, ROS fixtures."""
from __future__ import annotations

from coordinator.testing.inprocess import InProcessTransport
from coordinator.testing.kit import Coverage, RunStatus, TreeRun, TreeTest, UnscriptedWarning
from coordinator.testing.limits import TickLimitError
from coordinator.testing.mocks import (
    FunctionMock,
    MockError,
    MockModule,
    Mocks,
    Outcome,
    OutcomeKind,
    die,
    fail,
    hang,
    reject,
    respond,
    succeed,
)

__all__ = ["Coverage", "FunctionMock", "InProcessTransport", "MockError", "MockModule", "Mocks", "Outcome",
           "OutcomeKind", "RunStatus", "TickLimitError", "TreeRun", "TreeTest", "UnscriptedWarning", "die", "fail",
           "hang", "reject", "respond", "succeed"]
