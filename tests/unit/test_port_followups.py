"""Follow-ups of the SMACH port audit: no clash warning for a key only other subtrees write (two
subtrees that both write ``answer``, each copied by ``outputs``), one error for ``in_order`` given a
single call, a scenario event's params (every one, as ``t.mocks.event`` wants), a ``succeed_on``
parallel whose named child succeeds in the tick another fails, and ``timeout: none`` of
``wait_event`` (accepted) and ``recall`` (an error saying it always has a limit)."""
from __future__ import annotations

import os

import pytest

from coordinator.cli import main as bmtree
from coordinator.schema import json_schema
from coordinator.testing.mocks import MockError
from tests.conftest import ROOT
from tests.unit import test_call_status
from tests.unit.test_call_status import errors_of, said
from tests.unit.test_check_messages import check
from tests.unit.test_flow_paths import warned
from tests.unit.test_lang_parallel_include import write
from tests.unit.test_scenario_expect_more import DOC, FIND_APPLE, _at, _errors

tree = test_call_status.tree   # its fixture: ``tree(root_yaml)``, a one-file tree with the sim and arm modules


# 1. a key only other subtrees write is not the caller's -------------------------------------------------
LISTEN = "format: 1\nroot: {call: speech.listen, inputs: {seconds: 1}, outputs: {text: answer}}\n"
NAME_THEN_DRINK = """format: 1
root:
  sequence:
    - include: ask_name.yaml
      outputs: {answer: name}
    - include: ask_drink.yaml
      outputs: {answer: drink}
    - call: speech.say
      inputs: {text: "{name} likes {drink}"}
%s"""


def _two_askers(tmp_path) -> None:
    write(tmp_path, "ask_name.yaml", LISTEN)
    write(tmp_path, "ask_drink.yaml", LISTEN)


def test_two_subtrees_writing_the_same_key_do_not_clash_in_the_caller(tmp_path, capsys):
    _two_askers(tmp_path)
    status, lines = check(tmp_path, capsys, NAME_THEN_DRINK % "")
    assert (status, lines) == (0, [])
    assert bmtree(["check", "--strict", str(tmp_path / "t.yaml")]) == 0
    assert warned(tmp_path, "t.yaml") == []


def test_a_key_the_caller_writes_only_after_the_include_is_not_replaced_by_it(tmp_path):
    _two_askers(tmp_path)
    write(tmp_path, "t.yaml", NAME_THEN_DRINK % "    - set: {answer: done}\n")
    assert warned(tmp_path, "t.yaml") == []


def test_two_subtrees_taking_an_input_of_one_name_do_not_clash_in_the_caller(tmp_path):
    """Each include passes its own ``question``: the first one's argument is not the caller's key."""
    asker = "format: 1\ninputs: {question: {}}\nroot: {call: speech.say, inputs: {text: $question}}\n"
    write(tmp_path, "ask1.yaml", asker)
    write(tmp_path, "ask2.yaml", asker)
    write(tmp_path, "t.yaml", "format: 1\nroot:\n  sequence:\n"
                              "    - include: ask1.yaml\n      args: {question: Name?}\n"
                              "    - include: ask2.yaml\n      args: {question: Drink?}\n")
    assert warned(tmp_path, "t.yaml") == []


def test_the_callers_own_key_written_before_is_still_a_clash(tmp_path):
    _two_askers(tmp_path)
    write(tmp_path, "t.yaml", (NAME_THEN_DRINK % "").replace("name}", "answer}"))
    assert warned(tmp_path, "t.yaml") == [
        "t.yaml:6:7: warning: ask_drink.yaml writes 'answer' (ask_drink.yaml:2), replacing the caller's 'answer' "
        "(written at line 4): rename one of them"]


def test_a_key_of_a_file_further_up_is_still_a_clash_in_a_nested_include(tmp_path):
    _two_askers(tmp_path)
    write(tmp_path, "mid.yaml", "format: 1\nroot: {include: ask_drink.yaml, outputs: {answer: drink}}\n")
    write(tmp_path, "top.yaml", """format: 1
root:
  sequence:
    - {call: speech.listen, inputs: {seconds: 1}, outputs: {text: answer}}
    - include: mid.yaml
""")
    assert warned(tmp_path, "top.yaml") == [
        "mid.yaml:2:8: warning: ask_drink.yaml writes 'answer' (ask_drink.yaml:2), replacing the caller's 'answer' "
        "(written at top.yaml:4): rename one of them"]
    write(tmp_path, "top.yaml", """format: 1
root:
  sequence:
    - {include: ask_name.yaml, outputs: {answer: name}}
    - include: mid.yaml
""")
    assert warned(tmp_path, "top.yaml") == []


# 2. in_order given one call, not a list --------------------------------------------------------------------
def test_in_order_given_one_call_is_one_error_saying_to_make_it_a_list(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n" % FIND_APPLE
                 + "  - expect: {calls: {in_order: speech.say}}\n"                       # 3
                 + "  - expect: {calls: {in_order: {speech.say: {text: hi}}}}\n")         # 4
    call = "module.function or {module.function: {input: value}}"
    assert _errors(str(f), capsys) == [
        _at(f, 3, 32, "calls in_order is a list of the calls made in this order (%s), at least one; got "
                      "'speech.say': write one call as a list of one, in_order: [speech.say]" % call),
        _at(f, 4, 32, "calls in_order is a list of the calls made in this order (%s), at least one; got "
                      "{'speech.say': {'text': 'hi'}}: write one call as a list of one, in_order: "
                      "[{speech.say: {text: hi}}]" % call)]


