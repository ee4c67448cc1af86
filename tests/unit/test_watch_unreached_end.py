"""A watch cut off from the run (its link dropped) that finds the run's process gone once it can look again
does not say the run was killed: the run may have ended well meanwhile (a several-machines audit saw a
SUCCESS reported as 'gone … it did not stop its calls'). No ROS: the liveness watch's own decision."""
from __future__ import annotations

import types

from coordinator.watchlive import RunLiveness, gone_record
from coordinator.watchstate import SILENT_AFTER, WatchState
from tests.unit.test_watch_operator import tree

NODE = "/bmtree_4242_1"


def _watched():
    state = WatchState()
    state.apply(tree())
    watcher = types.SimpleNamespace(state=state, nodes={state.run: NODE}, apply=state.apply)
    liveness = RunLiveness.__new__(RunLiveness)   # its threads are not started: only its decision is looked at
    liveness.watcher, liveness.state = watcher, state
    return state, liveness


def test_a_run_gone_while_the_watch_could_not_reach_it_is_not_said_killed(monkeypatch):
    import coordinator.watchlive as watchlive

    monkeypatch.setattr(watchlive, "END_TICKS_GRACE", 0.0)
    state, liveness = _watched()
    state.heard(NODE, True, now=100.0)
    state.heard(NODE, False, now=100.0 + SILENT_AFTER + 1)   # the link dropped: silent
    assert state.silent
    liveness._gone(NODE, "its process ended")
    reason = state.end["reason"]
    assert "this watch could not reach it for" in reason and "may have ended meanwhile (well or not)" in reason
    assert "bmtree runs, bmtree replay there" in reason and "it did not stop its calls" not in reason, reason


def test_a_run_gone_while_it_answered_is_said_killed(monkeypatch):
    import coordinator.watchlive as watchlive

    monkeypatch.setattr(watchlive, "END_TICKS_GRACE", 0.0)
    state, liveness = _watched()
    state.heard(NODE, True, now=100.0)
    liveness._gone(NODE, "its process ended")
    assert state.end["reason"].endswith("its process ended; it did not stop its calls"), state.end["reason"]
    assert gone_record(state, NODE, "x", unreached=4.0)["status"] == "UNFINISHED"
