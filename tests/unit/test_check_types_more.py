"""``bmtree check`` uses what the module definitions say a tree key holds in three more places:
references into a key's fields (``$g.positon`` after ``g`` got a ``geometry_msgs/Pose``), counts,
durations and ``for_each`` lists given as references or expressions (``wait: $answer`` after
``speech.listen`` wrote text), and ``recall`` names (``arm/pick/grasp_pos``), whose outputs also
give the recalled keys their types. Keys whose type is not known (tree inputs) stay unchecked; what a ``set``
writes has a kind (``tests/unit/test_check_set_kinds.py``)."""
from __future__ import annotations

import json
import os

import pytest

from coordinator.cli import main as bmtree
from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from coordinator.refs import RefError, parse_ref
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA

ARM = {
    "Basic Module": "arm",
    "Brief Description": "An arm of the tests: picks an object and gives the pose it grasped it at.",
    "Hardware Required": [],
    "Functions": [
        {"Name": "pick", "Exec-condition": "", "Description": "Picks what is at the target.",
         "Input-params": [{"Name": "target", "Data-type": "geometry_msgs/Point", "Description": "where"}],
         "Output-params": [{"Name": "success", "Data-type": "std_msgs/Bool", "Description": "picked"},
                           {"Name": "grasp_pose", "Data-type": "geometry_msgs/Pose", "Description": "how"},
                           {"Name": "joints", "Data-type": "sensor_msgs/JointState", "Description": "the arm"}]},
        {"Name": "place", "Exec-condition": "", "Description": "Places what it holds.",
         "Input-params": [{"Name": "pose", "Data-type": "geometry_msgs/Pose", "Description": "where"}],
         "Output-params": [{"Name": "success", "Data-type": "std_msgs/Bool", "Description": "placed"}]},
    ],
}


@pytest.fixture(scope="module")
def arm_json(tmp_path_factory):
    path = tmp_path_factory.mktemp("arm") / "arm.json"
    path.write_text(json.dumps(ARM))
    return str(path)


@pytest.fixture(scope="module")
def defs(arm_json):
    return load_definitions([SIM_DIR, os.path.join(DATA, "modules_lang"), arm_json])


PICK = """format: 1
inputs:
  pose_in: {default: {position: {x: 1}}}
root:
  sequence:
    - call: arm.pick
      inputs: {target: {x: 1, y: 2, z: 0}}
      outputs: {grasp_pose: g, joints: js}
    - call: speech.listen
      inputs: {seconds: 5}
      outputs: {text: answer}
    - call: house.battery
      outputs: {state: battery}
"""


def found(tmp_path, defs, nodes: str):
    """The errors and warnings of PICK followed by ``nodes`` (each line indented under the sequence),
    ``file:line:column: message`` with the file shortened to t.yaml."""
    path = tmp_path / "t.yaml"
    path.write_text(PICK + "".join("    " + line + "\n" for line in nodes.strip("\n").split("\n")))
    try:
        tree = load_tree(str(path), defs)
    except TreeErrors as exc:
        return [str(e).replace(str(path), "t.yaml") for e in exc.errors + exc.warnings]
    return [str(e).replace(str(path), "t.yaml") for e in tree.warnings]


# 1. references into fields ---------------------------------------------------------------------
POSE_NO_POSITON = "g holds a geometry_msgs/Pose, which has no field 'positon' (did you mean 'position'?)"


