"""What a team moving from BehaviorTree.CPP 4 + Groot ran into: a ``{key}`` template where a value other
than text goes, written in a call or passed through an include, and the hints for BehaviorTree.CPP's
habits (its XML, its names, its ports and pre/post conditions, milliseconds, ``-1`` for forever)."""
from __future__ import annotations

import os
from typing import List, Tuple

import pytest

from coordinator.cli import main as bmtree
from tests.conftest import TREES


def check(tmp_path, capsys, root: str, files=None, top: str = "format: 1\n") -> Tuple[int, List[str]]:
    """``bmtree check`` of ``t.yaml`` (``root:`` then ``root``; ``files``: other files beside it): its exit
    status and stderr lines, the folder left out of the file names."""
    for name, text in (files or {}).items():
        (tmp_path / name).write_text(text)
    path = tmp_path / "t.yaml"
    path.write_text(top + "root:\n" + root)
    status = bmtree(["check", str(path)])
    return status, [line.replace(str(tmp_path) + os.sep, "") for line in capsys.readouterr().err.splitlines()]


# 2. a template makes text -------------------------------------------------------------------------------
FIND = """  sequence:
    - call: vision.find_object
      inputs: {object: apple}
      outputs: {position: obj_pos}
"""


def test_a_template_passed_to_a_message_input_says_it_makes_text_not_a_made_up_value(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, FIND + "    - call: navigation.approach\n"
                                                   "      inputs: {target: \"{obj_pos}\"}\n")
    assert status == 2
    assert lines == ["t.yaml:8:25: input 'target' takes a mapping of fields x, y, z (geometry_msgs/Point), got "
                     "'{obj_pos}': a {…} template makes text; write $obj_pos"]


def test_a_template_in_a_field_and_one_of_an_expression(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, FIND + "    - call: navigation.approach\n"
                                                   "      inputs: {target: {x: \"{obj_pos.x + 1}\", y: 0, z: 0}}\n")
    assert status == 2 and len(lines) == 1
    assert "field x takes a number (float64), got '{obj_pos.x + 1}': a {…} template makes text; write " \
           "$(obj_pos.x + 1)" in lines[0]
    # text around a hole, into text: fine
    status, lines = check(tmp_path, capsys, FIND + "    - call: speech.say\n"
                                                   "      inputs: {text: \"at {obj_pos.x}\"}\n")
    assert (status, lines) == (0, [])


SUB = """format: 1
inputs:
  target: {}
root:
  call: navigation.approach
  inputs: {target: $target}
"""


def test_a_template_passed_through_an_include_is_reported_where_the_subtree_uses_it(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, FIND + "    - include: sub.yaml\n      args: {target: \"{obj_pos}\"}\n",
                          {"sub.yaml": SUB})
    assert status == 2
    assert lines == ["sub.yaml:6:20: input 'target' takes a mapping of fields x, y, z (geometry_msgs/Point), got "
                     "$target, which is the template '{obj_pos}' (argument 'target' of the include at t.yaml:7): a "
                     "{…} template makes text; pass target: $obj_pos there"]
    # the reference itself: fine
    status, lines = check(tmp_path, capsys, FIND + "    - include: sub.yaml\n      args: {target: $obj_pos}\n",
                          {"sub.yaml": SUB})
    assert (status, lines) == (0, [])


def test_shipped_trees_still_check():
    for name in sorted(os.listdir(TREES)):
        if name.endswith(".yaml"):
            assert bmtree(["check", os.path.join(TREES, name)]) == 0, name


@pytest.fixture(autouse=True)
def _cwd(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)


# 3. an unknown module is one error: what its nodes write still counts as written ---------------------------
def test_a_wait_event_of_an_unknown_module_or_event_writes_its_outputs_for_the_data_flow(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """  sequence:
    - wait_event: charger.low
      outputs: {percentage: pct}
    - check: 'pct > 20'
    - wait_event: navigation.arived
      outputs: {place: p}
    - check: 'p == "x"'
""")
    assert status == 2
    assert [line.split(": ", 1)[0] for line in lines] == ["t.yaml:4:19", "t.yaml:7:19"], lines
    assert lines[0].startswith("t.yaml:4:19: unknown module 'charger'")
    assert lines[1] == "t.yaml:7:19: module 'navigation' has no event 'arived' (did you mean 'arrived'?)"


# 4. hints for BehaviorTree.CPP's habits ---------------------------------------------------------------------
def test_a_behaviortree_cpp_xml_file_is_named_as_such(tmp_path, capsys):
    path = tmp_path / "t.xml"
    path.write_text('<?xml version="1.0"?>\n<root BTCPP_format="4">\n  <BehaviorTree ID="Main"/>\n</root>\n')
    assert bmtree(["check", str(path)]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "t.xml:1:1: this looks like BehaviorTree.CPP XML (<root BTCPP_format=…>); bmtree trees are YAML: 'bmtree "
        "import FILE.xml -o FILE.yaml' converts it, and trees/README.md's 'Nodes' section names what each "
        "BehaviorTree.CPP node is in bmtree"]


