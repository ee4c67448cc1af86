"""``bmtree check`` follows a type from the key that has it to the keys that get its value: ``for_each``'s
``as`` key holds an element of its list (``$people.poses``: a ``geometry_msgs/Pose``), a ``set`` or an
include argument of ``$g`` or ``$g.position`` gives its key what that reference holds. And a tree input
that nothing else writes is checked, as a count, duration or ``for_each`` list, with the literals it is
given: an include's argument or the default it leaves (errors), the tree's own default (a warning: its
caller may set the input)."""
from __future__ import annotations

import json
import os

import pytest

from coordinator.dataflow import key_types
from coordinator.language import load_tree
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA
from tests.unit.test_check_messages import check
from tests.unit.test_check_types_more import ARM, found

SCAN = {
    "Basic Module": "scan",
    "Brief Description": "A scanner of the tests: the poses of the people it sees.",
    "Hardware Required": [],
    "Functions": [
        {"Name": "people", "Exec-condition": "", "Description": "Finds the people around.", "Input-params": [],
         "Output-params": [{"Name": "poses", "Data-type": "geometry_msgs/PoseArray", "Description": "where"}]},
    ],
}


@pytest.fixture(scope="module")
def defs(tmp_path_factory):
    """The definitions of test_check_types_more (PICK's modules) and the scanner."""
    folder = tmp_path_factory.mktemp("defs")
    (folder / "arm.json").write_text(json.dumps(ARM))
    (folder / "scan.json").write_text(json.dumps(SCAN))
    return load_definitions([SIM_DIR, os.path.join(DATA, "modules_lang"), str(folder / "arm.json"),
                             str(folder / "scan.json")])


def types_of(tmp_path, defs, nodes: str):
    """The key types of PICK followed by ``nodes`` (written by ``found``, which must find nothing)."""
    assert found(tmp_path, defs, nodes) == []
    return key_types(load_tree(str(tmp_path / "t.yaml"), defs))


SCANNED = "- call: scan.people\n  outputs: {poses: people}\n"
NO_W = "which has no field 'w' (its fields: x, y, z)"


# 1. for_each: the `as` key holds an element of the list ------------------------------------------------
@pytest.mark.parametrize("node,expected", [
    (SCANNED + "- for_each: $people.poses\n  as: pose\n  child: {check: 'pose.position.w > 0'}",
     "t.yaml:18:23: reads pose.position.w, but pose.position holds a geometry_msgs/Point, " + NO_W),
    (SCANNED + "- for_each: $people.poses\n  as: pose\n  child:\n    call: arm.pick\n    inputs: {target: $pose}",
     "t.yaml:20:26: input 'target' takes a mapping of fields x, y, z (geometry_msgs/Point), got $pose, which "
     "holds a mapping of fields position, orientation (geometry_msgs/Pose)"),
    ("- for_each: $js.name\n  as: joint\n  child: {wait: $joint}",
     "t.yaml:16:21: duration of wait $joint holds text (string), not a number of seconds >= 0"),
    (SCANNED + "- for_each: $people.poses\n  as: pose\n  child:\n    sequence:\n      - set: {p: $pose.position}\n"
               "      - check: 'p.w > 0'",
     "t.yaml:21:21: reads p.w, but p holds a geometry_msgs/Point, " + NO_W),
])
def test_a_wrong_use_of_a_for_each_element_is_an_error_at_the_reference(tmp_path, defs, node, expected):
    assert found(tmp_path, defs, node) == [expected]


def test_right_uses_of_a_for_each_element_pass_and_its_key_holds_the_element_type(tmp_path, defs):
    types = types_of(tmp_path, defs, SCANNED + "- for_each: $people.poses\n  as: pose\n  index: i\n  child:\n"
                                               "    call: arm.place\n    inputs: {pose: $pose}\n"
                                               "- for_each: $js.name\n  as: joint\n  child:\n"
                                               "    check: 'joint[0] == \"e\" and len(joint) > 1'\n"
                                               "- for_each: [1, 2]\n  as: n\n  child: {wait: $n}")
    assert (types["pose"], types["joint"]) == ({"geometry_msgs/Pose"}, {"string"})
    assert (types["i"], types["n"]) == ({None}, {None})   # an index, a literal list: not known