@pytest.mark.parametrize("node,expected", [
    ("- call: arm.place\n  inputs: {pose: $g.positon}",
     "t.yaml:15:22: input 'pose': reads g.positon, but " + POSE_NO_POSITON),
    ("- call: arm.pick\n  inputs: {target: $g.position.xx}",
     "t.yaml:15:24: input 'target': reads g.position.xx, but g.position holds a geometry_msgs/Point, which has "
     "no field 'xx' (did you mean 'x'?)"),
    ("- check: 'g.positon.x > 0'", "t.yaml:14:15: reads g.positon, but " + POSE_NO_POSITON),
    ("- check: '$g.positon.x > 0'", "t.yaml:14:15: reads g.positon, but " + POSE_NO_POSITON),
    ("- call: speech.say\n  inputs: {text: \"I hold it at {g.positon}\"}",
     "t.yaml:15:37: input 'text': reads g.positon, but " + POSE_NO_POSITON),
    ("- call: arm.pick\n  inputs: {target: \"$g[0]\"}",
     "t.yaml:15:25: input 'target': reads g[0], but g holds a geometry_msgs/Pose, which is not a list"),
    ("- set: {x: \"$(g.orientation.ww + 1)\"}",
     "t.yaml:14:19: reads g.orientation.ww, but g.orientation holds a geometry_msgs/Quaternion, which has no "
     "field 'ww' (did you mean 'w'?)"),
    ("- switch: $answer.dat\n  cases: {\"yes\": {wait: 0}}",
     "t.yaml:14:15: reads answer.dat, but answer holds text (std_msgs/String), which has no field 'dat' "
     "(did you mean 'data'?)"),
    ("- repeat: 2\n  until: 'battery.percentag < 20'\n  child: {wait: 0}",
     "t.yaml:15:15: reads battery.percentag, but battery holds a sensor_msgs/BatteryState, which has no field "
     "'percentag' (did you mean 'percentage'?)"),
    ("- check: 'g.position.q > 0'",
     "t.yaml:14:15: reads g.position.q, but g.position holds a geometry_msgs/Point, which has no field 'q' "
     "(its fields: x, y, z)"),
    ("- check: 'answer.data.x > 0'",
     "t.yaml:14:15: reads answer.data.x, but answer.data holds text (string), which has no fields"),
    ("- check: 'js.name.x > 0'",
     "t.yaml:14:15: reads js.name.x, but js.name holds a list (string[]), which has no fields (an element is "
     "js.name[0])"),
    ("- check: 'js[0] == 1'",
     "t.yaml:14:15: reads js[0], but js holds a sensor_msgs/JointState, which is not a list"),
    ("- wait: $(g.positon.x)",
     "t.yaml:14:15: reads g.positon, but " + POSE_NO_POSITON),
    ("- call: arm.place\n  inputs: {pose: {position: $g.positon, orientation: {w: 1}}}",
     "t.yaml:15:22: input 'pose': reads g.positon, but " + POSE_NO_POSITON),
])
def test_a_reference_into_a_field_the_type_does_not_have_is_an_error_at_the_reference(tmp_path, defs, node,
                                                                                    expected):
    assert found(tmp_path, defs, node) == [expected]


def test_a_field_reference_is_checked_in_an_include_argument(tmp_path, defs):
    (tmp_path / "sub.yaml").write_text("format: 1\ninputs:\n  x: {}\nroot:\n  check: 'x > 0'\n")
    assert found(tmp_path, defs, "- include: sub.yaml\n  args: {x: $g.position.xx}") == [
        "t.yaml:15:17: reads g.position.xx, but g.position holds a geometry_msgs/Point, which has no field 'xx' "
        "(did you mean 'x'?)"]


@pytest.mark.parametrize("node", [
    "- call: arm.pick\n  inputs: {target: $g.position}",
    "- check: 'g.position.x > 0 and g.orientation.w <= 1'",
    "- check: 'answer.data == \"yes\" and answer[0] == \"y\"'",          # text is indexed by character
    "- check: 'js.name[0] == \"elbow\" and len(js.position) > 0'",
    "- check: 'js.header.stamp.secs > 0'",                                # a time: not followed, not refused
    "- call: speech.say\n  inputs: {text: \"{pose_in.positon.x}\"}",      # a tree input: type not known
    "- set: {p: {position: {x: 1}}}\n- check: 'p.positon.x > 0'",        # set: type not known
    "- call: navigation.approach\n  inputs: {target: $battery.percentage}",   # a number for a Point: not this
])
def test_fields_that_exist_or_keys_of_unknown_type_are_not_refused(tmp_path, defs, node):
    errs = [e for e in found(tmp_path, defs, node) if "reads" in e]
    assert errs == []


