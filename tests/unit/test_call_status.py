"""A call's ``status`` and ``error`` keys (how it ended, written whether it succeeded or not: a tree
routes "grasp missed" and "arm busy" apart, as a SMACH state's outcomes do), and ``timeout: none``
(a call that waits as long as it takes), run through the mocks on the simulated clock."""
from __future__ import annotations

import pytest

from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from coordinator.schema import json_schema
from coordinator.testing import hang, reject, succeed
from modules.definition import load_definitions, parse_definition
from modules.sim import SIM_DIR
from tests.conftest import one_file_trees

ARM = parse_definition({
    "Basic Module": "arm",
    "Brief Description": "A test arm: grasps objects, follows people until told to stop.",
    "Hardware Required": [],
    "Functions": [
        {"Name": "grasp", "Exec-condition": "", "Description": "Grasp an object.",
         "Input-params": [{"Name": "object", "Data-type": "std_msgs/String", "Description": "what"}],
         "Output-params": [{"Name": "success", "Data-type": "std_msgs/Bool", "Description": "held"},
                           {"Name": "pose", "Data-type": "geometry_msgs/Pose", "Description": "where"}]},
        {"Name": "follow", "Exec-condition": "", "Description": "Follow a person until they stop.",
         "Input-params": [{"Name": "person", "Data-type": "std_msgs/String", "Description": "who"}],
         "Output-params": [{"Name": "success", "Data-type": "std_msgs/Bool", "Description": "arrived"}]},
    ],
}, "arm.json")
DEFS = dict(load_definitions([SIM_DIR]), arm=ARM)

# SMACH style: one call (a state), its status routed by a switch (its transitions)
GRASP = """
  sequence:
    - force_success:
        call: arm.grasp
        inputs: {object: cup}
        outputs: {pose: cup_pose}
        timeout: 5
        status: grasp
        error: why
    - switch: $grasp
      cases:
        succeeded: {call: speech.say, inputs: {text: "got it"}}
        failed: {call: speech.say, inputs: {text: "missed ({why})"}}
        rejected: {call: speech.say, inputs: {text: "arm busy ({why})"}}
        timeout: {call: speech.say, inputs: {text: "arm too slow ({why})"}}
"""


@pytest.fixture
def tree(tmp_path, bmtree_tree):
    """``tree(root_yaml, inputs_yaml="")`` -> a TreeTest of a one-file tree with the arm module."""
    return one_file_trees(tmp_path, bmtree_tree, DEFS)


def errors_of(tmp_path, root: str):
    path = tmp_path / "bad.yaml"
    path.write_text("format: 1\nroot:\n" + root)
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), DEFS)
    return [str(e).replace(str(path), "bad.yaml") for e in info.value.errors]


def said(run):
    return [c.inputs["text"] for c in run.calls("speech.say")]


@pytest.mark.parametrize("outcome, status, text", [
    (succeed(success=True), "succeeded", "got it"),
    (succeed(success=False), "failed", "missed (answered success: false)"),   # the grasp missed
    (reject("busy with call 7"), "rejected", "arm busy (busy with call 7)"),
    (hang(), "timeout", "arm too slow (no answer within 5s)"),
])
def test_a_switch_on_the_status_routes_each_ending(tree, outcome, status, text):
    t = tree(GRASP)
    t.mocks["arm.grasp"].script(outcome)
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == [text]
    assert run.blackboard["grasp"] == status
    # outputs when the module answered them: on success, and with success: false
    assert ("cup_pose" in run.blackboard) == (status in ("succeeded", "failed"))


def test_the_error_text_is_the_modules_and_empty_on_success(tree):
    t = tree(GRASP)
    t.mocks["arm.grasp"].fail("arm fault: joint 3 over current")
    run = t.run()
    assert run.blackboard["grasp"] == "failed" and run.blackboard["why"] == "arm fault: joint 3 over current"
    assert said(run) == ["missed (arm fault: joint 3 over current)"]
    t.mocks["arm.grasp"].succeed()
    run = t.run()
    assert run.blackboard["grasp"] == "succeeded" and run.blackboard["why"] == ""


def test_a_call_that_cannot_be_built_writes_not_sent(tree):
    t = tree("""
  force_success:
    call: arm.grasp
    inputs: {object: "$(at(objects, 3))"}
    status: st
    error: why
""", inputs="  objects: {default: [cup]}\n")
    run = t.run()
    assert run.succeeded and not run.calls("arm.grasp")
    assert run.blackboard["st"] == "not_sent"
    assert run.blackboard["why"].startswith("cannot build the call:")


