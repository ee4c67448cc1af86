"""Steering (coordinator.control) a run of a tree with ``cleanup:`` (no ROS, a simulated clock)."""
from __future__ import annotations

import pytest

from coordinator.control import Controller
from coordinator.runevents import RunObserver
from coordinator.testing.kit import TreeTest
from tests.unit.test_cleanup_runs import TREE


@pytest.fixture
def go(tmp_path, sim_defs):
    path = tmp_path / "go.yaml"
    path.write_text(TREE)
    return TreeTest(str(path), definitions=sim_defs)


class _Steer(RunObserver):
    """Applies ``commands[phase]`` (once) at the first tick that sees the top in that phase."""

    def __init__(self, control, commands):
        self.control, self.commands, self.answers = control, dict(commands), {}

    def on_tick(self, root, changes, now):
        for cmd in self.commands.pop(root.phase, []):
            self.answers[(root.phase, cmd["command"], cmd.get("node") or cmd.get("key"))] = self.control._apply(cmd)


def _run(go, commands):
    control = Controller(True)
    steer = _Steer(control, commands)
    run = go.run(observers=[control, steer])
    return run, steer.answers


READ_ONLY = ("'ended' is read-only: bmtree sets 'ended' and 'ended_reason' when root ends, to tell the cleanup "
             "how it ended; set another key")


def test_the_keys_that_say_how_root_ended_cannot_be_set(go):
    go.mocks["navigation.go_to"].succeed(room="kitchen", delay=1.0)
    go.mocks["navigation.where_am_i"].succeed(delay=1.0)
    set_ended = {"command": "set", "key": "ended", "value": '"succeeded"'}
    set_reason = {"command": "set", "key": "ended_reason", "value": '""'}
    run, answers = _run(go, {"root": [set_ended], "cleanup": [set_ended, set_reason]})
    assert answers[("root", "set", "ended")] == (False, READ_ONLY)
    assert answers[("cleanup", "set", "ended")] == (False, READ_ONLY)
    assert answers[("cleanup", "set", "ended_reason")] == (False, READ_ONLY.replace("'ended' is", "'ended_reason' is", 1))
    assert run.succeeded and run.blackboard["ended"] == "succeeded"


def test_commands_on_roots_nodes_are_refused_once_root_ended(go):
    go.mocks["navigation.go_to"].fail("blocked", delay=1.0)
    go.mocks["navigation.where_am_i"].hang()
    run, answers = _run(go, {"cleanup": [
        {"command": "force", "node": "navigation.go_to", "outcome": "SUCCESS"},
        {"command": "break", "node": "sequence"},
        {"command": "force", "node": "go", "outcome": "SUCCESS"},   # the top: root and cleanup
        {"command": "force", "node": "navigation.where_am_i", "outcome": "FAILURE"}]})
    refused = ("root has ended and the cleanup is running: %r is not a node of the cleanup, so it will not be "
               "ticked again; steer a node of the cleanup instead (cleanup, speech.say, navigation.where_am_i)")
    assert answers[("cleanup", "force", "navigation.go_to")] == (False, refused % "navigation.go_to")
    assert answers[("cleanup", "break", "sequence")] == (False, refused % "sequence")
    assert answers[("cleanup", "force", "go")] == (False, TOP)
    assert answers[("cleanup", "force", "navigation.where_am_i")] == (
        True, "'navigation.where_am_i' will end in FAILURE the next time it is ticked")   # the cleanup's: steered
    assert run.failed and run.reason == "navigation.go_to failed: blocked"
    assert run.cleanup_status == "FAILURE" and run.duration < 10   # forced, not cut by cleanup_timeout


TOP = ("'go' is the tree's top (root, then the cleanup): it ends after its cleanup, whatever happens; steer root's "
       "top node 'sequence' (the cleanup still runs) or a node of the cleanup instead")


def test_the_top_of_a_tree_with_a_cleanup_is_never_steered(go):
    go.mocks["navigation.go_to"].hang()
    run, answers = _run(go, {"root": [{"command": "force", "node": "go", "outcome": "SUCCESS"},
                                      {"command": "break", "node": "go"},
                                      {"command": "force", "node": "sequence", "outcome": "FAILURE"}]})
    assert answers[("root", "force", "go")] == (False, TOP)
    assert answers[("root", "break", "go")] == (False, TOP)
    assert answers[("root", "force", "sequence")][0]
    assert run.failed and run.ended == "failed"
    assert [c.target for c in run.cleanup_calls()] == ["speech.say", "navigation.where_am_i"]   # it still ran


def test_before_root_ends_its_nodes_and_the_cleanups_are_steered(go):
    go.mocks["navigation.go_to"].hang()
    run, answers = _run(go, {"root": [{"command": "force", "node": "navigation.go_to", "outcome": "SUCCESS"},
                                      {"command": "force", "node": "navigation.where_am_i", "outcome": "FAILURE"}]})
    assert answers[("root", "force", "navigation.go_to")][0] and answers[("root", "force", "navigation.where_am_i")][0]
    assert run.succeeded and run.cleanup_status == "FAILURE"


def test_a_key_named_ended_in_a_tree_without_cleanup_is_an_ordinary_key():
    import types

    control = Controller(True)
    ctx = types.SimpleNamespace(blackboard={"ended": "no"}, observers=[],
                                write=lambda k, v: ctx.blackboard.__setitem__(k, v))
    control.ctx, control.root = ctx, object()
    assert control._apply({"command": "set", "key": "ended", "value": "done"}) == (True, 'ended = "done"')