def test_a_key_two_writers_give_different_types_is_not_checked(tmp_path, defs):
    assert found(tmp_path, defs, "- call: navigation.where_am_i\n  outputs: {position: g}\n"
                                 "- check: 'g.x > 0 or g.positon.x > 0'") == []


def test_the_run_time_error_of_a_missing_field_says_did_you_mean():
    from geometry_msgs.msg import Pose

    values = {"g": Pose(), "d": {"room": "kitchen"}, "t": "hi"}
    said = {}
    for text in ("$g.positon", "$g.position.xx", "$d.rom", "$g[0]", "$t[5]", "$t.data"):
        with pytest.raises(RefError) as info:
            parse_ref(text).resolve(values.__getitem__)
        said[text] = str(info.value)
    assert said == {
        "$g.positon": "g has no field 'positon' (did you mean 'position'?)",
        "$g.position.xx": "g.position has no field 'xx' (did you mean 'x'?)",
        "$d.rom": "d has no field 'rom' (did you mean 'room'?)",
        "$g[0]": "g has no index 0: it holds a geometry_msgs/Pose, not a list",
        "$t[5]": "t has no index 5 (it has 2 characters)",
        "$t.data": "t has no field 'data': it holds text, which has no fields",
    }


def test_a_call_whose_input_misses_a_field_fails_with_did_you_mean_when_running(tmp_path, bmtree_tree, defs):
    """A tree input's type is not known before running: the run says it, with the closest field (a value
    the test kit gives; the tree's own default is checked before running: test_check_input_values.py)."""
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\ninputs:\n  where: {}\nroot:\n"
                    "  call: navigation.approach\n  inputs: {target: $where.positon}\n")
    run = bmtree_tree(str(path), definitions=defs, inputs={"where": {"position": {"x": 1.0, "y": 2.0}}}).run()
    assert run.failed and "cannot build the call: where has no field 'positon' (did you mean 'position'?)" \
        in run.reason, run.reason


