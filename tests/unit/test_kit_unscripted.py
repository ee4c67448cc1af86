"""What the kit says of calls a test did not script, how a run's status compares, how a call prints, and the
cancels of a run's last tick.

A team's first tree test passed with no script at all: every unscripted mock succeeded with empty text and
zero positions, the robot "said" ``Here is your , .`` and vision "found" the cup at (0, 0, 0), and nothing
told them. ``assert run.status == "FAILURE"`` failed against py_trees' enum; a failed ``assert`` on calls
printed each call's whole definition; a call halted on the tick that ended the run looked as if its module had
never answered the cancel.
"""
from __future__ import annotations

import os
import warnings

import pytest
from py_trees.common import Status

from coordinator.testing import MockError, RunStatus, TreeTest, UnscriptedWarning
from tests.conftest import TREES

APPLE = os.path.join(TREES, "find_apple.yaml")


def _run(test):
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        run = test.run()
    return run, [w for w in seen if issubclass(w.category, UnscriptedWarning)]


def test_calls_answered_without_a_script_are_listed_and_warned_of():
    run, warned = _run(TreeTest(APPLE))
    # speech.say answers only `success`: its default is no value the tree could misuse, so it is not listed
    assert run.unscripted == {"navigation.approach": 1, "navigation.go_to": 1, "vision.find_object": 1}
    assert len(warned) == 1
    text = str(warned[0].message)
    assert text.startswith(APPLE + ": calls answered without a script (success, empty text, zero numbers): "
                           "navigation.approach, navigation.go_to, vision.find_object; script them")
    assert "strict=True" in text and "bmtree_strict_mocks = true" in text
    assert "answered without a script (success, empty outputs): navigation.approach" in repr(run)


def test_a_fully_scripted_run_warns_of_nothing():
    t = TreeTest(APPLE)
    t.mocks["vision.find_object"].succeed(position={"x": 1.0}, room="living_room")
    t.mocks["navigation.go_to"].succeed(room="living_room")
    t.mocks["navigation.approach"].succeed()
    run, warned = _run(t)
    assert run.succeeded and run.unscripted == {} and warned == []
    assert "without a script" not in repr(run)


def test_counts_are_of_this_run_only():
    t = TreeTest(APPLE)
    t.mocks["navigation.go_to"].succeed(room="living_room")
    _run(t)
    run, _ = _run(t)
    assert run.unscripted == {"navigation.approach": 1, "vision.find_object": 1}


def test_strict_mocks_fail_the_test_naming_every_unscripted_function():
    t = TreeTest(APPLE, strict=True)
    t.mocks["speech.say"].succeed()
    t.mocks["navigation.go_to"].succeed(room="living_room")
    with pytest.raises(MockError) as err:
        t.run()
    assert str(err.value) == ("calls to functions without a script (strict mocks; answered failed): "
                              "vision.find_object ×4; script them, e.g. mocks['vision.find_object'].succeed(...) "
                              "or .fail(...)")
    t = TreeTest(APPLE, strict=True)
    for target in ("speech.say", "navigation.go_to", "navigation.approach", "vision.find_object"):
        t.mocks[target].succeed()
    assert t.run().succeeded


def test_a_runs_status_equals_its_text_and_the_py_trees_status():
    t = TreeTest(APPLE)
    t.mocks["navigation.go_to"].fail("blocked")
    run, _ = _run(t)
    assert run.status == "FAILURE" and run.status == Status.FAILURE and Status.FAILURE == run.status
    assert run.status != "SUCCESS" and run.status != Status.SUCCESS
    assert run.status in ("FAILURE",) and run.status in (Status.SUCCESS, Status.FAILURE)
    assert run.status.value == "FAILURE" and str(run.status) == "FAILURE" and isinstance(run.status, RunStatus)
    assert {run.status: 1}["FAILURE"] == 1 and run.failed and not run.succeeded


def test_a_call_prints_what_a_test_compares():
    t = TreeTest(APPLE)
    t.mocks["navigation.go_to"].fail("blocked")
    run, _ = _run(t)
    said = repr(run.calls("navigation.go_to")[0])
    assert said == "<CallRecord navigation.go_to failed at 0.000s for 0.000s inputs={'place': 'living_room'} " \
                   "error='blocked'>"


def test_a_call_halted_on_the_last_tick_has_its_cancel_answered(tmp_path):
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n  timeout: 20\n  child: {call: speech.listen, inputs: {seconds: 5}}\n")
    t = TreeTest(str(tree))
    t.mocks["speech.listen"].succeed(text="water", delay=25)
    run, _ = _run(t)
    call, = run.calls()
    assert run.failed and call.status == "halted" and call.cancel_sent
    assert call.cancel_answer == "cancelled by the coordinator" and call.maybe_running == ""
