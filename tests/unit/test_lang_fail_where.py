"""Three pieces of the tree language, run through the mocks on the simulated clock: the ``fail`` leaf
(FAILURE on purpose, its text the run's reason: SMACH's outcome ``aborted``), ``wait_event``'s
``where:`` (the first event whose params satisfy an expression: SMACH's MonitorState condition), and
``for_each``'s ``max`` checked before running against a literal list, an include's argument and a tree
input's default."""
from __future__ import annotations

import os
from typing import List

import pytest

from coordinator.cli import main as bmtree
from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from coordinator.nodes import REGISTRY
from coordinator.replay import cmd_replay
from coordinator.schema import json_schema
from coordinator.testing.kit import Coverage
from coordinator.treeast import walk
from modules.definition import load_definitions, parse_definition
from modules.sim import SIM_DIR
from tests.conftest import TREES, one_file_trees
from tests.unit.test_check_messages import check
from tests.unit.test_recording import _args, recorded

ARM = parse_definition({
    "Basic Module": "arm",
    "Brief Description": "A test arm that reports its faults.",
    "Hardware Required": [],
    "Functions": [
        {"Name": "grasp", "Exec-condition": "", "Description": "Grasp an object.",
         "Input-params": [{"Name": "object", "Data-type": "std_msgs/String", "Description": "what"}],
         "Output-params": [{"Name": "success", "Data-type": "std_msgs/Bool", "Description": "held"},
                           {"Name": "pose", "Data-type": "geometry_msgs/Pose", "Description": "where"},
                           {"Name": "code", "Data-type": "std_msgs/Int32", "Description": "fault code"}]},
    ],
    "Events": [
        {"Name": "fault", "Description": "Something went wrong.",
         "Event-params": [{"Name": "code", "Data-type": "std_msgs/Int32", "Description": "fault code"},
                          {"Name": "text", "Data-type": "std_msgs/String", "Description": "what"}]},
    ],
}, "arm.json")
DEFS = dict(load_definitions([SIM_DIR]), arm=ARM)


@pytest.fixture
def tree(tmp_path, bmtree_tree):
    """``tree(root_yaml, inputs_yaml="", **kwargs)`` -> a TreeTest of a one-file tree with the arm module."""
    return one_file_trees(tmp_path, bmtree_tree, DEFS)


def bad(tmp_path, root: str) -> List[str]:
    """The errors of a one-file tree of ``root`` (with the arm module), file name shortened to bad.yaml."""
    path = tmp_path / "bad.yaml"
    path.write_text("format: 1\nroot:\n" + root)
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), DEFS)
    return [str(e).replace(str(path), "bad.yaml") for e in info.value.errors]


# fail -----------------------------------------------------------------------------------------
FAULT = """
  sequence:
    - wait_event: arm.fault
      outputs: {code: code}
    - fail: "the arm has a problem (code {code})"
      name: give up
    - call: speech.say
      inputs: {text: never}
"""


def test_fail_is_failure_with_its_text_as_the_runs_reason(tree):
    t = tree(FAULT)
    t.mocks.event(2.0, "arm.fault", code=2, text="joint 3")
    run = t.run()
    assert run.failed
    assert run.reason == "give up: the arm has a problem (code 2)"
    assert run.statuses("give up") == ["FAILURE"] and run.calls() == []
    assert run.duration == pytest.approx(2.0)


def test_an_unnamed_fail_says_fail_and_its_text(tree):
    run = tree('  sequence: [{set: {n: 3}}, {fail: "{n * 2} tries is too many"}]\n').run()
    assert run.failed and run.reason == "fail: 6 tries is too many"
    run = tree("  fail: plain words\n").run()
    assert run.reason == "fail: plain words"


def test_fail_says_what_the_tree_means_where_check_false_cannot(tree):
    assert tree("  check: 'false'\n").run().reason == "check false: false is false"
    t = tree("  sequence: [{call: arm.grasp, inputs: {object: cup}, outputs: {code: c}}, {fail: 'code {c}'}]\n")
    t.mocks["arm.grasp"].succeed(success=True, code=4)
    assert t.run().reason == "fail: code 4"


def test_fail_of_a_reference_says_what_the_key_holds(tree):
    t = tree("""
  selector:
    - {call: arm.grasp, inputs: {object: cup}, status: st, error: why}
    - {fail: $why, name: could not grasp}
""")
    t.mocks["arm.grasp"].fail("the cup slipped")
    run = t.run()
    assert run.failed and run.reason == "could not grasp: the cup slipped"