def test_a_halted_call_writes_no_status(tree):
    t = tree("""
  force_success:
    timeout: 10
    child: {call: arm.follow, inputs: {person: Ana}, timeout: none, status: st, error: why}
""")
    t.mocks["arm.follow"].hang()
    run = t.run()
    assert run.succeeded and [c.status for c in run.calls()] == ["halted"]
    assert "st" not in run.blackboard and "why" not in run.blackboard
    assert run.duration == pytest.approx(10.0)


def test_the_flow_check_takes_the_status_as_written_when_the_call_fails(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text("""format: 1
root:
  sequence:
    - selector:
        - {call: arm.grasp, inputs: {object: cup}, status: st, error: why}
        - {call: speech.say, inputs: {text: "I could not: {why}"}}
    - {call: speech.say, inputs: {text: "the grasp {st}"}}
""")
    load_tree(str(path), DEFS)   # no error: both keys are written whether the grasp succeeds or fails
    # an output is still written only on success
    assert errors_of(tmp_path, """  sequence:
    - selector:
        - {call: arm.grasp, inputs: {object: cup}, outputs: {pose: p}, status: st}
        - {call: speech.say, inputs: {text: "{p}"}}
""") == ["bad.yaml:6:47: reads 'p', which is not written on every path before this node (written at line 5, but "
         "not before it on every path: write it earlier on every path or declare it under 'inputs:')"]


def test_status_and_error_keys_may_not_clash(tmp_path):
    assert errors_of(tmp_path, """  call: arm.grasp
  inputs: {object: cup}
  outputs: {success: held}
  status: held
  error: held
""") == ["bad.yaml:6:11: output 'success' and status both write tree key 'held': one value would replace the other; "
         "give status its own key",
         "bad.yaml:7:10: output 'success' and error both write tree key 'held': one value would replace the other; "
         "give error its own key"]
    assert errors_of(tmp_path, "  call: arm.grasp\n  inputs: {object: cup}\n  status: st\n  error: st\n") == [
        "bad.yaml:6:10: status and error both write tree key 'st': one value would replace the other; give error "
        "its own key"]
    assert errors_of(tmp_path, "  call: arm.grasp\n  inputs: {object: cup}\n  status: 2nd\n") == [
        "bad.yaml:5:11: status of call must be a tree key, got '2nd'"]


def test_a_switch_case_that_is_no_status_is_an_error(tmp_path):
    root = GRASP.replace("        timeout: {call", "        timed_out: {call").replace(
        "        rejected: {call", "        halted: {call")
    assert errors_of(tmp_path, root) == [
        "bad.yaml:16:9: case 'halted' never matches: $grasp is the status of the call to arm.grasp at line 6, "
        "written when the call has ended, never when it is halted (its parent moved on, and a halted call writes "
        "no status)",
        "bad.yaml:17:9: case 'timed_out' never matches: $grasp is the status of the call to arm.grasp at line 6, one "
        "of 'succeeded', 'failed', 'rejected', 'cancelled', 'timeout', 'module_lost', 'not_sent' (did you mean "
        "'timeout'?)"]
    # `contains` takes a part of a status; a key something else writes too may hold anything
    path = tmp_path / "ok.yaml"
    path.write_text("format: 1\nroot:\n" + GRASP.replace("$grasp", "$grasp\n      match: contains").replace(
        "        timeout: {call", "        fail: {call"))
    load_tree(str(path), DEFS)
    path.write_text("format: 1\nroot:\n" + GRASP.replace("timeout: {call", "timed_out: {call").replace(
        "    - switch", "    - set: {grasp: timed_out}\n    - switch"))
    load_tree(str(path), DEFS)


def test_an_unquoted_yes_case_on_a_status_is_one_error_not_two(tmp_path):
    errors = errors_of(tmp_path, GRASP.replace("        timeout: {call", "        yes: {call"))
    assert len(errors) == 1 and errors[0].startswith("bad.yaml:17:9: this case is read by YAML as true"), errors


def test_timeout_none_waits_as_long_as_it_takes(tree):
    follow = "  call: arm.follow\n  inputs: {person: Ana}\n  status: st\n"
    t = tree(follow + "  timeout: none\n")
    t.mocks["arm.follow"].succeed(delay=100)
    run = t.run(default_timeout=30)
    assert run.succeeded, run.reason
    assert run.duration == pytest.approx(100.0) and run.blackboard["st"] == "succeeded"
    t = tree(follow)   # without it: --call-timeout
    t.mocks["arm.follow"].succeed(delay=100)
    run = t.run(default_timeout=30)
    assert run.failed and run.reason.endswith("arm.follow: no answer within 30s") and run.blackboard["st"] == "timeout"
    assert {"const": "none"} in json_schema()["definitions"]["kind_call"]["properties"]["timeout"]["anyOf"]


@pytest.mark.parametrize("written, message", [
    ("null", "bad.yaml:5:12: timeout of call is null (written null, ~ or left empty), which is not read as no limit: "
             "for no time limit write 'timeout: none'; else give seconds (> 0), or leave it out for --call-timeout"),
    ("None", "bad.yaml:5:12: timeout of call must be a positive number of seconds or 'none', got 'None': for no time "
             "limit write 'timeout: none'; else give seconds (> 0), or leave it out for --call-timeout"),
    ("0", "bad.yaml:5:12: timeout of call must be a positive number of seconds, got 0: for no time limit write "
          "'timeout: none'; else give seconds (> 0), or leave it out for --call-timeout"),
    ("off", "bad.yaml:5:12: timeout of call is false (YAML reads an unquoted yes/no/on/off as true or false): for no "
            "time limit write 'timeout: none'; else give seconds (> 0), or leave it out for --call-timeout"),
])
def test_other_spellings_of_no_timeout_are_errors(tmp_path, written, message):
    assert errors_of(tmp_path, "  call: arm.follow\n  inputs: {person: Ana}\n  timeout: %s\n" % written) == [message]


def test_a_calls_outputs_are_plain_data_like_its_inputs(tree):
    """``run.calls(...)[i].inputs`` was plain data and ``.outputs`` ROS messages: one test, two styles."""
    t = tree("  call: arm.grasp\n  inputs: {object: cup}\n")
    run = t.run()
    call = run.calls("arm.grasp")[0]
    assert call.inputs == {"object": "cup"}
    assert call.outputs["success"] is True and call.outputs["pose"]["position"] == {"x": 0.0, "y": 0.0, "z": 0.0}
    assert call.output_messages["success"].data is True


def test_an_answered_success_false_still_writes_its_outputs(tree):
    """The original modules' convention: ``success: false`` and why in the other outputs (an error
    code); those outputs were dropped, so a tree could not tell "grasp missed" from "arm fault"."""
    t = tree(GRASP)
    t.mocks["arm.grasp"].succeed(success=False, pose={"position": {"x": 1.5}})
    run = t.run()
    assert run.succeeded, run.reason
    assert run.blackboard["grasp"] == "failed" and run.blackboard["why"] == "answered success: false"
    assert run.blackboard["cup_pose"]["position"]["x"] == 1.5
    assert run.said() == ["missed (answered success: false)"]
    t.mocks["arm.grasp"].script(reject("busy"))   # an answer without outputs writes none
    assert "cup_pose" not in t.run().blackboard


def test_the_reason_and_the_summary_of_a_success_false_say_the_outputs_that_tell_why(tree):
    """An original module says why in its other outputs (an error code); the reason and the summary row
    showed only ``answered success: false``. Outputs left at their defaults say nothing and are left out;
    the ``error`` key keeps its text (trees compare it)."""
    from coordinator.runner import summary_lines

    t = tree("  call: arm.grasp\n  inputs: {object: cup}\n  error: why\n")
    t.mocks["arm.grasp"].succeed(success=False, pose={"position": {"x": 1.5}})
    run = t.run()
    assert run.reason == 'arm.grasp answered success: false (pose {"position":{"x":1.5}})', run.reason
    assert run.blackboard["why"] == "answered success: false"
    row = [line for line in summary_lines(run.result, "t") if line.startswith("  +")][0]
    assert "arm.grasp" in row and "failed" in row and 'answered success: false (pose {"position":{"x":1.5}})' in row, row
    t.mocks["arm.grasp"].succeed(success=False)   # every other output at its default
    assert t.run().reason == "arm.grasp answered success: false"
