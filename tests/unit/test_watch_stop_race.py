"""A call halted by a Ctrl-C of the run is said ``interrupted`` by the watch whatever order its record and
the stop's tick record arrive in, and whatever their times: a several-machines audit saw 'halted by the
tree' in 2 of 6 Ctrl-C, the call's end stamped just after the tick that halted root."""
from __future__ import annotations

from coordinator.watchstops import StopCalls

ROOT = 0


def _stopped_run(call_t: float, call_first: bool) -> StopCalls:
    stops = StopCalls()
    if call_first:
        stops.halted("c1", False, call_t)
    stops.tick({ROOT, 3}, ROOT, None, before=1.0, t=2.0)   # root went INVALID in the tick at 2.0 s
    if not call_first:
        stops.halted("c1", False, call_t)
    return stops


def test_a_call_halted_by_the_stop_is_the_stops_in_any_order():
    end = {"status": "INVALID", "reason": "interrupted (Ctrl-C) while 'look' was running"}
    for call_t in (1.5, 2.0, 2.0004):
        for first in (True, False):
            stops = _stopped_run(call_t, first)
            assert "c1" in stops.stopped, (call_t, first)
            assert stops.label({"call_id": "c1", "status": "halted", "error": "halted by the tree"}, end, {}) == (
                "interrupted", ""), (call_t, first)


def test_a_call_halted_before_the_stop_is_not():
    stops = StopCalls()
    stops.halted("c0", False, 0.5)
    stops.tick({4}, ROOT, None, before=0.0, t=0.6)        # a tick that halted a branch, not root
    stops.tick({ROOT}, ROOT, None, before=1.0, t=2.0)
    assert "c0" not in stops.stopped


def test_a_halted_call_whose_stop_tick_comes_after_the_end_waits_for_it():
    """call_end, then end, then the tick that halted root (three topics): the line waits for the tick."""
    end = {"status": "INVALID", "reason": "interrupted (Ctrl-C) while 'look' was running"}
    call = {"call_id": "c1", "status": "halted", "error": "halted by the tree", "t": 1.9}
    stops = StopCalls()
    stops.halted("c1", False, 1.9)
    assert not stops.settled(call, end, {}, tick_t=1.0)   # before: settled at the end, 'halted by the tree'
    stops.tick({ROOT}, ROOT, None, before=1.0, t=2.0)
    assert stops.settled(call, end, {}, tick_t=2.0)
    assert stops.label(call, end, {}) == ("interrupted", "")