# 2. set and include arguments: a copy of a reference holds what it holds ---------------------------------
@pytest.mark.parametrize("node,expected", [
    ("- set: {target: $g}\n- check: 'target.positon.x > 0'",
     "t.yaml:15:15: reads target.positon, but target holds a geometry_msgs/Pose, which has no field 'positon' "
     "(did you mean 'position'?)"),
    ("- set: {p: $g.position}\n- call: arm.place\n  inputs: {pose: $p}",
     "t.yaml:16:22: input 'pose' takes a mapping of fields position, orientation (geometry_msgs/Pose), got $p, "
     "which holds a mapping of fields x, y, z (geometry_msgs/Point)"),
    ("- set: {t: $answer}\n- wait: $t",
     "t.yaml:15:13: duration of wait $t holds text (std_msgs/String), not a number of seconds >= 0"),
    ("- set: {a: $g}\n- set: {b: $a}\n- check: 'b.position.w > 0'",
     "t.yaml:16:15: reads b.position.w, but b.position holds a geometry_msgs/Point, " + NO_W),
])
def test_a_key_set_to_a_reference_holds_its_type(tmp_path, defs, node, expected):
    assert found(tmp_path, defs, node) == [expected]


def test_an_include_argument_gives_the_input_the_type_of_its_reference(tmp_path, defs):
    (tmp_path / "sub.yaml").write_text("format: 1\ninputs:\n  where: {}\nroot:\n  check: 'where.positon.x > 0'\n")
    assert [e.replace(str(tmp_path) + os.sep, "") for e in found(tmp_path, defs, "- include: sub.yaml\n"
                                                                                 "  args: {where: $g}")] == [
        "sub.yaml:5:11: reads where.positon, but where holds a geometry_msgs/Pose, which has no field 'positon' "
        "(did you mean 'position'?)"]


def test_copies_of_known_types_are_typed_and_others_stay_unknown(tmp_path, defs):
    types = types_of(tmp_path, defs, "- set: {target: $g, p: $g.position, n: two, t: \"{answer}\"}\n"
                                     "- set: {a: $pose_in}\n- set: {b: $a}\n"       # a copy of a tree input
                                     "- set: {d: $answer}\n- set: {c: $d}\n- set: {d: $c}\n"   # copies of each other
                                     "- set: {mixed: $g}\n- set: {mixed: $answer}\n"
                                     "- call: arm.place\n  inputs: {pose: $target}\n"
                                     "- check: 'p.x > 0 and c.data == \"yes\"'")
    assert (types["target"], types["p"], types["c"]) == ({"geometry_msgs/Pose"}, {"geometry_msgs/Point"},
                                                         {"std_msgs/String"})
    assert all(types[k] == {None} for k in ("n", "t", "a", "b")), types
    assert types["mixed"] == {"geometry_msgs/Pose", "std_msgs/String"}   # two types: not checked


# 3. the literals a tree input is given, as counts, durations and lists ------------------------------------
SUB = """format: 1
inputs:
  tries: {default: 2}
  pause: {default: 0.5}
  rooms: {default: [kitchen]}
root:
  sequence:
    - retry: $tries
      child: {wait: $pause}
    - for_each: $rooms
      as: room
      child: {wait: 0}
"""


def sub_found(tmp_path, defs, nodes: str, sub: str = SUB):
    (tmp_path / "sub.yaml").write_text(sub)
    return [e.replace(str(tmp_path) + os.sep, "") for e in found(tmp_path, defs, nodes)]


