"""Leaving the master once the ``--sim`` run shown has ended: its private master went with it, there is
nothing to leave and nothing to say (README, "Watching a run"); any other master not answering is still
said, with what to clean up (no ROS)."""
from __future__ import annotations

from comm.nodelife import LEFT_BEHIND
from coordinator.watch import leaving
from coordinator.watchstate import WatchState

# what comm.nodelife.leave_graph says of a master that does not answer
GONE = "the ROS master at http://127.0.0.1:40123/ does not answer: leaving without unregistering (%s)" % LEFT_BEHIND


def _state(sim, ended=True):
    s = WatchState()
    tree = {"v": 1, "type": "tree", "run": "r1", "t": 0.0, "name": "go", "blackboard": {},
            "nodes": [{"id": 0, "parent": None, "kind": "call", "shape": "leaf", "name": "go"}]}
    if sim:
        tree["sim"] = {"world": None, "dir": "/tmp/sim"}
    s.apply(tree)
    if ended:
        s.apply({"type": "end", "run": "r1", "t": 1.0, "status": "SUCCESS", "ticks": 1, "duration": 1.0})
    return s


def test_a_sim_runs_master_gone_with_it_is_left_without_a_word():
    said = []
    say, gone = leaving(_state(sim=True), said.append, answers=lambda timeout: False)
    assert gone   # known gone: rospy's questions fail at once, no wait
    say(GONE)
    say("stopped again: leaving without unregistering from the ROS master at http://127.0.0.1:40123/ (…)")
    assert said == ["stopped again: leaving without unregistering from the ROS master at http://127.0.0.1:40123/ (…)"]
    # still there when asked, gone a moment later: not said either
    said.clear()
    say, gone = leaving(_state(sim=True), said.append, answers=lambda timeout: True)
    assert not gone
    say(GONE)
    assert said == []


def test_another_master_that_does_not_answer_is_still_said():
    asked = []
    for state in (_state(sim=False), _state(sim=True, ended=False)):
        said = []
        say, gone = leaving(state, said.append, answers=lambda timeout: asked.append(timeout) or False)
        say(GONE)
        assert said == [GONE] and not gone and asked == []