# 2. counts, durations and lists given as references or expressions -----------------------------------
@pytest.mark.parametrize("node,expected", [
    ("- wait: $answer", "t.yaml:14:13: duration of wait $answer holds text (std_msgs/String), not a number of "
                        "seconds >= 0"),
    ("- wait: $(answer + \"s\")", "t.yaml:14:13: duration of wait $(answer + \"s\") is text, not a number of "
                                 "seconds >= 0"),
    ("- wait: $(answer == \"x\")", "t.yaml:14:13: duration of wait $(answer == \"x\") is true or false, not a "
                                  "number of seconds >= 0"),
    ("- retry: $answer\n  child: {wait: 0}",
     "t.yaml:14:14: count of retry $answer holds text (std_msgs/String), not an integer >= 1"),
    ("- retry: 2\n  delay: $answer\n  child: {wait: 0}",
     "t.yaml:15:14: delay of retry $answer holds text (std_msgs/String), not a number of seconds >= 0"),
    ("- repeat: $g\n  child: {wait: 0}",
     "t.yaml:14:15: count of repeat $g holds a geometry_msgs/Pose, not an integer >= 1"),
    ("- timeout: $answer\n  child: {wait: 0}",
     "t.yaml:14:16: duration of timeout $answer holds text (std_msgs/String), not a positive number of seconds"),
    ("- call: speech.say\n  inputs: {text: hi}\n  timeout: $js.name",
     "t.yaml:16:16: timeout of call $js.name holds a list (string[]), not a positive number of seconds"),
    ("- recall: {r: room}\n  timeout: $answer",
     "t.yaml:15:16: timeout of recall $answer holds text (std_msgs/String), not a positive number of seconds"),
    ("- wait_event: navigation.arrived\n  timeout: $(upper(answer))",
     "t.yaml:15:16: timeout of wait_event $(upper(answer)) is text, not a positive number of seconds"),
    ("- for_each: $answer\n  as: a\n  child: {wait: 0}",
     "t.yaml:14:17: for_each $answer holds text (std_msgs/String), not a list"),
    ("- for_each: $js\n  as: a\n  child: {wait: 0}",
     "t.yaml:14:17: for_each $js holds a sensor_msgs/JointState, not a list"),
    ("- for_each: $(lower(answer))\n  as: a\n  child: {wait: 0}",
     "t.yaml:14:17: for_each $(lower(answer)) is text, not a list"),
    ("- for_each: [a, b]\n  as: a\n  max: $answer\n  child: {wait: 0}",
     "t.yaml:16:12: max of for_each $answer holds text (std_msgs/String), not an integer >= 1"),
    # a constant expression is worked out when the tree loads: its value is checked then
    ("- wait: $(\"five\")", "t.yaml:14:13: duration of wait is 'five', not a number of seconds >= 0"),
    ("- retry: $(5 / 2)\n  child: {wait: 0}", "t.yaml:14:14: count of retry is 2.5, not an integer >= 1"),
    ("- timeout: $(1 - 1)\n  child: {wait: 0}",
     "t.yaml:14:16: duration of timeout is 0, not a positive number of seconds"),
    ("- for_each: $(\"abc\")\n  as: a\n  child: {wait: 0}", "t.yaml:14:17: for_each is 'abc', not a list"),
    # what a set writes has a kind (coordinator.keykinds)
    ("- set: {n: two}\n- retry: $n\n  child: {wait: 0}", "t.yaml:15:14: count of retry $n holds text, not an integer >= 1"),
])
def test_a_count_duration_or_list_of_a_known_wrong_type_is_an_error(tmp_path, defs, node, expected):
    assert found(tmp_path, defs, node) == [expected]


@pytest.mark.parametrize("node", [
    "- retry: $battery.percentage\n  child: {wait: 0}",       # a float32: 3.0 is a count when running
    "- wait: $(len(answer))",
    "- wait: $battery.voltage",
    "- repeat: $(len(js.name) + 1)\n  child: {wait: 0}",
    "- for_each: $js.name\n  as: joint\n  child: {wait: 0}",
    "- for_each: [$answer, $g.position.x]\n  as: v\n  child: {wait: 0}",
    "- retry: $(6 / 2)\n  child: {wait: 0}",                 # 3.0: taken as 3
    "- wait: $pose_in",                                       # a tree input: type not known
    "- for_each: $(pose_in)\n  as: v\n  child: {wait: 0}",
])
def test_counts_durations_and_lists_that_can_be_right_are_not_refused(tmp_path, defs, node):
    assert found(tmp_path, defs, node) == []


def test_an_operand_error_is_said_once_not_again_as_the_wrong_kind(tmp_path, defs):
    assert found(tmp_path, defs, "- wait: $(answer * 2)") == ["t.yaml:14:22: cannot multiply a string and a number"]


@pytest.mark.parametrize("node,name", [
    ("wait: 5", "wait 5s"),
    ("wait: 0.5", "wait 0.5s"),
    ("wait: $pause", "wait $pause"),
    ("wait: $(pause + 1)", "wait $(pause + 1)"),
    ("wait: $(pause + \"s\")", "wait $(pause + \"s\")"),
])
def test_the_default_name_of_a_wait_shows_its_duration_as_written(tmp_path, defs, node, name):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\ninputs:\n  pause: {default: 1}\nroot:\n  " + node + "\n")
    assert load_tree(str(path), defs).root.name == name


