"""Hints from the RoboCup@Home audit: a failed check says the values it compared, a misplaced or
misspelt option says what would fix it, an unquoted template or a YAML slip says to quote."""
from __future__ import annotations

import json

import pytest

from coordinator.cli import main as bmtree
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runstream import RunStream
from coordinator.testing import TreeTest
from tests.unit.test_check_messages import check

# 1. a failed check says the values it compared -----------------------------------------------------
ROOMS = """format: 1
inputs:
  host_room: {default: hall}
root:
  sequence:
    - call: navigation.go_to
      inputs: {place: kitchen}
      outputs: {room: arrived_room}
    - check: arrived_room == host_room
"""


def test_a_failed_check_says_the_values_it_compared_in_the_reason_the_run_log_and_the_replay(tmp_path, capsys):
    path = tmp_path / "t.yaml"
    path.write_text(ROOMS)
    t = TreeTest(str(path))
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    log = str(tmp_path / "run.jsonl")
    run = t.run(observers=[RunStream([RunLogWriter(log, fsync=False)], {"inputs": {}})])
    said = "arrived_room == host_room is false (arrived_room = 'kitchen', host_room = 'hall')"
    assert run.failed and run.reason.endswith(said), run.reason
    assert read_log(log).end["reason"] == run.reason
    assert bmtree(["replay", log, "--failure"]) == 0
    assert said in capsys.readouterr().out


def test_the_values_said_are_brief_and_each_said_once():
    from coordinator.expr import Expr, brief

    e = Expr.parse("len(answer) > 3 and answer != 'x' and p.x > 1 and missing")
    values = {"answer": "a" * 100, "p": {"x": 0.5, "y": 2}}
    assert e.values_read(values.__getitem__) == " (answer = '%s…, p.x = 0.5)" % ("a" * 38)
    assert brief(list(range(100))).endswith("…") and len(brief(list(range(100)))) == 40
    assert brief(True) == "true" and brief(None) == "null" and brief({"x": 1.0}) == "{x: 1.0}"
    assert Expr.parse("1 > 2").values_read({}.__getitem__) == ""


# 2. a leaf's option beside a decorator or composite ------------------------------------------------
def test_a_call_option_beside_a_decorator_says_where_it_belongs(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
root:
  sequence:
    - retry: 3
      child:
        call: speech.say
      inputs: {text: hi}
    - sequence: [{wait: 1}]
      outputs: {text: heard}
""")
    assert status == 2
    assert "t.yaml:7:7: unknown option 'inputs' for retry (retry takes child, delay, index, name): 'inputs' is an " \
           "option of the call at line 6: indent it under that call" in lines
    assert "t.yaml:9:7: unknown option 'outputs' for sequence (sequence takes memory, name): 'outputs' is an " \
           "option of call, wait_event or include: indent it under the node it is for" in lines


def test_a_call_beside_a_decorator_is_nested_under_its_child(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  retry: 3\n  call: speech.say\n  inputs: {text: hi}\n")
    assert status == 2
    assert lines == ["t.yaml:4:3: node has two kinds, 'retry' and 'call': nest the call and its inputs under 'child:'"]


# 3. text that YAML read as a mapping or a list ---------------------------------------------------------
def test_an_unquoted_template_says_to_quote_it(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
inputs:
  object: {default: apple}
root:
  sequence:
    - call: speech.say
      inputs:
        text: {object}
    - call: speech.say
      inputs: {text: [object]}
""")
    assert status == 2
    assert lines == [
        "t.yaml:8:15: input 'text' takes text (std_msgs/String), got {'object': None}: YAML reads an unquoted "
        "{object} as a mapping; quote it: text: \"{object}\" (or $object)",
        "t.yaml:10:22: input 'text' takes text (std_msgs/String), got ['object']: YAML reads an unquoted [object] "
        "as a list; quote it: text: \"[object]\""]


