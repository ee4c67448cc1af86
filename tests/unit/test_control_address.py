"""``break``/``force`` name one node: a name several nodes share is refused with the candidates, where
they are and how to pick one (``NAME@ID``, the id of the run stream's ``nodes`` table) (no ROS)."""
from __future__ import annotations

import pytest

from coordinator.control import Controller
from coordinator.runevents import RunObserver
from coordinator.runstream import node_table
from coordinator.testing.kit import TreeTest
from tests.unit.test_cleanup_runs import TREE

# ids (preorder, as the run stream's nodes table): 0 go, 1 sequence, 2 navigation.go_to, 3 speech.say,
# 4 cleanup, 5 speech.say, 6 navigation.where_am_i
SAY = ("2 nodes are named 'speech.say': speech.say@3 (go.yaml:7, in go > sequence), speech.say@5 (go.yaml:11, in go > "
       "cleanup); say which one by its id (%s speech.say@3%s), or give them names of their own (name: in the tree)")


@pytest.fixture
def go(tmp_path, sim_defs):
    path = tmp_path / "go.yaml"
    path.write_text(TREE)
    return TreeTest(str(path), definitions=sim_defs)


class _Steer(RunObserver):
    """Applies ``commands[phase]`` (once) at the first tick that sees the top in that phase; keeps the ids."""

    def __init__(self, control, commands):
        self.control, self.commands, self.answers, self.table = control, dict(commands), [], []

    def on_tick(self, root, changes, now):
        self.table = self.table or node_table(root)
        for cmd in self.commands.pop(root.phase, []):
            self.answers.append(self.control._apply(cmd))


def _run(go, commands):
    control = Controller(True)
    steer = _Steer(control, commands)
    run = go.run(observers=[control, steer])
    return run, steer


def test_a_name_several_nodes_share_is_refused_and_changes_nothing(go):
    go.mocks["navigation.go_to"].succeed(room="kitchen", delay=1.0)
    run, steer = _run(go, {"root": [{"command": "force", "node": "speech.say", "outcome": "SUCCESS"},
                                    {"command": "break", "node": "speech.say"}]})
    assert steer.answers == [(False, SAY % ("force", " SUCCESS")), (False, SAY % ("break", ""))]
    assert [(n["id"], n["name"]) for n in steer.table if n["name"] == "speech.say"] == [(3, "speech.say"),
                                                                                      (5, "speech.say")]
    assert run.said() == ["arrived", "succeeded: "]   # both announcements made: neither was forced


def test_name_at_id_steers_that_node_alone(go):
    go.mocks["navigation.go_to"].succeed(room="kitchen", delay=1.0)
    run, steer = _run(go, {"root": [{"command": "force", "node": "speech.say@5", "outcome": "SUCCESS"}]})
    assert steer.answers == [(True, "'speech.say@5' will end in SUCCESS the next time it is ticked")]
    assert run.said() == ["arrived"]   # root's announcement made, the cleanup's forced


def test_a_unique_name_works_as_before_and_an_id_alone_too(go):
    go.mocks["navigation.go_to"].hang()
    run, steer = _run(go, {"root": [{"command": "force", "node": "navigation.go_to", "outcome": "FAILURE"},
                                    {"command": "force", "node": "@6", "outcome": "FAILURE"}]})
    assert steer.answers == [(True, "'navigation.go_to' will end in FAILURE the next time it is ticked"),
                             (True, "'navigation.where_am_i' will end in FAILURE the next time it is ticked")]
    assert run.ended == "failed" and run.cleanup_status == "FAILURE"


def test_a_wrong_id_is_refused_with_the_right_ones(go):
    go.mocks["navigation.go_to"].hang()
    run, steer = _run(go, {"root": [{"command": "force", "node": "speech.say@4", "outcome": "SUCCESS"},
                                    {"command": "break", "node": "@99"},
                                    {"command": "break", "node": "speach.say"}]})
    assert steer.answers == [
        (False, "node 4 is 'cleanup', not 'speech.say' (the nodes so named are: speech.say@3, speech.say@5)"),
        (False, "no node of id 99 in this tree (its ids are 0 to 6)"),
        (False, "no node named 'speach.say' in this tree (did you mean 'speech.say'?)")]


def test_once_the_cleanup_runs_the_name_of_its_one_node_so_named_is_no_longer_ambiguous(go):
    """Root's node of that name is never ticked again: only the cleanup's can be meant."""
    go.mocks["navigation.go_to"].fail("blocked", delay=1.0)
    go.mocks["navigation.where_am_i"].hang()
    run, steer = _run(go, {"cleanup": [{"command": "force", "node": "navigation.where_am_i", "outcome": "SUCCESS"},
                                       {"command": "break", "node": "speech.say"}]})
    assert steer.answers[1] == (True, "will pause before 'speech.say@5' starts")


def test_clear_takes_a_shared_name_or_an_id():
    """Clearing breakpoints is harmless: a name clears those of every node so named."""
    class Node:
        def __init__(self, name, children=()):
            self.name, self.children = name, list(children)

    control = Controller(True)
    a, b = Node("x"), Node("x")
    control.root = Node("top", [a, b])
    control.breaks = {a: True, b: True}
    # it said "no breakpoint on 'x@2'" when it had just cleared one
    assert control._apply({"command": "clear", "node": "x@2"}) == (True, "breakpoint on 'x@2' cleared")
    assert list(control.breaks) == [a]
    assert control._apply({"command": "clear", "node": "x"}) == (True, "breakpoint on 'x' cleared")
    assert control.breaks == {}
    assert control._apply({"command": "clear", "node": "x"}) == (True, "no breakpoint on 'x' (none was set)")