@pytest.mark.parametrize("written", ['"{obj_pos}"', '"$obj_pos"', "{obj_pos}"])
def test_an_output_written_to_a_port_is_told_to_write_the_key_with_no_knock_on_error(tmp_path, capsys, written):
    status, lines = check(tmp_path, capsys, """  sequence:
    - call: vision.find_object
      inputs: {object: apple}
      outputs:
        position: %s
    - call: navigation.approach
      inputs: {target: $obj_pos}
""" % written)
    assert status == 2 and len(lines) == 1, lines
    assert lines[0].startswith("t.yaml:7:%d: tree key " % (19 if written.startswith("{") else 20))
    assert lines[0].endswith(" is not an identifier: an output is written to a tree key by its plain name: "
                             "write obj_pos")


@pytest.mark.parametrize("root,said", [
    ("  speech.say: {text: hi}\n",
     "t.yaml:3:3: unknown node kind 'speech.say' (a function is called by a call node: write call: speech.say "
     "with inputs: {...} beside it)"),
    ("  call: vision.find_object\n  object: apple\n",
     "t.yaml:4:3: unknown option 'object' for call: 'object' is an input of vision.find_object: move it under "
     "inputs: (inputs: {object: …})"),
    ("  wait: 1\n  _successIf: 'done'\n",
     "t.yaml:4:3: unknown option '_successIf' for wait (BehaviorTree.CPP's _successIf condition has no option in "
     "bmtree: write a selector of check: 'condition' and the node (SUCCESS without running it when the condition "
     "holds))"),
    ("  wait: 1\n  _onHalted: 'x := 1'\n",
     "t.yaml:4:3: unknown option '_onHalted' for wait (BehaviorTree.CPP's _onHalted condition has no option in "
     "bmtree: write what it does as the tree's cleanup: (a node beside root:), which runs once after root ends, "
     "however it ended, also when it was halted (see 'Cleaning up' in trees/README.md))"),
    ("  include: sub.yaml\n  _autoremap: true\n",
     "t.yaml:4:3: unknown option '_autoremap' for include (BehaviorTree.CPP's _autoremap has no option "
     "in bmtree: write include alone: it shares the tree blackboard (the subtree reads and writes the caller's "
     "keys by their own names); args: sets its inputs and outputs: copies its keys to other names (see 'Subtrees' "
     "in trees/README.md))"),
    ("  wait: 1\n  _onSuccess: 'x := 1'\n",
     "t.yaml:4:3: unknown option '_onSuccess' for wait (BehaviorTree.CPP's _onSuccess condition has no option in "
     "bmtree: write a sequence of the node and set: {key: value} (what comes after the node runs only when it "
     "succeeded))"),
    ("  parallel: [{wait: 1}]\n  failure_count: 2\n",
     "t.yaml:4:3: unknown option 'failure_count' for parallel (parallel takes ended_by, name, policy, succeed_on, "
     "synchronise): BehaviorTree.CPP's success_count and failure_count are parallel's policy: all (every child "
     "succeeds), one (the first success wins, the first failure fails it), first_success (the first success wins, "
     "it fails only when all failed), or succeed_on: [names]"),
    ("  switch: a\n  case_1: a\n  cases: {a: {wait: 1}}\n",
     "t.yaml:4:3: unknown option 'case_1' for switch (switch takes cases, default, match, name): BehaviorTree.CPP's "
     "variable is switch's value, and its case_N ports its cases: switch: $key, with cases: {value: node} and "
     "default: node"),
    ("  retry: -1\n  child: {wait: 1}\n",
     "t.yaml:3:10: count of retry is -1, BehaviorTree.CPP's 'forever': every bmtree loop is bounded, so give the "
     "most attempts it may take (retry: 100); see 'Every loop is bounded' in trees/README.md"),
    ("  repeat: -1\n  child: {wait: 1}\n",
     "t.yaml:3:11: count of repeat is -1, BehaviorTree.CPP's 'forever': every bmtree loop is bounded, so give the "
     "most runs it may take (repeat: 100); see 'Every loop is bounded' in trees/README.md"),
])
def test_behaviortree_cpp_habits_get_what_bmtree_writes(tmp_path, capsys, root, said):
    status, lines = check(tmp_path, capsys, root, {"sub.yaml": "format: 1\nroot: {wait: 0}\n"})
    assert (status, lines) == (2, [said])