# 4. YAML slips -----------------------------------------------------------------------------------------
def test_a_colon_in_a_flow_value_and_a_tab_in_the_indentation_say_the_fix(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  call: speech.say\n  inputs: {text: Hello: welcome}\n")
    assert status == 2
    assert lines == ["t.yaml:4:23: YAML syntax error: did not find expected ',' or '}': quote a value containing "
                     "': ' (text: \"Hello: welcome\")"]
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  sequence:\n    - wait: 1\n\t- wait: 2\n")
    assert status == 2
    assert lines == ["t.yaml:5:1: YAML syntax error: found a tab character that violates indentation: a tab: YAML "
                     "indents with spaces only"]


# 5. an unknown event param or output -----------------------------------------------------------------
def test_an_unknown_event_param_gets_the_param_it_shortens_or_the_list(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
root:
  wait_event: vision.personSeen
  outputs: {pos: p, xyzzy: q}
""")
    assert status == 2
    assert lines == ["t.yaml:4:13: vision.personSeen has no event param 'pos' (did you mean 'position'?)",
                     "t.yaml:4:21: vision.personSeen has no event param 'xyzzy' (event params: person, position)"]


# 6. a number compared with text ------------------------------------------------------------------------
COUNTER = {
    "Basic Module": "counter",
    "Brief Description": "Counts people.",
    "Hardware Required": [],
    "Functions": [{"Name": "count", "Exec-condition": "", "Description": "Counts the people in view.",
                   "Input-params": [],
                   "Output-params": [{"Name": "count", "Data-type": "std_msgs/Int32", "Description": "How many."}]}],
}


@pytest.mark.parametrize("expr,col,said", [
    ('count == "0"', 21, 'a number == a string is always false (write 0, not "0")'),
    ('"2" != count', 19, 'a string != a number is always true (write 2, not "2")'),
    ("str(count) == heard", 0, ""),
    ("count == heard", 21, "a number == a string is always false"),
])
def test_a_number_compared_with_text_is_an_error_with_the_fix(tmp_path, capsys, expr, col, said):
    defs = tmp_path / "counter.json"
    defs.write_text(json.dumps(COUNTER))
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  sequence:\n    - call: counter.count\n      outputs: {count: count}\n"
                    "    - call: speech.listen\n      inputs: {seconds: 3}\n      outputs: {text: heard}\n"
                    "    - check: '%s'\n" % expr)
    status = bmtree(["check", "--modules", str(defs), str(path)])
    lines = [line.replace(str(path), "t.yaml") for line in capsys.readouterr().err.splitlines()]
    if not said:
        assert status == 0, lines
        return
    assert status == 2
    assert lines == ["t.yaml:9:%d: %s" % (col, said)]


def test_check_takes_a_module_definition_as_one_and_says_its_problems_at_their_json_path(tmp_path, capsys):
    """A new author checks their gripper.json with bmtree check: it was read as a tree (missing 'root',
    unknown top-level key 'Basic Module', …)."""
    import os

    from tests.conftest import DATA

    good = os.path.join(DATA, "gripper", "gripper.json")
    assert bmtree(["check", good]) == 0
    assert capsys.readouterr().out == "%s: ok (the definition of module gripper: 2 functions, 0 events)\n" % good
    bad = tmp_path / "arm.json"
    bad.write_text(json.dumps({"Basic Module": "arm", "Brief Description": "x", "Hardware Required": [],
                                "Functions": [{"Name": "open", "Exec-condition": "", "Description": "d",
                                               "Input-params": []}]}))
    assert bmtree(["check", str(bad)]) == 2
    assert capsys.readouterr().err == "%s: Functions[0]: 'Output-params' is missing\n" % bad


def test_check_takes_the_trees_given_with_a_definition_against_it(tmp_path, capsys):
    """``bmtree check gripper.json grasp.yaml`` (a C++ author's first try) checked the definition, then
    said ``unknown module 'gripper'`` of the tree: definitions given beside trees count, whatever their
    order, as with --modules; a bad one is its own error, and the tree is not checked against it."""
    import os

    from tests.conftest import DATA

    good, tree = os.path.join(DATA, "gripper", "gripper.json"), os.path.join(DATA, "gripper", "grasp.yaml")
    assert bmtree(["check", tree, good]) == 0, capsys.readouterr()
    assert capsys.readouterr().out.splitlines() == [
        "%s: ok" % tree, "%s: ok (the definition of module gripper: 2 functions, 0 events)" % good]
    assert bmtree(["check", tree]) == 2
    assert "unknown module 'gripper'" in capsys.readouterr().err
    bad = tmp_path / "gripper.json"
    bad.write_text(json.dumps({"Basic Module": "gripper", "Brief Description": "x", "Hardware Required": []}))
    assert bmtree(["check", str(bad), tree]) == 2
    said = capsys.readouterr().err
    assert "%s: " % bad in said and "unknown module 'gripper'" in said, said
