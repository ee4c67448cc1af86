"""Ported SMACH idioms: a ``parallel`` that ``succeed_on`` named children (a Concurrence's outcome map,
"done when the follower arrives"), an ``include``'s ``outputs`` copied to the caller's keys, and a
coverage report that does not ask for an outcome a node can never reach (a ``force_failure``'s
SUCCESS). Run through the mocks on the simulated clock."""
from __future__ import annotations

import os

import pytest

from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from coordinator.schema import json_schema
from coordinator.testing import Coverage, TreeTest, fail, succeed
from tests.conftest import TREES
from tests.unit import test_call_status
from tests.unit.test_call_status import DEFS, said
from tests.unit.test_check_messages import check

tree = test_call_status.tree   # its fixture: ``tree(root_yaml)``, a one-file tree with the sim and arm modules

# SMACH: Concurrence(outcome_map={"arrived": {"FOLLOW": "succeeded"}}): the chat goes on until the
# follower arrives, and is halted then
FOLLOW = """
  sequence:
    - parallel:
        - name: follow
          call: arm.follow
          inputs: {person: Ana}
          timeout: none
          outputs: {success: arrived}
        - name: chat
          call: speech.listen
          inputs: {seconds: 60}
          timeout: none
          outputs: {text: heard}
      succeed_on: [follow]
    - call: speech.say
      inputs: {text: "we are there ({arrived})"}
"""


