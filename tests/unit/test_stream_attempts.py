"""The run stream says a running retry's attempt (``loops`` [id, attempt, of]) and, while it waits its delay,
when the next attempt starts (``waits`` [id, t]); the watch shows ``attempt 2 of 3`` and counts down to
the next. Before, the viewers could only guess the attempt from the child's failures, without its count."""
from __future__ import annotations

import json

from coordinator.runrecords import record_problem
from coordinator.runstream import RunStream, Sink
from coordinator.testing.kit import TreeTest
from coordinator.testing.mocks import fail, succeed
from coordinator.watchstate import WatchState
from coordinator.watchview import render
from tests.unit.test_watch_operator import shown

TREE = """format: 1
name: grab
root:
  retry: 3
  name: grab with retries
  delay: 2
  child:
    call: navigation.go_to
    inputs: {place: kitchen}
"""


def test_a_retrys_attempts_and_its_wait_are_in_the_stream_and_the_watch(tmp_path, sim_defs):
    path = tmp_path / "grab.yaml"
    path.write_text(TREE)
    records, screens = [], []
    state = WatchState()

    class Both(Sink):
        def write(self, channel, text):
            rec = json.loads(text)
            assert record_problem(rec, range(5)) is None, rec   # every record is one the readers take
            records.append(rec)
            state.apply_text(text)
            if rec["type"] == "tick":
                screens.append(shown(render(state, 120, 30), 120))

    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].script(fail("blocked", delay=1.0), fail("blocked", delay=1.0),
                                       succeed(room="kitchen", delay=1.0))
    assert t.run(observers=[RunStream([Both()])]).succeeded
    loops = [row[1:] for r in records for row in r.get("loops") or []]
    assert loops == [[1, 3], [2, 3], [3, 3]], loops
    waits = [row[1] for r in records for row in r.get("waits") or []]
    assert waits == [3.0, 6.0], waits     # failed at 1 s then at 4 s, each followed by 2 s of delay
    assert any("attempt 2 of 3" in s for s in screens), screens
    assert any("next attempt in" in s for s in screens), screens