def test_a_fail_recovered_from_is_not_the_reason(tree):
    t = tree("""
  sequence:
    - selector:
        - fail: first try
        - set: {ok: true}
    - {call: arm.grasp, inputs: {object: cup}, name: grasp}
""")
    t.mocks["arm.grasp"].fail("no cup")
    run = t.run()
    assert run.failed and run.reason == "grasp: arm.grasp failed: no cup", run.reason
    t.mocks["arm.grasp"].succeed(success=True)
    run = t.run()
    assert run.succeeded and run.blackboard["ok"] is True


def test_a_template_that_cannot_be_filled_is_still_the_failure_with_why(tree):
    run = tree('  fail: "at {at(rooms, 5)}"\n', inputs="  rooms: {default: [a]}\n").run()
    assert run.failed and run.reason.startswith("fail: 'at {at(rooms, 5)}' (its text could not be made: ")
    assert "at(): no position 5 in a list of 1" in run.reason


def test_fail_never_succeeds_for_the_data_flow(tmp_path):
    """A selector whose last choice is a fail guarantees what the other choice writes (the README's example)."""
    ok = """  sequence:
    - selector:
        - {call: arm.grasp, inputs: {object: cup}, outputs: {pose: cup_pose}, status: st, error: why}
        - fail: "the grasp {st}: {why}"
          name: give up
    - call: navigation.approach
      inputs: {target: $cup_pose.position}
"""
    path = tmp_path / "ok.yaml"
    path.write_text("format: 1\nroot:\n" + ok)
    load_tree(str(path), DEFS)
    errors = bad(tmp_path, ok.replace('fail: "the grasp {st}: {why}"', "set: {tried: true}"))
    assert errors == ["bad.yaml:9:24: reads 'cup_pose', which is not written on every path before this node "
                      "(written at line 5, but not before it on every path: write it earlier on every path or "
                      "declare it under 'inputs:')"]


def test_coverage_does_not_miss_a_success_that_fail_cannot_have(tree):
    t = tree(FAULT)
    cov = Coverage()
    cov.add_tree(t.tree)
    node = next(n for n in walk(t.tree.root) if n.kind == "fail")
    assert cov.possible(node) == ("FAILURE",)


def test_the_keys_of_fails_text_are_checked_at_their_column(tmp_path):
    assert bad(tmp_path, """  sequence:
    - call: arm.grasp
      inputs: {object: cup}
      outputs: {code: code, pose: pose}
    - fail: "code {cod}, at {pose.positon.x}"
""") == [
        "bad.yaml:7:20: reads 'cod', which no node writes and no input declares (did you mean 'code'?)",
        "bad.yaml:7:30: reads pose.positon, but pose holds a geometry_msgs/Pose, which has no field 'positon' "
        "(did you mean 'position'?)"]


@pytest.mark.parametrize("node, message", [
    ("fail: 3", "3:9: fail takes text (why the branch fails), got 3"),
    ("fail: ''", "3:10: fail takes text (why the branch fails), got nothing"),
    ("fail:", "3:8: fail takes text (why the branch fails), got nothing"),
    ("fail: {code}", "3:9: fail takes text (why the branch fails), got {'code': None}: YAML reads an unquoted "
                     "{code} as a mapping; quote it: fail: \"{code}\" (or $code)"),
    ("fail: 'code {'", "3:15: '{' without its '}' in text (write '{{' for a brace)"),
    ("fail: 'n {len(1) + }'", "3:22: in {len(1) + }: expected a value, found 'end of expression'"),
])
def test_a_fail_without_text_is_an_error(tmp_path, node, message):
    assert bad(tmp_path, "  " + node + "\n") == ["bad.yaml:" + message]


def test_fail_is_in_the_registry_schema_and_tables():
    assert REGISTRY["fail"].family == "leaf"
    assert REGISTRY["fail"].schema()["properties"]["fail"]["type"] == "string"
    schema = json_schema()
    text = repr(schema)
    assert "'fail'" in text and "FAILURE with that reason" in text
    with open(os.path.join(TREES, "README.md"), encoding="utf-8") as fh:
        readme = fh.read()
    assert "| `fail` |" in readme and "**fail**" in readme


# wait_event where: ------------------------------------------------------------------------------
SEEN = """
  wait_event: vision.personSeen
  where: 'person == "Ana" and position.x > 0'
  outputs: {person: who, position: at}
  timeout: 5
"""