# 3. recall names --------------------------------------------------------------------------------
@pytest.mark.parametrize("names,expected", [
    ("{x: arm/pick/grasp_pos}",
     ["t.yaml:14:19: blackboard name 'arm/pick/grasp_pos': arm.pick has no output 'grasp_pos' "
      "(did you mean 'grasp_pose'?)"]),
    ("{z: arm/pik/success}",
     ["t.yaml:14:19: blackboard name 'arm/pik/success': module 'arm' has no function 'pik' (did you mean 'pick'?)"]),
    ("{z: arm/wave/success}",
     ["t.yaml:14:19: blackboard name 'arm/wave/success': module 'arm' has no function 'wave' (functions: pick, "
      "place)"]),
    ("{z: arm/place/grasp_pose}",
     ["t.yaml:14:19: blackboard name 'arm/place/grasp_pose': arm.place has no output 'grasp_pose' "
      "(outputs: success)"]),
    ("{y: arms/pick/grasp_pose}",
     ["t.yaml:14:19: warning: recall of 'arms/pick/grasp_pose': no definition of module 'arms' is loaded "
      "(did you mean 'arm'?): the recall finds it only if a module of that name stored it"]),
    ("{w: sucess}",
     ["t.yaml:14:19: warning: recall of 'sucess': no function of the known modules (arm, battery, house, navigation, "
      "speech, vision) has an output 'sucess' (did you mean 'success'?)"]),
    ("{w: never_stored}",
     ["t.yaml:14:19: warning: recall of 'never_stored': no function of the known modules (arm, battery, house, "
      "navigation, speech, vision) has an output 'never_stored': the recall finds it only if a module whose "
      "definition is not given stored it"]),
])
def test_a_recall_name_is_checked_against_the_definitions(tmp_path, defs, names, expected):
    assert found(tmp_path, defs, "- recall: " + names) == expected


@pytest.mark.parametrize("names", [
    "{x: arm/pick/grasp_pose, y: success, z: grasp_pose}",
    "{x: PYTHON_BM/graspObject/final_pos}",       # a module the checker has no definition of: may be stored
    "{x: house/rooms/rooms, y: navigation/go_to/room}",
])
def test_recall_names_of_known_outputs_or_unknown_modules_pass(tmp_path, defs, names):
    assert found(tmp_path, defs, "- recall: " + names) == []


def test_without_definitions_a_recall_name_is_not_checked(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  recall: {x: arm/pik/success, y: sucess}\n")
    assert load_tree(str(path), {}).warnings == []


def test_a_recalled_output_gives_its_key_the_output_type(tmp_path, defs):
    assert found(tmp_path, defs, "- recall: {p: arm/pick/grasp_pose, room: navigation/go_to/room}\n"
                                 "- check: 'p.positon.x > 0'\n"
                                 "- wait: $room\n"
                                 "- call: arm.place\n  inputs: {pose: $p}") == [
        "t.yaml:15:15: reads p.positon, but p holds a geometry_msgs/Pose, which has no field 'positon' "
        "(did you mean 'position'?)",
        "t.yaml:16:13: duration of wait $room holds text (std_msgs/String), not a number of seconds >= 0"]


def test_a_plain_recall_name_gives_no_type(tmp_path, defs):
    """The latest ``position`` may come from any module (also one whose definition is not given)."""
    assert found(tmp_path, defs, "- recall: {p: position}\n- check: 'p.positon.x > 0'") == []


def test_check_exit_codes_of_recall_names(tmp_path, capsys, arm_json):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  recall: {y: arms/pick/grasp_pose}\n")
    assert bmtree(["check", "--modules", arm_json, str(path)]) == 0
    assert bmtree(["check", "--strict", "--modules", arm_json, str(path)]) == 2
    path.write_text("format: 1\nroot:\n  recall: {y: arm/pick/grasp_pos}\n")
    assert bmtree(["check", "--modules", arm_json, str(path)]) == 2
    err = capsys.readouterr().err
    assert "t.yaml:3:15: blackboard name 'arm/pick/grasp_pos': arm.pick has no output 'grasp_pos' " \
           "(did you mean 'grasp_pose'?)" in err
    assert "Traceback" not in err