@pytest.mark.parametrize("name,part", [
    ("Script", "set: {key: \"$( … )\"} for an assignment"),
    ("RunOnce", "a selector of check: 'done' and a sequence of the node and set: {done: true}"),
    ("LoopString", "BehaviorTree.CPP's LoopString is bmtree's for_each: LIST"),
    ("LoopDouble", "is bmtree's for_each"), ("LoopNode", "is bmtree's for_each"),
    ("AlwaysSuccess", "check: 'true' succeeds at once"), ("AlwaysFailure", "is bmtree's fail"),
    ("WhileDoElse", "a selector with memory: false of a sequence [check, do-node] and the else-node"),
    ("UnsetBlackboard", "set: {key: null}"), ("Action", "call: module.function"),
    ("Condition", "check: 'expression' over tree keys"),
])
def test_more_behaviortree_cpp_names_have_a_hint(tmp_path, capsys, name, part):
    status, lines = check(tmp_path, capsys, "  %s: {}\n" % name)
    assert status == 2 and len(lines) == 1 and part in lines[0], lines


def test_a_duration_in_milliseconds_by_habit_is_a_warning(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """  sequence:
    - timeout: 3000
      child: {call: speech.say, inputs: {text: hi}, timeout: 5000}
    - wait: 500
    - retry: 2
      delay: 1000
      child: {wait: 3600}
""")
    assert status == 0
    assert lines == [
        "t.yaml:4:16: warning: duration of timeout is 3000 seconds (50 min): durations are in seconds; for 3000 "
        "milliseconds write 3",
        "t.yaml:5:62: warning: timeout of call is 5000 seconds (83 min): durations are in seconds; for 5000 "
        "milliseconds write 5",
        "t.yaml:8:14: warning: delay of retry is 1000 seconds (17 min): durations are in seconds; for 1000 "
        "milliseconds write 1"]


def test_a_set_of_text_that_is_an_expression_over_keys_is_a_warning(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """  set:
    counter: "counter + 1"
    said: "see you - later"
    where: "kitchen or hall"
    size: "len(rooms)"
""", top="format: 1\ninputs: {counter: {default: 0}, rooms: {default: [a]}, kitchen: {default: 1}, hall: {default: 2}}\n")
    assert status == 0
    assert lines == [
        "t.yaml:5:15: warning: counter: 'counter + 1' is stored as that text, not worked out: did you mean "
        "\"$(counter + 1)\"?",
        "t.yaml:8:12: warning: size: 'len(rooms)' is stored as that text, not worked out: did you mean "
        "\"$(len(rooms))\"?"]


def test_a_mapping_written_in_quotes_is_said_to_be_text(tmp_path, capsys):
    """``target: "{x: 1, y: 2}"`` is a {…} template (text), not the geometry_msgs/Point meant: write it
    without quotes (a call's input, a set's value by their key; elsewhere the mapping alone)."""
    status, lines = check(tmp_path, capsys, """  sequence:
    - call: navigation.approach
      inputs: {target: "{x: 1, y: 2}"}
    - set: {where: "{x: 1}"}
    - switch: "{a: b}"
      cases: {x: {wait: 1}}
    - call: speech.say
      inputs: {text: "{where}"}
""")
    assert status == 2
    assert lines == [
        "t.yaml:5:25: \"{x: 1, y: 2}\" is text in quotes (a {…} template), not a mapping: write the mapping without "
        "quotes: target: {x: 1, y: 2}",
        "t.yaml:6:21: \"{x: 1}\" is text in quotes (a {…} template), not a mapping: write the mapping without "
        "quotes: where: {x: 1}",
        "t.yaml:7:16: \"{a: b}\" is text in quotes (a {…} template), not a mapping: write the mapping without "
        "quotes: {a: b}"]


def test_a_mapping_in_quotes_as_an_include_argument_or_a_default_names_its_key(tmp_path, capsys):
    sub = "format: 1\ninputs: {target: {}}\nroot:\n  call: navigation.approach\n  inputs: {target: $target}\n"
    status, lines = check(tmp_path, capsys, """  include: sub.yaml
  args: {target: "{x: 1, y: 2}"}
""", files={"sub.yaml": sub}, top='format: 1\ninputs:\n  spot: {default: "{x: 3}"}\n')
    assert status == 2
    assert lines[:2] == [
        "t.yaml:3:20: \"{x: 3}\" is text in quotes (a {…} template), not a mapping: write the mapping without "
        "quotes: default: {x: 3}",
        "t.yaml:6:19: \"{x: 1, y: 2}\" is text in quotes (a {…} template), not a mapping: write the mapping without "
        "quotes: target: {x: 1, y: 2}"], lines
