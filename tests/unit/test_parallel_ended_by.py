"""``parallel``'s ``ended_by``: the name of the child whose ending ended it, for a ``switch`` after it
(SMACH's Concurrence outcome map with several outcomes: a follow ended by "stop" or by arriving)."""
from __future__ import annotations

import os

import pytest

from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from coordinator.testing import fail
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA, one_file_trees

DEFS = load_definitions([SIM_DIR, os.path.join(DATA, "modules_lang")])

STOP_OR_ARRIVE = """
  sequence:
    - parallel:
        policy: {policy}
        ended_by: why
        children:
          - name: seen Ana
            wait_event: vision.personSeen
            where: 'person == "Ana"'
          - name: arrived
            call: navigation.go_to
            inputs: {{place: kitchen}}
    - switch: $why
      cases:
        seen Ana: {{call: speech.say, inputs: {{text: "Hello Ana."}}}}
        arrived: {{call: speech.say, inputs: {{text: "Here we are."}}}}
"""


@pytest.fixture
def tree(tmp_path, bmtree_tree):
    return one_file_trees(tmp_path, bmtree_tree, DEFS)


def said(run):
    return [c.inputs["text"] for c in run.calls("speech.say")]


@pytest.mark.parametrize("policy", ["one", "first_success"])
@pytest.mark.parametrize("seen_at, expected", [(1.0, "Hello Ana."), (9.0, "Here we are.")])
def test_the_child_that_ended_the_parallel_is_named(tree, policy, seen_at, expected):
    t = tree(STOP_OR_ARRIVE.format(policy=policy))
    t.mocks["navigation.go_to"].succeed(delay=5, room="kitchen")
    t.mocks.event(seen_at, "vision.personSeen", person="Ana", position={"x": 1.0, "y": 0.0, "z": 0.0})
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == [expected]


def test_a_failure_names_the_child_that_failed(tree):
    t = tree("""
  sequence:
    - force_success:
        parallel:
          ended_by: why
          children:
            - {name: wait, wait: 10}
            - {name: go, call: navigation.go_to, inputs: {place: kitchen}}
    - check: why == "go"
""")
    t.mocks["navigation.go_to"].script(fail("blocked", delay=2))
    run = t.run()
    assert run.succeeded, run.reason


def test_all_and_succeed_on_name_the_last_child_they_waited_for(tree):
    t = tree("""
  sequence:
    - parallel:
        ended_by: last
        children:
          - {name: short, wait: 1}
          - {name: long, wait: 3}
    - parallel:
        succeed_on: [a, b]
        ended_by: awaited
        children:
          - {name: a, wait: 2}
          - {name: b, wait: 1}
          - {name: c, wait: 0.5}
    - check: last == "long" and awaited == "a"
""")
    run = t.run()
    assert run.succeeded, run.reason


def test_first_success_that_fails_names_the_last_to_fail(tree):
    t = tree("""
  sequence:
    - force_success:
        parallel:
          policy: first_success
          ended_by: why
          children:
            - {name: early, call: vision.find_object, inputs: {object: cup}}
            - {name: late, call: navigation.go_to, inputs: {place: kitchen}}
    - check: why == "late"
""")
    t.mocks["vision.find_object"].script(fail("not seen", delay=1))
    t.mocks["navigation.go_to"].script(fail("blocked", delay=3))
    run = t.run()
    assert run.succeeded, run.reason


def test_a_halted_parallel_writes_nothing_and_the_check_knows_the_key(tree, tmp_path):
    t = tree("""
  sequence:
    - timeout: 1
      child:
        parallel:
          ended_by: why
          children:
            - {name: w, wait: 5}
    - check: why == "w"
""")
    run = t.run()
    assert run.failed and "why" not in run.blackboard, run.blackboard
    path = tmp_path / "bad.yaml"
    path.write_text("format: 1\nroot:\n  sequence:\n    - parallel:\n        ended_by: 3\n        children: "
                    "[{wait: 1}]\n")
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), DEFS)
    assert "bad.yaml:5:19: " in str(info.value), str(info.value)


def test_the_language_reference_example_runs(tmp_path, bmtree_tree):
    from tests.unit.test_lang_parallel_include import readme_example

    path = tmp_path / "ref.yaml"
    path.write_text(readme_example("**Which child ended it.**"))
    t = bmtree_tree(str(path), definitions=DEFS)
    t.mocks["navigation.go_to"].succeed(delay=5, room="kitchen")
    t.mocks.event(2.0, "vision.personSeen", person="Ana", position={"x": 1.0, "y": 0.0, "z": 0.0})
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == ["Hello Ana."]


def test_a_case_or_a_check_no_child_name_can_match_is_an_error(tmp_path):
    """As a misspelt status of a call: a misspelt child name would silently never run its case."""
    path = tmp_path / "bad.yaml"
    path.write_text("format: 1\nroot:\n  sequence:\n    - parallel:\n        policy: one\n        ended_by: why\n"
                    "        children:\n          - {name: waited, wait: 1}\n          - {name: arrived, wait: 2}\n"
                    "    - switch: $why\n      cases:\n        arived: {wait: 0}\n        waited: {wait: 0}\n"
                    "    - check: why != \"waitd\"\n")
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), DEFS)
    assert [str(e).replace(str(path), "bad.yaml") for e in info.value.errors] == [
        "bad.yaml:12:9: case 'arived' never matches: $why is the name of the child that ended the parallel at line "
        "4, one of 'waited', 'arrived' (did you mean 'arrived'?)",
        "bad.yaml:14:18: why != \"waitd\" is always true: $why is the name of the child that ended the parallel at "
        "line 4, one of 'waited', 'arrived' (did you mean 'waited'?)"]
