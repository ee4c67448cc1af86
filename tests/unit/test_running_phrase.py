"""The reason of a run stopped between two runs of a loop reads as a sentence (a cleanup may say it
aloud as ``ended_reason``), not as the loop's progress note (no ROS)."""
from __future__ import annotations

from coordinator.runevents import RunObserver
from coordinator.testing.kit import TreeTest
from tests.stopkit import GO_CLEANUP


class Ended(RunObserver):
    """A stop from outside once ``count`` calls have ended (asked after the tick that took the last one)."""

    def __init__(self, count: int = 1):
        self.count, self.ended = count, 0

    def on_call_end(self, record):
        self.ended += 1

    def stop(self) -> str:
        return "stopped after 30 s" if self.ended >= self.count else ""


def _run(tmp_path, sim_defs, text, mocks, count=1):
    tree = tmp_path / "loop.yaml"
    tree.write_text(text)
    t = TreeTest(str(tree), definitions=sim_defs)
    mocks(t.mocks)
    ended = Ended(count)
    return t.run(observers=[ended], stop_when=ended.stop)


PICK = "format: 1\nroot:\n  retry: 2\n  name: pick\n  child:\n    call: navigation.go_to\n    inputs: {place: kitchen}\n"


def test_a_stop_between_two_attempts_of_a_retry(tmp_path, sim_defs):
    run = _run(tmp_path, sim_defs, PICK, lambda m: m["navigation.go_to"].fail("blocked"))
    assert run.reason == "stopped after 30 s while 'pick' was running (between attempts: attempt 1 of 2 failed)"


def test_the_cleanup_says_the_stop_between_attempts_as_a_sentence(tmp_path, sim_defs):
    run = _run(tmp_path, sim_defs, PICK + GO_CLEANUP, lambda m: m["navigation.go_to"].fail("blocked"))
    assert run.ended == "stopped"
    assert [c.inputs["text"] for c in run.cleanup_calls("speech.say")] == ["stopped"]
    assert run.blackboard["ended_reason"] == ("stopped after 30 s while 'pick' was running (between attempts: "
                                              "attempt 1 of 2 failed)")


def test_a_stop_between_two_runs_of_a_repeat(tmp_path, sim_defs):
    text = "format: 1\nroot:\n  repeat: 3\n  name: patrol\n  child:\n    call: speech.say\n    inputs: {text: hi}\n"
    run = _run(tmp_path, sim_defs, text, lambda m: None)
    assert run.reason == "stopped after 30 s while 'patrol' was running (between runs: run 1 of 3 succeeded)"


def test_a_stop_between_two_elements_of_a_for_each(tmp_path, sim_defs):
    text = ("format: 1\nroot:\n  for_each: [kitchen, hall]\n  as: room\n  name: visit\n  child:\n"
            "    call: speech.say\n    inputs: {text: $room}\n")
    run = _run(tmp_path, sim_defs, text, lambda m: None)
    assert run.reason == ("stopped after 30 s while 'visit' was running (about to start element 2 of 2: "
                          "room = 'hall')"), run.reason


def test_several_running_nodes_keep_what_each_is_at(tmp_path, sim_defs):
    text = ("format: 1\nroot:\n  parallel:\n    - retry: 2\n      name: pick\n      child:\n"
            "        call: navigation.go_to\n        inputs: {place: kitchen}\n"
            "    - call: navigation.where_am_i\n")

    def mocks(m):
        m["navigation.go_to"].fail("blocked")
        m["navigation.where_am_i"].hang()
    run = _run(tmp_path, sim_defs, text, mocks)
    assert run.reason == ("stopped after 30 s while 'pick' (between attempts: attempt 1 of 2 failed), "
                          "'navigation.where_am_i' were running"), run.reason