def test_where_takes_the_first_event_that_satisfies_it_and_skips_the_others(tree):
    t = tree(SEEN)
    t.mocks.event(1.0, "vision.personSeen", person="Bob", position={"x": 1.0})
    t.mocks.event(2.0, "vision.personSeen", person="Ana", position={"x": -1.0})   # the wrong side
    t.mocks.event(3.0, "vision.personSeen", person="Ana", position={"x": 2.0})
    run = t.run()
    assert run.succeeded, run.reason
    assert run.blackboard["who"] == "Ana" and run.blackboard["at"]["x"] == 2.0
    assert run.duration == pytest.approx(3.0)


def test_a_timeout_says_how_many_events_were_skipped(tree):
    t = tree(SEEN)
    t.mocks.event(1.0, "vision.personSeen", person="Bob", position={"x": 1.0})
    t.mocks.event(2.0, "vision.personSeen", person="Eve", position={"x": 1.0})
    run = t.run()
    assert run.failed and run.duration == pytest.approx(5.0)
    assert run.reason == 'vision.personSeen: no vision.personSeen where person == "Ana" and position.x > 0 within ' \
                         '5s (2 skipped)'
    assert "who" not in run.blackboard


def test_where_keeps_the_events_that_came_together_for_a_loop(tree):
    """Bob, Ana, Bob and Eve seen at once: a loop over a wait_event that skips Bob takes Ana, then Eve
    (from the others of that moment, the second Bob skipped); Zoe, seen before the loop started, is not."""
    t = tree("""
  sequence:
    - wait: 1
    - repeat: 3
      child:
        wait_event: vision.personSeen
        where: 'person != "Bob"'
        outputs: {person: who}
        timeout: 5
      until: 'who == "Eve"'
""")
    t.mocks.event(0.5, "vision.personSeen", person="Zoe", position={"x": 1.0})   # before it started
    for who in ("Bob", "Ana", "Bob", "Eve"):
        t.mocks.event(2.0, "vision.personSeen", person=who, position={"x": 1.0})
    run = t.run()
    assert run.succeeded, run.reason
    assert run.blackboard["who"] == "Eve" and run.duration == pytest.approx(2.0)
    assert run.statuses("repeat until who == \"Eve\" (at most 3)")[-1] == "SUCCESS"


def test_events_of_that_moment_that_do_not_match_are_skipped_after_a_restart(tree):
    t = tree("""
  repeat: 2
  child:
    wait_event: vision.personSeen
    where: 'person != "Bob"'
    outputs: {person: who}
    timeout: 5
""")
    for who in ("Ana", "Bob", "Bob"):
        t.mocks.event(1.0, "vision.personSeen", person=who, position={"x": 1.0})
    t.mocks.event(3.0, "vision.personSeen", person="Eve", position={"x": 1.0})
    run = t.run()
    assert run.succeeded and run.blackboard["who"] == "Eve" and run.duration == pytest.approx(3.0)


def test_an_expression_that_cannot_be_worked_out_on_an_event_fails_the_leaf(tree):
    t = tree("""
  wait_event: vision.personSeen
  where: 'len(person) / (position.x - 1) > 1'
""")
    t.mocks.event(1.0, "vision.personSeen", person="Ana", position={"x": 1.0})
    run = t.run()
    assert run.failed and run.reason == "vision.personSeen: where len(person) / (position.x - 1) > 1: division by zero"


def test_where_reads_params_not_tree_keys(tree):
    """A tree key of the same name as a param does not change what the expression reads."""
    t = tree("""
  sequence:
    - set: {code: 7}
    - wait_event: arm.fault
      where: 'code == 2'
      outputs: {text: what}
""")
    t.mocks.event(1.0, "arm.fault", code=7, text="seven")
    t.mocks.event(2.0, "arm.fault", code=2, text="two")
    run = t.run()
    assert run.succeeded and run.blackboard == {"code": 7, "what": "two"}


@pytest.mark.parametrize("where, message", [
    ("'persn == \"Ana\"'", "5:11: where reads 'persn', which is no param of vision.personSeen (did you mean "
                           "'person'?)"),
    ("'who == \"Ana\"'", "5:11: reads 'who', which is not written on every path before this node (only this "
                         "node writes it: write it earlier on every path or declare it under 'inputs:')"),
    ("'person == \"Ana\" and $positon.x > 1'", "5:31: where reads 'positon', which is no param of "
                                              "vision.personSeen (did you mean 'position'?)"),
    ("'position.q > 1'", "5:11: reads position.q, but position holds a geometry_msgs/Point, which has no field "
                         "'q' (its fields: x, y, z)"),
    ("'person + 1 > 2'", "5:18: cannot add a string and a number"),
    ("'position.x == \"1\"'", "5:22: a number == a string is always false (write 1, not \"1\")"),
    ("'person == '", "5:21: bad expression in 'where': expected a value, found 'end of expression'"),
    ("3", "5:10: 'where' takes an expression string, e.g. 'answer == \"yes\"'"),
])
def test_where_is_checked_against_the_events_params(tmp_path, where, message):
    errors = bad(tmp_path, "  wait_event: vision.personSeen\n  outputs: {person: who}\n  where: %s\n" % where)
    assert errors == ["bad.yaml:" + message]


