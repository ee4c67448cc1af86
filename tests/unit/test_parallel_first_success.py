"""``parallel`` with ``policy: first_success``: the first child that succeeds wins (the others halted), and the
parallel fails only when every child has failed (BehaviorTree.CPP's Parallel with ``success_count: 1`` and
``failure_count`` all: several detectors racing), which ``policy: one`` (failing at the first failure) cannot say."""
from __future__ import annotations

import pytest

from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from coordinator.schema import json_schema
from modules.definition import load_definitions, parse_definition
from modules.sim import SIM_DIR
from tests.conftest import one_file_trees


def _fn(name):
    return {"Name": name, "Exec-condition": "", "Description": "look", "Concurrent": True,
            "Input-params": [],
            "Output-params": [{"Name": "position", "Data-type": "geometry_msgs/Point", "Description": "where"},
                              {"Name": "label", "Data-type": "std_msgs/String", "Description": "what"}]}


DETECT = parse_definition({"Basic Module": "detect", "Brief Description": "three detectors",
                           "Hardware Required": [], "Functions": [_fn("by_color"), _fn("by_shape"), _fn("by_net")],
                           "Events": []}, "detect.json")
DEFS = dict(load_definitions([SIM_DIR]), detect=DETECT)

RACE = """  sequence:
    - parallel:
        - {call: detect.by_color, name: color, outputs: {position: pos, label: seen_by}}
        - {call: detect.by_shape, name: shape, outputs: {position: pos, label: seen_by}}
        - {call: detect.by_net, name: net, outputs: {position: pos}}
      policy: first_success
    - call: navigation.approach
      inputs: {target: $pos}
"""


@pytest.fixture
def tree(tmp_path, bmtree_tree):
    return one_file_trees(tmp_path, bmtree_tree, DEFS)


def test_two_fail_one_succeeds_is_success_and_the_others_are_halted_once_it_does(tree):
    t = tree(RACE)
    t.mocks["detect.by_color"].fail("no red blob", delay=1.0)
    t.mocks["detect.by_shape"].succeed(delay=2.0, position={"x": 1.0}, label="shape")
    t.mocks["detect.by_net"].fail("nothing above 0.5", delay=1.5)
    run = t.run()
    assert run.succeeded, run.reason
    assert run.blackboard["pos"]["x"] == 1.0 and run.calls("navigation.approach")
    assert [c.status for c in run.calls() if c.target.startswith("detect.")] == ["failed", "succeeded", "failed"]
    t.mocks["detect.by_color"].succeed(delay=1.0, label="color")
    t.mocks["detect.by_shape"].succeed(delay=5.0)
    t.mocks["detect.by_net"].hang()
    run = t.run()
    assert run.succeeded and run.blackboard["seen_by"] == "color"
    assert {c.target: c.status for c in run.calls()} == {
        "detect.by_color": "succeeded", "detect.by_shape": "halted", "detect.by_net": "halted",
        "navigation.approach": "succeeded"}
    assert run.calls("navigation.approach")[0].started == pytest.approx(1.0)


def test_all_fail_is_failure_with_a_reason_naming_each_failure(tree):
    t = tree(RACE)
    t.mocks["detect.by_color"].fail("no red blob", delay=1.0)
    t.mocks["detect.by_shape"].fail("no cylinder", delay=3.0)
    t.mocks["detect.by_net"].fail("nothing above 0.5", delay=2.0)
    run = t.run()
    assert run.failed and run.duration == pytest.approx(3.0)
    assert run.reason == ("parallel: all 3 children failed: color: detect.by_color failed: no red blob; net: "
                          "detect.by_net failed: nothing above 0.5; shape: detect.by_shape failed: no cylinder")
    assert len(run.calls("detect.by_color")) == 1   # a failed child is not run again
    assert not run.calls("navigation.approach")


def test_policy_one_still_fails_at_the_first_failure(tree):
    t = tree(RACE.replace("first_success", "one"))
    t.mocks["detect.by_color"].fail("no red blob", delay=1.0)
    t.mocks["detect.by_shape"].succeed(delay=2.0)
    t.mocks["detect.by_net"].hang()
    run = t.run()
    assert run.failed and "no red blob" in run.reason


def test_the_data_flow_counts_what_every_child_writes_when_it_succeeds(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n" + RACE.replace("inputs: {target: $pos}", "inputs: {target: $pos}\n"
                                                        "    - check: 'seen_by == \"x\"'"))
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), DEFS)
    (e,) = info.value.errors   # net does not write seen_by: it may be the one that succeeded
    assert "reads 'seen_by', which is not written on every path before this node" in str(e)
    path.write_text("format: 1\nroot:\n" + RACE)
    load_tree(str(path), DEFS)   # pos: written by every child


def test_the_policy_is_in_the_schema_and_a_misspelt_one_is_an_error(tmp_path):
    props = json_schema()["definitions"]["kind_parallel"]["properties"]
    assert props["policy"]["enum"] == ["all", "one", "first_success"]
    assert json_schema()["definitions"]["kind_for_each"]["properties"]["policy"]["enum"] == ["all", "one"]
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  parallel: [{wait: 1}]\n  policy: first_succes\n")
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), DEFS)
    assert "policy must be 'all' or 'one' or 'first_success' (did you mean 'first_success'?)" in str(info.value)
