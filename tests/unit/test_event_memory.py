"""A run keeps only the recent events and those a waiting ``wait_event`` has not read: a robot's modules send
events all day (a battery level, a person detector at 30 Hz), and a run kept every one (about 700 bytes
each), so a day's patrol grew by hundreds of megabytes it never read again."""
from __future__ import annotations

import pytest

from coordinator.received import KEEP, Received
from coordinator.runevents import RunObserver
from coordinator.testing import TreeTest
from tests.unit.test_engine import tree


class _Ctx(RunObserver):
    def on_start(self, tree, root, ctx) -> None:
        self.ctx = ctx


def test_old_events_go_and_their_numbers_stay():
    r = Received(keep=10)
    for i in range(55):
        r.append("e%d" % i, i // 3)
    assert len(r) == 55 and r[54] == "e54" and r.tick_of(54) == 18
    assert len(r) - r.base < 20 and r[r.base] == "e%d" % r.base
    assert not r.kept(0) and r.kept(54) and not r.kept(55)
    with pytest.raises(IndexError, match="event 0 is not kept"):
        r[0]


def test_the_events_a_reader_has_not_read_are_kept():
    r = Received(keep=10)
    r.append("first", 0)
    r.read_from("waiting", 1)
    for i in range(100):
        r.append(i, 1)
    assert r.base == 1 and r[1] == 0 and r[100] == 99   # all it has not read, none before
    r.read_from("waiting", 101)
    r.append("more", 2)
    assert r.base == 92 and r[101] == "more"   # read: only the last 10 stay
    r.read_from("waiting", 95)
    for i in range(30):
        r.append(i, 3)
    assert r.base == 95   # a reader restarted within the kept ones pins them again
    r.done("waiting")
    r.append("last", 4)
    assert len(r) - r.base == 10


def test_a_long_run_holds_a_bounded_number_of_events(tmp_path):
    """5,000 battery events while the robot waits, then two people seen at once: the loop over wait_event
    still takes both (one moment), and the run holds no more than 2 x KEEP events."""
    t = TreeTest(tree(tmp_path, """
root:
  sequence:
    - wait: 60
    - repeat: 10
      until: 'who == "Ana"'
      child:
        wait_event: vision.personSeen
        outputs: {person: who}
        timeout: 5
"""))
    for i in range(5000):
        t.mocks.event(i * 0.01, "vision.personSeen", person="nobody%d" % i, position={"x": 0.0})
    t.mocks.event(61.0, "vision.personSeen", person="Bob", position={"x": 1.0})
    t.mocks.event(61.0, "vision.personSeen", person="Ana", position={"x": 1.0})
    seen = _Ctx()
    run = t.run(observers=[seen])
    assert run.succeeded and run.blackboard["who"] == "Ana" and run.duration == pytest.approx(61.0), run
    events = seen.ctx.events
    assert len(events) == 5002 and len(events) - events.base < 2 * KEEP


def test_a_waiting_wait_event_reads_every_event_that_came_at_once(tmp_path):
    """3,000 events in one moment, the one it waits for the last: none of those it has not read is dropped."""
    t = TreeTest(tree(tmp_path, """
root:
  wait_event: vision.personSeen
  where: 'person == "Zed"'
  outputs: {person: who}
  timeout: 5
"""))
    for i in range(3000):
        t.mocks.event(1.0, "vision.personSeen", person="p%d" % i, position={"x": 0.0})
    t.mocks.event(1.0, "vision.personSeen", person="Zed", position={"x": 0.0})
    seen = _Ctx()
    run = t.run(observers=[seen])
    assert run.succeeded and run.blackboard["who"] == "Zed", run
    assert len(seen.ctx.events) == 3001