# 3. a scenario event gives every param, as t.mocks.event must ---------------------------------------------
def test_a_scenario_event_missing_a_param_says_the_rule(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n" % FIND_APPLE
                 + "  - events: [{event: vision.personSeen, at: 1, params: {person: Ana}}]\n")   # 3
    assert _errors(str(f), capsys) == [
        _at(f, 3, 14, "vision event personSeen: missing event param 'position': an event gives every param its "
                      "definition lists (person, position), as a module's emit and t.mocks.event must; unlike a "
                      "mock's outputs, params get no defaults")]


def test_the_kit_wants_every_param_of_an_event_too(bmtree_tree):
    t = bmtree_tree(FIND_APPLE)
    with pytest.raises(MockError, match="missing event param 'position'"):
        t.mocks.event(1.0, "vision.personSeen", person="Ana")
    t.mocks.event(1.0, "vision.personSeen", person="Ana", position={"x": 1.0})   # a message's fields may be left out


def test_the_format_page_says_an_event_gives_every_param():
    with open(DOC, encoding="utf-8") as fh:
        doc = fh.read()
    assert "An event gives every parameter its definition lists: unlike a mock's `succeed` outputs, a\nmissing " \
           "parameter gets no default." in doc
    assert "`t.mocks.event(...)` require too" in doc


# 4. succeed_on: the named child succeeds in the tick another fails ----------------------------------------
LEAD = "{name: a, call: speech.listen, inputs: {seconds: 1}, outputs: {text: heard}}"
GIVE_UP = "{name: b, sequence: [{wait: 1}, {fail: b gave up}]}"


@pytest.mark.parametrize("children", [[LEAD, GIVE_UP], [GIVE_UP, LEAD]], ids=["named first", "named last"])
def test_succeed_on_fails_when_another_child_fails_in_the_tick_the_named_one_succeeds(tree, children):
    t = tree("  parallel:\n    succeed_on: [a]\n    children:\n%s" % "".join("      - %s\n" % c for c in children))
    t.mocks["speech.listen"].succeed(delay=1, text="hi")
    run = t.run()
    assert run.failed and run.reason.endswith("b gave up") and run.duration == pytest.approx(1.0)
    assert run.blackboard["heard"] == "hi"   # the named child's outputs are written all the same
    t = tree("  parallel:\n    succeed_on: [a]\n    children:\n%s" % "".join("      - %s\n" % c for c in children))
    t.mocks["speech.listen"].succeed(delay=0.999, text="hi")
    run = t.run()
    assert run.succeeded, run.reason   # a tick earlier: b is halted before it fails
    assert run.statuses("b")[-1] != "FAILURE"


def test_the_readme_says_what_a_failure_in_the_same_tick_does():
    with open(os.path.join(ROOT, "trees", "README.md"), encoding="utf-8") as fh:
        text = fh.read()
    section = text[text.index("## Waiting for some children"):text.index("## Subtrees")]
    assert "When a named child succeeds and another child fails in the same tick" in section
    assert "the parallel fails, with the failing child's reason" in section


# 5. timeout: none of wait_event and recall ----------------------------------------------------------------
def test_wait_event_takes_timeout_none_as_no_limit(tree):
    t = tree("  sequence:\n"
             "    - wait_event: navigation.arrived\n      timeout: none\n      outputs: {place: where}\n"
             "    - {call: speech.say, inputs: {text: 'in the {where}'}}\n")
    assert t.tree.root.children[0].spec.timeout is None   # as when left out
    t.mocks.event(500.0, "navigation.arrived", place="kitchen")
    run = t.run()
    assert run.succeeded, run.reason
    assert run.duration == pytest.approx(500.0) and said(run) == ["in the kitchen"]
    timeout = json_schema()["definitions"]["kind_wait_event"]["properties"]["timeout"]
    assert {"const": "none"} in timeout["anyOf"]


@pytest.mark.parametrize("written, message", [
    ("None", "timeout of wait_event must be a positive number of seconds or 'none', got 'None': wait_event waits "
             "without a time limit by default: leave timeout out, or write 'timeout: none', for no limit; else give "
             "seconds (> 0)"),
    ("0", "timeout of wait_event must be a positive number of seconds, got 0: wait_event waits without a time limit "
          "by default: leave timeout out, or write 'timeout: none', for no limit; else give seconds (> 0)"),
    ("null", "timeout of wait_event is null (written null, ~ or left empty), which is not read as no limit: "
             "wait_event waits without a time limit by default: leave timeout out, or write 'timeout: none', for no "
             "limit; else give seconds (> 0)"),
])
def test_other_spellings_of_no_timeout_of_wait_event_say_how(tmp_path, written, message):
    assert errors_of(tmp_path, "  wait_event: navigation.arrived\n  timeout: %s\n" % written) == [
        "bad.yaml:4:12: " + message]


@pytest.mark.parametrize("written, got", [("none", "got 'none'"), ("-2", "got -2")])
def test_recall_timeout_none_says_a_recall_always_has_a_limit(tmp_path, written, got):
    assert errors_of(tmp_path, "  recall: {x: text}\n  timeout: %s\n" % written) == [
        "bad.yaml:4:12: timeout of recall must be a positive number of seconds, %s: a recall always has a time "
        "limit (by default 5 s): give seconds (> 0), or leave it out for 5 s" % got]