def test_bmtree_check_reports_a_misspelt_param_in_where(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
root:
  wait_event: navigation.arrived
  where: 'plase == "kitchen"'
""")
    assert status == 2
    assert lines == ["t.yaml:4:11: where reads 'plase', which is no param of navigation.arrived "
                     "(did you mean 'place'?)"]


def test_where_compares_a_param_with_a_tree_key(tree):
    """SMACH's MonitorState compares with userdata: a name that is no param of the event is a tree key,
    read when each event is looked at."""
    t = tree("""
  sequence:
    - set: {guest: Ana, far: 2}
    - wait_event: vision.personSeen
      where: 'person == guest and position.x > far'
      outputs: {position: where_seen}
      timeout: 10
""")
    t.mocks.event(1.0, "vision.personSeen", person="Bob", position={"x": 5.0, "y": 0.0, "z": 0.0})
    t.mocks.event(2.0, "vision.personSeen", person="Ana", position={"x": 1.0, "y": 0.0, "z": 0.0})
    t.mocks.event(3.0, "vision.personSeen", person="Ana", position={"x": 3.0, "y": 0.0, "z": 0.0})
    run = t.run()
    assert run.succeeded, run.reason
    assert run.blackboard["where_seen"]["x"] == 3.0 and run.duration == pytest.approx(3.0)


@pytest.mark.parametrize("where, message", [
    ("'person == guest'", "6:25: reads 'guest', which no node writes and no input declares (write it first, with "
                          "a call's 'outputs:' or a 'set', or declare it under 'inputs:')"),
    ("'position.x > who'", "6:26: cannot compare a number > a string"),
])
def test_a_tree_key_in_where_is_checked_as_any_read(tmp_path, where, message):
    errors = bad(tmp_path, "  sequence:\n    - set: {who: Ana}\n    - wait_event: vision.personSeen\n"
                           "      where: %s\n" % where)
    assert errors == ["bad.yaml:" + message], errors


def test_a_key_the_where_names_is_not_a_read_of_the_tree(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  wait_event: arm.fault\n  where: 'code > 1 and len(text) > 0'\n")
    load_tree(str(path), DEFS)   # no "reads 'code', which no node writes"


# for_each's max before running ------------------------------------------------------------------
ROOMS = ["r%d" % i for i in range(150)]


def rooms_yaml(n: int = 150) -> str:
    return "[%s]" % ", ".join(ROOMS[:n])


def write(tmp_path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


SUB = """format: 1
inputs:
  rooms: %s
root:
  for_each: $rooms
  as: room
  child: {call: navigation.go_to, inputs: {place: $room}}
"""


def test_a_literal_list_longer_than_max_is_an_error_with_the_max_it_needs(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  for_each: %s\n  as: room\n  child: {wait: 0}\n"
                          % rooms_yaml())
    assert status == 2
    assert lines == ["t.yaml:3:13: for_each over 150 elements, more than max 100 (raise 'max'): write max: 150, "
                     "or give a shorter list"]
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  for_each: %s\n  max: 150\n  as: room\n"
                          "  child: {wait: 0}\n" % rooms_yaml())
    assert status == 0, lines


def test_an_include_argument_longer_than_max_is_an_error_at_the_loop(tmp_path, capsys):
    write(tmp_path, "sub.yaml", SUB % "{}")
    main = write(tmp_path, "main.yaml", "format: 1\nroot:\n  sequence:\n    - include: sub.yaml\n"
                                        "      args: {rooms: %s}\n" % rooms_yaml())
    assert bmtree(["check", main]) == 2
    err = capsys.readouterr().err.replace(str(tmp_path) + "/", "")
    assert err.splitlines() == [
        "sub.yaml:5:13: for_each $rooms has 150 elements (argument 'rooms' of the include at main.yaml:4), more "
        "than max 100: raise max: to 150, or pass a shorter list there"]
    write(tmp_path, "main.yaml", "format: 1\nroot:\n  include: sub.yaml\n  args: {rooms: %s}\n" % rooms_yaml(100))
    assert bmtree(["check", main]) == 0


def test_a_subtrees_default_the_include_leaves_is_an_error_too(tmp_path, capsys):
    write(tmp_path, "sub.yaml", SUB % ("{default: %s}" % rooms_yaml()))
    main = write(tmp_path, "main.yaml", "format: 1\nroot:\n  include: sub.yaml\n")
    assert bmtree(["check", main]) == 2
    err = capsys.readouterr().err.replace(str(tmp_path) + "/", "")
    assert err.splitlines() == [
        "sub.yaml:5:13: for_each $rooms has 150 elements (the default of input 'rooms'; the include at "
        "main.yaml:3 passes no argument), more than max 100: raise max: to 150, or give the input a shorter "
        "default, or pass a shorter list"]


def test_the_trees_own_default_is_a_warning_and_the_run_fails_at_the_first_tick(tmp_path, capsys, bmtree_tree):
    path = write(tmp_path, "sub.yaml", SUB % ("{default: %s}" % rooms_yaml()))
    assert bmtree(["check", path]) == 0
    err = capsys.readouterr().err.replace(str(tmp_path) + "/", "")
    assert err.splitlines()[0] == (
        "sub.yaml:5:13: warning: for_each $rooms has 150 elements (the default of input 'rooms'), more than max "
        "100: a run that does not set the input fails here; raise max: to 150, or give it a shorter default")
    assert bmtree(["check", "--strict", path]) == 2
    capsys.readouterr()
    run = bmtree_tree(path, definitions=DEFS).run()
    assert run.failed and "the list has 150 elements, more than max 100" in run.reason
    assert run.calls() == []
    t = bmtree_tree(path, definitions=DEFS, inputs={"rooms": ["kitchen"]})   # a caller's shorter list
    assert t.tree.warnings == []
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    assert t.run().succeeded


def test_a_max_that_fits_or_is_not_known_is_no_error(tmp_path, capsys):
    write(tmp_path, "sub.yaml", (SUB % "{}\n  most: {}").replace("  as: room", "  as: room\n  max: $most"))
    main = write(tmp_path, "main.yaml", "format: 1\nroot:\n  include: sub.yaml\n  args: {rooms: %s, most: 200}\n"
                 % rooms_yaml())
    assert bmtree(["check", main]) == 0, capsys.readouterr().err   # a max from an input: checked when it runs
    write(tmp_path, "sub.yaml", (SUB % "{}").replace("  as: room", "  as: room\n  max: 150"))
    main = write(tmp_path, "main.yaml", "format: 1\nroot:\n  include: sub.yaml\n  args: {rooms: %s}\n"
                 % rooms_yaml())
    assert bmtree(["check", main]) == 0, capsys.readouterr().err


def test_an_input_that_is_no_list_is_said_as_before(tmp_path, capsys):
    write(tmp_path, "sub.yaml", SUB % "{default: kitchen}")
    main = write(tmp_path, "main.yaml", "format: 1\nroot:\n  include: sub.yaml\n")
    assert bmtree(["check", main]) == 2
    err = capsys.readouterr().err.replace(str(tmp_path) + "/", "")
    assert err.splitlines() == [
        "sub.yaml:5:13: for_each $rooms is 'kitchen' (the default of input 'rooms'; the include at main.yaml:3 "
        "passes no argument), not a list: give the input a default that is one, or pass one"]


def test_the_replay_of_a_run_names_the_fail_as_the_live_reason_did(sim_defs, tmp_path, capsys):
    """reasons.py's rule (a leaf is an origin of failure) is one for the live reason and the replay."""
    path = write(tmp_path, "t.yaml", """format: 1
inputs:
  room: {default: kitchen}
root:
  sequence:
    - selector:
        - fail: first try
        - {call: navigation.go_to, inputs: {place: $room}}
    - {fail: "no apple in the {room}", name: give up}
""")
    log, run = recorded(path, sim_defs, tmp_path, lambda m: m["navigation.go_to"].succeed(room="kitchen"))
    assert run.failed and run.reason == "give up: no apple in the kitchen"
    assert cmd_replay(_args(run=log, failure=True)) == 0
    out = capsys.readouterr().out
    assert "the failure that ended the run" in out and "'give up' (" in out and "no apple in the kitchen" in out, out
    assert "first try (recovered: " in out, out
    assert cmd_replay(_args(run=log)) == 0
    assert "reason: give up: no apple in the kitchen" in capsys.readouterr().out