def write(tmp_path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


# parallel succeed_on ------------------------------------------------------------------------------
def test_succeed_on_ends_when_the_named_child_succeeds_halting_the_others(tree):
    t = tree(FOLLOW)
    t.mocks["arm.follow"].succeed(delay=20, success=True)
    t.mocks["speech.listen"].hang()
    run = t.run()
    assert run.succeeded, run.reason
    assert run.duration == pytest.approx(20.0)
    assert [c.status for c in run.calls("speech.listen")] == ["halted"]
    assert said(run) == ["we are there (true)"]
    assert run.statuses("follow")[-1] == "SUCCESS" and "SUCCESS" not in run.statuses("chat")


def test_succeed_on_does_not_end_when_another_child_succeeds_first(tree):
    t = tree(FOLLOW)
    t.mocks["arm.follow"].succeed(delay=20, success=True)
    t.mocks["speech.listen"].succeed(delay=5, text="wait for me")
    run = t.run()
    assert run.succeeded, run.reason
    assert run.duration == pytest.approx(20.0)   # not at 5 s, as policy: one would
    assert len(run.calls("speech.listen")) == 1   # synchronise: a child that succeeded is not run again
    assert run.blackboard["heard"] == "wait for me"


def test_succeed_on_still_fails_when_any_child_fails(tree):
    t = tree(FOLLOW)
    t.mocks["arm.follow"].succeed(delay=20, success=True)
    t.mocks["speech.listen"].fail("microphone unplugged", delay=5)
    run = t.run()
    assert run.failed and "microphone unplugged" in run.reason
    assert run.duration == pytest.approx(5.0)
    assert [c.status for c in run.calls("arm.follow")] == ["halted"]


def test_succeed_on_guarantees_what_the_named_children_write(tmp_path):
    text = "format: 1\nroot:\n" + FOLLOW.replace("({arrived})", "({arrived}, {heard})")
    with pytest.raises(TreeErrors) as info:
        load_tree(write(tmp_path, "t.yaml", text), DEFS)
    assert [e.message for e in info.value.errors] == [
        "reads 'heard', which is not written on every path before this node (written at line 12, but not before "
        "it on every path: write it earlier on every path or declare it under 'inputs:')"]
    load_tree(write(tmp_path, "ok.yaml", "format: 1\nroot:\n" + FOLLOW), DEFS)   # {arrived}: fine


PAR = """format: 1
root:
  parallel:
    - {name: follow, call: navigation.go_to, inputs: {place: kitchen}}
    - {name: chat, call: speech.say, inputs: {text: "follow me"}}
%s
"""


@pytest.mark.parametrize("option, line", [
    ("  succeed_on: [folow]",
     "t.yaml:6:16: succeed_on: no child of this parallel is named 'folow' (did you mean 'follow'?)"),
    ("  succeed_on: [chat, arrive]",
     "t.yaml:6:22: succeed_on: no child of this parallel is named 'arrive' (children are picked by their "
     "'name:'; named here: 'chat', 'follow')"),
    ("  succeed_on: [chat, chat]", "t.yaml:6:22: succeed_on names 'chat' twice: list it once"),
    ("  succeed_on: chat", "t.yaml:6:15: succeed_on takes a non-empty list of the names of children (their "
                           "'name:'), e.g. succeed_on: [follow]; got 'chat'"),
    ("  succeed_on: [chat]\n  policy: one", "t.yaml:6:3: parallel takes 'succeed_on' or 'policy', not both: "
                                            "succeed_on (these children succeed) replaces policy (all or one)"),
])
def test_succeed_on_errors_say_where_and_how(tmp_path, capsys, option, line):
    status, lines = check(tmp_path, capsys, PAR % option)
    assert status == 2 and lines == [line]


def test_succeed_on_needs_children_with_names(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
root:
  parallel:
    children:
      - {call: navigation.go_to, inputs: {place: kitchen}}
      - {name: talk, call: speech.say, inputs: {text: "follow me"}}
      - {name: talk, call: speech.say, inputs: {text: "this way"}}
    succeed_on: [go, talk]
""")
    assert status == 2
    assert lines == [
        "t.yaml:8:18: succeed_on: no child of this parallel is named 'go' (children are picked by their 'name:'; "
        "named here: 'talk')",
        "t.yaml:8:22: succeed_on: 2 children of this parallel are named 'talk' (line 6, line 7): give the one to "
        "wait for a name of its own"]
    status, lines = check(tmp_path, capsys, PAR.replace("name: follow, ", "").replace("name: chat, ", "")
                          % "  succeed_on: [follow]")
    assert lines == ["t.yaml:6:16: succeed_on: no child of this parallel is named 'follow' (no child has a name: "
                     "succeed_on picks children by their 'name:'; give the one to wait for name: follow)"]


def test_succeed_on_is_in_the_schema():
    props = json_schema()["definitions"]["kind_parallel"]["properties"]
    assert props["succeed_on"]["type"] == "array" and props["succeed_on"]["items"]["type"] == "string"
    inline = props["parallel"]["anyOf"][1]["properties"]
    assert "succeed_on" in inline


# include outputs ----------------------------------------------------------------------------------
ASK = """format: 1
inputs:
  question: {}
root:
  sequence:
    - call: speech.say
      inputs: {text: "{question}"}
    - call: speech.listen
      inputs: {seconds: 5}
      outputs: {text: answer}
"""


def test_include_outputs_copy_the_subtrees_keys_to_the_callers(tmp_path, bmtree_tree):
    write(tmp_path, "ask.yaml", ASK)
    main = write(tmp_path, "main.yaml", """format: 1
root:
  sequence:
    - include: ask.yaml
      args: {question: "Coffee?"}
      outputs: {answer: coffee}
    - include: ask.yaml
      args: {question: "Tea?"}
      outputs: {answer: tea}
    - call: speech.say
      inputs: {text: "coffee: {coffee}, tea: {tea}"}
""")
    t = bmtree_tree(main, definitions=DEFS)
    t.mocks["speech.listen"].script(succeed(text="yes"), succeed(text="no"))
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run)[-1] == "coffee: yes, tea: no"
    assert run.blackboard["coffee"] == "yes" and run.blackboard["tea"] == "no"
    assert run.blackboard["answer"] == "no"   # the subtree's own key is still on the shared blackboard


def test_include_outputs_are_copied_only_when_the_subtree_succeeds(tmp_path, bmtree_tree):
    write(tmp_path, "ask.yaml", ASK)
    main = write(tmp_path, "main.yaml", """format: 1
root:
  force_success:
    include: ask.yaml
    args: {question: "Coffee?"}
    outputs: {answer: coffee}
""")
    t = bmtree_tree(main, definitions=DEFS)
    t.mocks["speech.listen"].fail("nobody answered")
    run = t.run()
    assert run.succeeded and "coffee" not in run.blackboard


def test_include_outputs_must_be_surely_written_by_the_subtree(tmp_path, capsys):
    write(tmp_path, "ask.yaml", ASK.replace("""    - call: speech.listen""", """    - selector:
        - {call: vision.find_person, inputs: {name: ""}, outputs: {person: who}}
        - {set: {nobody: true}}
    - call: speech.listen"""))
    status, lines = check(tmp_path, capsys, """format: 1
root:
  include: ask.yaml
  args: {question: "Coffee?"}
  outputs: {answr: coffee, who: guest, room: where}
""")
    at = str(tmp_path / "ask.yaml")
    assert status == 2
    assert lines == [
        "t.yaml:5:13: outputs: ask.yaml does not write 'answr' (did you mean 'answer'?)",
        "t.yaml:5:28: outputs: ask.yaml writes 'who' (%s:9), but not on every path by which it succeeds: write "
        "it on every path (it surely writes answer)" % at,
        "t.yaml:5:40: outputs: ask.yaml does not write 'room' (it surely writes answer)"]


def test_include_outputs_type_the_callers_key_like_the_subtrees(tmp_path, capsys):
    write(tmp_path, "ask.yaml", ASK)
    status, lines = check(tmp_path, capsys, """format: 1
root:
  sequence:
    - include: ask.yaml
      args: {question: "Where to?"}
      outputs: {answer: goal}
    - call: navigation.approach
      inputs: {target: $goal}
""")
    assert status == 2
    assert lines == [
        "t.yaml:8:24: input 'target' takes a mapping of fields x, y, z (geometry_msgs/Point), got $goal, which "
        "holds text (std_msgs/String)"]


@pytest.mark.parametrize("outputs, line", [
    ("{answer: goal, question: goal}", "t.yaml:5:37: outputs 'answer' and 'question' both write tree key 'goal': "
                                       "one value would replace the other; give 'question' its own key"),
    ("[answer]", "t.yaml:5:12: 'outputs' must be a mapping of subtree key: caller key, e.g. outputs: {answer: "
                 "guest_answer}"),
    ("{answer: 3}", "t.yaml:5:21: caller key 3 is not a tree key (an identifier)"),
])
def test_include_outputs_shape_errors(tmp_path, capsys, outputs, line):
    write(tmp_path, "ask.yaml", ASK)
    status, lines = check(tmp_path, capsys, """format: 1
root:
  include: ask.yaml
  args: {question: "Coffee?"}
  outputs: %s
""" % outputs)
    assert status == 2 and lines == [line]


def test_a_caller_key_read_before_the_include_is_not_written_yet(tmp_path, capsys):
    write(tmp_path, "ask.yaml", ASK)
    status, lines = check(tmp_path, capsys, """format: 1
root:
  sequence:
    - call: speech.say
      inputs: {text: "{coffee}"}
    - include: ask.yaml
      args: {question: "Coffee?"}
      outputs: {answer: coffee}
""")
    assert status == 2 and lines == [
        "t.yaml:5:24: reads 'coffee', which is not written on every path before this node (written at line 6, but "
        "not before it on every path: write it earlier on every path or declare it under 'inputs:')"]


# coverage: only the outcomes a node can reach ----------------------------------------------------
COVERED = """format: 1
root:
  sequence:
    - force_success:
        call: navigation.go_to
        inputs: {place: kitchen}
    - selector:
        - call: vision.find_object
          inputs: {object: apple}
        - force_failure:
            call: speech.say
            inputs: {text: "I cannot find it"}
"""


def coverage_lines(tmp_path, text: str, script=None):
    path = write(tmp_path, "t.yaml", text)
    cov = Coverage()
    t = TreeTest(path, definitions=DEFS, coverage=cov)
    for target, outcome in (script or {}).items():
        t.mocks[target].script(outcome)
    t.run()
    return {line.split(": ", 1)[1]: line for line in cov.report().splitlines()[2:]}


def test_coverage_does_not_ask_for_an_outcome_a_node_cannot_reach(tmp_path):
    lines = coverage_lines(tmp_path, COVERED, {"vision.find_object": fail("no apple")})
    assert set(lines) == {
        "sequence 'sequence' reached FAILURE; never SUCCESS",
        "force_success 'force_success' reached SUCCESS",              # it never fails: nothing missing
        "call 'navigation.go_to' reached SUCCESS; never FAILURE",   # its child can fail
        "selector 'selector' reached FAILURE; never SUCCESS",
        "call 'vision.find_object' reached FAILURE; never SUCCESS",
        "force_failure 'force_failure' reached FAILURE",              # it never succeeds
        "call 'speech.say' reached SUCCESS; never FAILURE",
    }, lines


def test_coverage_of_branches_that_surely_fail(tmp_path):
    lines = coverage_lines(tmp_path, """format: 1
root:
  selector:
    - sequence:
        - call: speech.say
          inputs: {text: "trying"}
        - force_failure: {wait: 1}
    - inverter:
        force_success: {wait: 1}
""")
    assert set(lines) == {
        "selector 'selector' reached FAILURE",    # neither child can succeed
        "sequence 'sequence' reached FAILURE",    # a child that never succeeds
        "call 'speech.say' reached SUCCESS; never FAILURE",
        "force_failure 'force_failure' reached FAILURE",
        "wait 'wait 1s' reached SUCCESS; never FAILURE",
        "inverter 'inverter' reached FAILURE",    # of a node that never fails
        "force_success 'force_success' reached SUCCESS",
    }, lines


def test_coverage_of_a_fail_leaf_and_an_include_that_never_succeeds(tmp_path):
    write(tmp_path, "give_up.yaml", "format: 1\nroot:\n  fail: \"the arm has a problem\"\n")
    lines = coverage_lines(tmp_path, """format: 1
root:
  selector:
    - include: give_up.yaml
    - call: speech.say
      inputs: {text: "fallback"}
""")
    assert "fail 'fail' reached FAILURE" in lines, lines
    assert "include 'give_up' reached FAILURE" in lines, lines
    assert "selector 'selector' reached SUCCESS; never FAILURE" in lines, lines


# the language reference's examples -------------------------------------------------------------
def readme_example(after: str) -> str:
    """The first yaml block of trees/README.md after the text ``after``, as the root sequence's children."""
    with open(os.path.join(TREES, "README.md"), encoding="utf-8") as fh:
        text = fh.read()
    block = text.split(after, 1)[1].split("```yaml\n", 1)[1].split("```", 1)[0]
    return "format: 1\nroot:\n  sequence:\n" + "".join("    " + line + "\n" for line in block.splitlines())


def test_the_readme_examples_check_and_run(tmp_path, bmtree_tree):
    t = bmtree_tree(write(tmp_path, "lead.yaml", readme_example("## Waiting for some children")), definitions=DEFS)
    t.mocks["navigation.go_to"].succeed(delay=30, room="dining room")
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run)[-1] == "Here we are, in the dining room." and run.duration == pytest.approx(30.0)
    write(tmp_path, "ask.yaml", ASK)
    t = bmtree_tree(write(tmp_path, "main.yaml", readme_example("`outputs: {subtree_key: caller_key}`")),
                    definitions=DEFS)
    t.mocks["speech.listen"].script(succeed(text="yes"), succeed(text="no"))
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run)[-1] == "Coffee: yes, tea: no."


def test_a_set_of_literals_never_fails_and_one_that_works_something_out_may(tmp_path):
    """SMACH's "try, then say why": the selector's next child reads what the first child's ``set`` wrote
    before its call failed. A ``set`` of literals cannot fail: the key is there on every path (it was
    refused, 'not written on every path'), and coverage does not ask for its FAILURE."""
    tree = """format: 1
root:
  selector:
    - sequence:
        - set: {a: "x"%s}
        - call: vision.find_object
          inputs: {object: apple}
    - call: speech.say
      inputs: {text: "{a}"}
"""
    lines = coverage_lines(tmp_path, tree % "", {"vision.find_object": fail("no apple")})
    assert "set 'set a' reached SUCCESS" in lines, lines
    path = write(tmp_path, "t2.yaml", tree % ', b: "$(len(a))"')   # reads a key: it may fail, as before
    with pytest.raises(TreeErrors) as e:
        TreeTest(path, definitions=DEFS)
    assert "t2.yaml:9:24: reads 'a', which is not written on every path before this node" in str(e.value), str(e.value)