@pytest.mark.parametrize("args,expected", [
    ("{tries: three}", "sub.yaml:8:14: count of retry $tries is 'three' (argument 'tries' of the include at "
                       "t.yaml:14), not an integer >= 1: pass one there"),
    ("{tries: 0}", "sub.yaml:8:14: count of retry $tries is 0 (argument 'tries' of the include at t.yaml:14), "
                   "not an integer >= 1: pass one there"),
    ("{tries: 2.5}", "sub.yaml:8:14: count of retry $tries is 2.5 (argument 'tries' of the include at "
                     "t.yaml:14), not an integer >= 1: pass one there"),
    ("{pause: soon}", "sub.yaml:9:21: duration of wait $pause is 'soon' (argument 'pause' of the include at "
                      "t.yaml:14), not a number of seconds >= 0: pass one there"),
    ("{rooms: kitchen}", "sub.yaml:10:17: for_each $rooms is 'kitchen' (argument 'rooms' of the include at "
                         "t.yaml:14), not a list: pass one there"),
])
def test_a_literal_include_argument_is_checked_where_the_subtree_uses_it(tmp_path, defs, args, expected):
    assert sub_found(tmp_path, defs, "- include: sub.yaml\n  args: " + args) == [expected]


def test_only_the_include_that_passes_a_wrong_literal_is_reported(tmp_path, defs):
    assert sub_found(tmp_path, defs, "- include: sub.yaml\n  args: {tries: 3, pause: 0, rooms: [a, b]}\n"
                                     "- include: sub.yaml\n  args: {tries: 3.0, pause: $battery.voltage}\n"
                                     "- include: sub.yaml\n  args: {tries: $(1 + 1), rooms: $js.name}\n"
                                     "- include: sub.yaml\n  args: {tries: \"3\"}") == [
        "sub.yaml:8:14: count of retry $tries is '3' (argument 'tries' of the include at t.yaml:20), not an "
        "integer >= 1: pass one there"]


def test_the_default_an_include_leaves_to_its_subtree_is_checked(tmp_path, defs):
    assert sub_found(tmp_path, defs, "- include: sub.yaml", SUB.replace("{default: 0.5}", "{default: -1}")) == [
        "sub.yaml:9:21: duration of wait $pause is -1 (the default of input 'pause'; the include at t.yaml:14 "
        "passes no argument), not a number of seconds >= 0: give the input a default that is one, or pass one"]


def test_a_literal_is_checked_only_when_nothing_else_writes_the_input(tmp_path, defs):
    args = "- include: sub.yaml\n  args: {tries: three}"
    assert len(sub_found(tmp_path, defs, args)) == 1
    written = SUB.replace("  sequence:\n", "  sequence:\n    - {call: speech.listen, inputs: {seconds: 1}, "
                                           "outputs: {text: heard}}\n    - set: {tries: $heard.data}\n")
    assert sub_found(tmp_path, defs, args, written) == []    # (its value when the retry starts is not known)
    assert sub_found(tmp_path, defs, args + "\n- set: {tries: 2}") == []


ROOT_DEFAULTS = """format: 1
inputs:
  tries: {default: three}
  rooms: {default: kitchen}
  pause: {default: 1}
root:
  sequence:
    - repeat: $tries
      child: {wait: $pause}
    - for_each: $rooms
      as: room
      child: {wait: 0}
"""


def test_a_wrong_default_of_the_tree_is_a_warning_unless_the_caller_sets_the_input(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, ROOT_DEFAULTS)
    assert (status, lines) == (0, [
        "t.yaml:8:15: warning: count of repeat $tries is 'three' (the default of input 'tries'), not an integer "
        ">= 1: a run that does not set the input fails here; give it a default that is one",
        "t.yaml:10:17: warning: for_each $rooms is 'kitchen' (the default of input 'rooms'), not a list: a run "
        "that does not set the input fails here; give it a default that is one"])
    path = str(tmp_path / "t.yaml")
    assert [e.message.split(" is ")[0] for e in load_tree(path, {}, given={"tries"}).warnings] == [
        "warning: for_each $rooms"]
    assert load_tree(path, {}, given={"tries", "rooms"}).warnings == []
