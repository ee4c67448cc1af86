"""Hints for tasks ported from SMACH, BehaviorTree.CPP and py_trees: true/false compared with text, the
switch's matching rule and its cases that can never match, other tools' kind names, every kind's options
in an unknown-option error, a list given as a decorator's child, and a decorator written as a mapping."""
from __future__ import annotations

import json
import re

import pytest

from coordinator.cli import main as bmtree
from coordinator.language import _ALLOWED
from coordinator.nodes import REGISTRY
from coordinator.nodes.switch import matches
from coordinator.othernames import OTHER_KINDS, OTHER_OPTIONS
from tests.unit.test_check_messages import check
from tests.unit.test_hints_audit import COUNTER


def check_counted(tmp_path, capsys, text: str):
    """``check`` of a tree with the counter module (``counter.count`` writes a ``std_msgs/Int32``) too."""
    defs = tmp_path / "counter.json"
    defs.write_text(json.dumps(COUNTER))
    path = tmp_path / "t.yaml"
    path.write_text(text)
    status = bmtree(["check", "--modules", str(defs), str(path)])
    return status, [line.replace(str(path), "t.yaml") for line in capsys.readouterr().err.splitlines()]


# speech.listen's 'success' is a std_msgs/Bool, its 'text' a std_msgs/String; counter.count's 'count' an Int32
HEARD = ("format: 1\nroot:\n  sequence:\n    - call: speech.listen\n      inputs: {seconds: 3}\n"
         "      outputs: {success: heard, text: answer}\n    - call: counter.count\n      outputs: {count: count}\n")


# 1. true/false compared with text ------------------------------------------------------------------------
@pytest.mark.parametrize("expr,col,said", [
    ('heard == "true"', 21, "a bool == a string is always false (write heard, or heard == true, unquoted)"),
    ('heard != "true"', 21, "a bool != a string is always true (write not heard, or heard != true, unquoted)"),
    ('heard == "false"', 21, "a bool == a string is always false (write not heard, or heard == false, unquoted)"),
    ('"True" == heard', 22, "a string == a bool is always false (write heard, or heard == true, unquoted)"),
    ('heard == "open"', 21, "a bool == a string is always false (a true/false value is not text: write heard or "
                            "not heard, or compare it with true or false, unquoted)"),
    ('(count > 2) == "true"', 27, "a bool == a string is always false (compare with true, unquoted)"),
    ("heard == answer", 21, "a bool == a string is always false"),
    ("heard == true", 0, ""),
    ("str(heard) == \"true\"", 0, ""),
])
def test_true_or_false_compared_with_text_is_an_error_with_the_fix(tmp_path, capsys, expr, col, said):
    status, lines = check_counted(tmp_path, capsys, HEARD + "    - check: '%s'\n" % expr)
    if not said:
        assert status == 0, lines
        return
    assert lines == ["t.yaml:9:%d: %s" % (col, said)]


# 2. switch: one rule, and the cases that can never match ------------------------------------------------
@pytest.mark.parametrize("value,label,matched", [
    (True, "true", True),       # a value of another kind: by its text, as str(value) == "case"
    (False, "false", True),
    (True, True, True),         # of the case's kind: equal
    (3, "3", True),
    ("3", 3, True),
    (3.0, 3, True),
    (3.0, "3.0", False),        # 3.0 is written 3
    (True, 1, False),           # true/false is no number
    (False, 0, False),
    ("yes", True, False),       # an unquoted yes: (true) is not the text "yes"
])
def test_switch_matches_a_case_of_its_kind_by_value_and_of_another_by_its_text(value, label, matched):
    assert matches(value, label, "equals") is matched


def switch_on(key: str, cases: str, more: str = "") -> str:
    return HEARD + "    - switch: $%s\n%s      cases:\n%s" % (key, more, "".join(
        "        %s\n" % c for c in cases.split("; ")))


def test_the_cases_a_number_can_never_match_are_errors_naming_the_type_and_the_case(tmp_path, capsys):
    status, lines = check_counted(tmp_path, capsys, switch_on(
        "count", 'ok: {wait: 0}; grasp_missed: {wait: 0}; 3: {wait: 0}; "4": {wait: 0}; "5.0": {wait: 0}'))
    assert status == 2
    assert lines == [
        "t.yaml:11:9: case 'ok' never matches: $count holds a whole number (std_msgs/Int32), not text",
        "t.yaml:12:9: case 'grasp_missed' never matches: $count holds a whole number (std_msgs/Int32), not text",
        "t.yaml:15:10: case '5.0' never matches: $count holds a whole number (std_msgs/Int32), whose text is never "
        "'5.0' (write 5:)"]


def test_a_true_or_false_value_takes_true_and_false_cases_unquoted_or_quoted(tmp_path, capsys):
    status, lines = check_counted(tmp_path, capsys, switch_on("heard", "true: {wait: 0}; false: {wait: 0}"))
    assert (status, lines) == (0, [])
    status, lines = check_counted(tmp_path, capsys, switch_on("heard", '"true": {wait: 0}; "false": {wait: 0}'))
    assert (status, lines) == (0, [])


def test_the_cases_a_true_or_false_value_can_never_match_are_errors(tmp_path, capsys):
    status, lines = check_counted(tmp_path, capsys, switch_on("heard", '"yes": {wait: 0}; 1: {wait: 0}'))
    assert lines == [
        "t.yaml:11:10: case 'yes' never matches: $heard holds true or false (std_msgs/Bool): its cases are true: "
        "and false:",
        "t.yaml:12:9: case 1 never matches: $heard holds true or false (std_msgs/Bool): its cases are true: and "
        "false:"]


@pytest.mark.parametrize("key,said", [
    ("answer", 'this case is read by YAML as true (unquoted yes/no/on/off/null): quote it, e.g. "yes": or "no":'),
    ("count", "this case is read by YAML as true (unquoted yes/no/on/off/null), and $count holds a whole number "
              "(std_msgs/Int32): it never matches"),
    ("tries", 'this case is read by YAML as true (unquoted yes/no/on/off/null): quote it, e.g. "yes": or "no": '
              '(a value that is true or false is matched by true: and false:)'),
])
def test_an_unquoted_yes_is_an_error_unless_the_value_is_true_or_false(tmp_path, capsys, key, said):
    text = switch_on(key, "yes: {wait: 0}").replace("root:", "inputs:\n  tries: {}\nroot:")
    status, lines = check_counted(tmp_path, capsys, text)
    assert lines == ["t.yaml:13:9: " + said]


@pytest.mark.parametrize("case", ["true", "True", "false", "'true'"])
def test_a_true_or_false_case_written_so_is_no_error(tmp_path, capsys, case):
    """YAML reads ``true:`` and ``yes:`` alike; only ``yes:`` never matches the text it says: ``true:``
    matches a true value and the text "true" (a tree input given false by default, as SMACH ports have)."""
    text = switch_on("tries", "%s: {wait: 0}" % case).replace("root:", "inputs:\n  tries: {default: false}\nroot:")
    assert check_counted(tmp_path, capsys, text) == (0, [])
    status, lines = check_counted(tmp_path, capsys, switch_on("count", "%s: {wait: 0}" % case))
    assert status == 2 and "never matches" in lines[0] and "whole number" in lines[0], lines


def test_contains_on_a_value_that_is_not_text_is_an_error(tmp_path, capsys):
    status, lines = check_counted(tmp_path, capsys, switch_on("count", '"3": {wait: 0}', "      match: contains\n"))
    assert lines == ["t.yaml:10:14: match: contains looks for the case's text in the value, but $count holds a "
                     "whole number (std_msgs/Int32): use match: equals"]


def test_a_switch_on_text_takes_number_and_text_cases(tmp_path, capsys):
    assert check_counted(tmp_path, capsys, switch_on("answer", '3: {wait: 0}; "ok": {wait: 0}')) == (0, [])


# 3. other tools' names of kinds --------------------------------------------------------------------------
@pytest.mark.parametrize("name,said", [
    ("fallback", "BehaviorTree.CPP's Fallback is bmtree's selector"),
    ("ReactiveSequence", "BehaviorTree.CPP's ReactiveSequence is bmtree's sequence with memory: false (the earlier "
                         "children are checked again on every tick, so only its last child may take more than one "
                         "tick; to react while an action runs, see 'Reacting while an action runs' in "
                         "trees/README.md)"),
    ("Sequence", "BehaviorTree.CPP's, py_trees' and SMACH's Sequence is bmtree's sequence"),
    ("py_trees.composites.Selector", "py_trees' Selector is bmtree's selector"),
    ("retry_until_successful", "BehaviorTree.CPP's RetryUntilSuccessful is bmtree's retry: N (attempts in all), "
                               "with child: beside it"),
    ("Switch3", "BehaviorTree.CPP's Switch3 is bmtree's switch: $key, with cases: {case: node} and default:"),
    ("Concurrence", "SMACH's Concurrence is bmtree's parallel, with policy: all, one or first_success, or "
                    "succeed_on: [child names] (its outcome map); ended_by: KEY and a switch: $KEY after it for "
                    "several outcomes"),
    ("Delay", "BehaviorTree.CPP's Delay has no kind of its own in bmtree: a wait before the node, in a sequence: "
              "[{wait: SECONDS}, node] (or retry's delay: between attempts)"),
    ("EternalGuard", "py_trees' EternalGuard has no kind of its own in bmtree: a sequence with memory: false whose "
                     "first child is the check: the condition is checked again on every tick"),
])
def test_a_kind_of_another_tool_is_named_with_what_it_is_in_bmtree(tmp_path, capsys, name, said):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  %s: [{wait: 0}]\n" % name)
    assert lines == ["t.yaml:3:3: unknown node kind %r (%s)" % (name, said)]


def test_other_tools_names_lead_only_to_kinds_and_options_bmtree_has():
    for name, (kinds, hint) in OTHER_KINDS.items():
        assert kinds and set(kinds) <= set(REGISTRY), name
        said = re.sub(r"\{[^}]*\}", "", re.sub(r"^.*? bmtree('s|:)", "", hint))   # (nor set: {key: value})
        words = set(re.findall(r"\b[a-z_]+\b(?=:)", said))   # 'memory: false', 'child:', 'retry: N'
        assert words <= set(REGISTRY) | {o for k in kinds for o in _ALLOWED[k]}, (name, words)
    for option, (options, _) in OTHER_OPTIONS.items():
        assert any(set(options) <= set(a) for a in _ALLOWED.values()), option


# 4. an unknown option lists the kind's options -----------------------------------------------------------
NODES = {
    "sequence": "sequence: [{wait: 0}]", "selector": "selector: [{wait: 0}]", "parallel": "parallel: [{wait: 0}]",
    "switch": "switch: x\n    cases: {x: {wait: 0}}", "retry": "retry: 2\n    child: {wait: 0}",
    "timeout": "timeout: 2\n    child: {wait: 0}", "inverter": "inverter: {wait: 0}",
    "force_success": "force_success: {wait: 0}", "force_failure": "force_failure: {wait: 0}",
    "repeat": "repeat: 2\n    child: {wait: 0}", "for_each": "for_each: [a]\n    as: x\n    child: {wait: 0}",
    "call": "call: speech.say\n    inputs: {text: hi}", "recall": "recall: {x: text}", "check": "check: 'true'",
    "wait_event": "wait_event: vision.personSeen", "set": "set: {x: 1}", "wait": "wait: 0",
    "include": "include: sub.yaml", "fail": "fail: stop",
}


def test_every_kind_is_tried():
    assert set(NODES) == set(REGISTRY)


@pytest.mark.parametrize("kind", sorted(NODES))
def test_an_unknown_option_lists_the_options_of_the_kind_from_its_table(tmp_path, capsys, kind):
    (tmp_path / "sub.yaml").write_text("format: 1\nroot: {wait: 0}\n")
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  sequence:\n  - %s\n    xyzzy: 1\n" % NODES[kind])
    options = sorted(["name"] + [o.name for o in REGISTRY[kind].options])
    assert ("unknown option 'xyzzy' for %s (%s takes %s)" % (kind, kind, ", ".join(options))) in lines[0], lines


def test_an_unknown_option_in_a_composites_mapping_form_lists_its_options_too(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  parallel: {children: [{wait: 0}], polcy_: one, "
                                            "x: 1}\n")
    assert lines == ["t.yaml:3:37: unknown option 'polcy_' for parallel (did you mean 'policy'?)",
                     "t.yaml:3:50: unknown option 'x' for parallel (parallel takes ended_by, name, policy, succeed_on, synchronise)"]


def test_smachs_remapping_says_inputs_and_outputs(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  call: speech.listen\n  inputs: {seconds: 3}\n"
                                            "  remapping: {text: answer}\n")
    (line,) = lines
    assert line.startswith("t.yaml:5:3: unknown option 'remapping' for call (call takes ")
    assert line.endswith("): SMACH's remapping is inputs: (input name: $key) and outputs: (output name: key)")


# 5. a list as a decorator's child ------------------------------------------------------------------------
@pytest.mark.parametrize("node,where,said", [
    ("retry: 3\n  child: [{wait: 0}, {wait: 1}]", "4:10", "a decorator (retry) has one child, not a list: wrap "
                                                          "several nodes in a sequence, child: {sequence: [...]}"),
    ("inverter: [{wait: 0}, {wait: 1}]", "3:13", "a decorator (inverter) has one child, not a list: wrap several "
                                                 "nodes in a sequence, inverter: {sequence: [...]}"),
    ("timeout: 3\n  child: [{wait: 0}]", "4:10", "a decorator (timeout) has one child, not a list: write the node "
                                                 "without [ ]"),
    ("switch: x\n  cases: {x: [{wait: 0}, {wait: 1}]}", "4:14", 'a case of switch runs one child, not a list: wrap '
                                                                'several nodes in a sequence, "case": {sequence: [...]}'),
])
def test_a_list_as_a_decorators_child_says_to_wrap_it_in_a_sequence(tmp_path, capsys, node, where, said):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  %s\n" % node)
    assert lines == ["t.yaml:%s: %s" % (where, said)]


# 6. a decorator written as a mapping ---------------------------------------------------------------------
@pytest.mark.parametrize("node,where,said", [
    ("retry: {attempts: 3, child: {wait: 0}}", "3:10",
     "retry takes its count as its value and its options beside it, not in a mapping: {retry: 3, child: …} (in "
     "block form, child: on a line of its own below retry:, at its indentation)"),
    ("timeout: {child: {wait: 0}}", "3:12",
     "timeout takes its duration as its value and its options beside it, not in a mapping: {timeout: SECONDS, "
     "child: …} (in block form, child: on a line of its own below timeout:, at its indentation)"),
    ("for_each: {as: room, child: {wait: 0}}", "3:13",
     "for_each takes its list as its value and its options beside it, not in a mapping: {for_each: LIST, as: room, "
     "child: …} (in block form, as: and child: each on a line of its own below for_each:, at its indentation)"),
    ("retry: {wait: 0}", "3:10",
     "retry takes its count as its value and the node under 'child:', beside it: {retry: N, child: …}"),
    ("inverter: {child: {wait: 0}}", "3:13",
     "inverter takes its child node as its value, not under 'child:': inverter: {…the node…}"),
])
def test_a_decorator_written_as_a_mapping_is_one_error_that_shows_the_form(tmp_path, capsys, node, where, said):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  %s\n" % node)
    assert lines == ["t.yaml:%s: %s" % (where, said)]


def test_the_child_of_a_decorator_written_as_a_mapping_is_still_checked(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
root:
  sequence:
    - retry: {attempts: three, child: {call: speech.listen, inputs: {seconds: 3}, outputs: {txt: answer}}}
    - check: 'answer == "yes"'
    - retry: {attempts: 2, child: {call: speech.listen, inputs: {seconds: 3}, outputs: {text: heard}}}
    - check: 'heard == "yes"'
""")
    assert lines == [   # the count and the child as they would be without the mapping; 'heard' is written,
                        # and so is 'answer' (from an output not named right: said once, not again where read)
        "t.yaml:4:14: retry takes its count as its value and its options beside it, not in a mapping: "
        "{retry: three, child: …} (in block form, child: on a line of its own below retry:, at its indentation)",
        "t.yaml:4:25: count of retry must be an integer >= 1, got 'three'",
        "t.yaml:4:93: speech.listen has no output 'txt' (did you mean 'text'?)",   # and no knock-on: 'answer'
        "t.yaml:6:14: retry takes its count as its value and its options beside it, not in a mapping: "
        "{retry: 2, child: …} (in block form, child: on a line of its own below retry:, at its indentation)"]


def test_smachs_transitions_and_outcome_map_are_named_with_what_bmtree_writes(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  sequence:\n    - call: speech.say\n"
                                            "      inputs: {text: hi}\n      transitions: {succeeded: next}\n"
                                            "    - parallel:\n        - wait: 1\n      outcome_map: {done: {a: x}}\n")
    assert status == 2
    assert lines[0].startswith("t.yaml:6:7: unknown option 'transitions' for call (call takes check_success, ")
    assert lines[0].endswith("): SMACH's transitions are a sequence's order (the next state when one succeeds) and, "
                             "to route on how a call ended, its status: KEY with a switch: $KEY over the outcomes "
                             "after it")
    assert lines[1] == ("t.yaml:9:7: unknown option 'outcome_map' for parallel (parallel takes ended_by, name, policy, succeed_on, "
                        "synchronise): SMACH's outcome_map is parallel's succeed_on: [child names] (those children "
                        "succeed: it succeeds, halting the others) or policy: all, one or first_success; for several outcomes, ended_by: KEY (the name of the child that ended it) "
                        "and a switch: $KEY after it")
    assert OTHER_OPTIONS["child_termination_cb"] == OTHER_OPTIONS["outcome_map"]


def test_an_input_name_yaml_read_as_true_says_to_quote_it(tmp_path, capsys):
    defs = tmp_path / "lamp.json"
    defs.write_text(json.dumps({"Basic Module": "lamp", "Brief Description": "A lamp.", "Hardware Required": [],
                                "Functions": [{"Name": "switch", "Exec-condition": "", "Description": "Turns it.",
                                               "Input-params": [{"Name": "on", "Data-type": "std_msgs/Bool",
                                                                 "Description": "on or off"}],
                                               "Output-params": [], "Concurrent": False}]}))
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  call: lamp.switch\n  inputs: {on: true}\n")
    assert bmtree(["check", "--modules", str(defs), str(path)]) == 2
    err = capsys.readouterr().err.replace(str(path), "t.yaml")
    assert "t.yaml:4:12: lamp.switch has no input True: YAML reads an unquoted on, off, yes or no as true or false; " \
           "quote the name ('on': …)\n" in err, err
    path.write_text("format: 1\nroot:\n  call: lamp.switch\n  inputs: {'on': true}\n")
    assert bmtree(["check", "--modules", str(defs), str(path)]) == 0


def test_a_for_each_policy_to_go_on_past_failures_is_told_the_idiom(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  for_each: [a, b]\n  as: x\n  policy: continue\n"
                                            "  child: {wait: 0}\n")
    assert status == 2 and lines == [
        "t.yaml:5:11: policy must be 'all' or 'one' (to go on to the next element when one fails, as SMACH's "
        "Iterator with a 'continue' outcome: put the child in force_success, and keep what failed with its call's "
        "status: KEY)"]


BOOL_SAID = ": YAML reads an unquoted on, off, yes or no as true or false; quote the name"


@pytest.mark.parametrize("tree,said", [
    ("root:\n  set: {on: true}\n", "t.yaml:3:9: tree key True is not an identifier" + BOOL_SAID),
    ("root:\n  set: {5: 1}\n", "t.yaml:3:9: tree key 5 is not an identifier"),
    ("inputs:\n  yes: {default: 1}\nroot:\n  wait: 1\n", "t.yaml:3:3: input name True is not an identifier" + BOOL_SAID),
    ("root:\n  call: speech.say\n  inputs: {text: hi}\n  status: on\n",
     "t.yaml:5:11: status of call must be a tree key, got True" + BOOL_SAID),
    ("root:\n  for_each: [1]\n  as: off\n  child: {wait: 1}\n",
     "t.yaml:4:7: 'as' must be a tree key (an identifier), got False" + BOOL_SAID),
    ("root:\n  recall: {no: room}\n", "t.yaml:3:12: tree key False is not an identifier" + BOOL_SAID),
])
def test_a_name_yaml_read_as_true_or_false_is_a_positioned_error_that_says_to_quote_it(tmp_path, capsys, tree, said):
    """A ``set:`` of ``on: true`` raised TypeError out of ``check``, ``run`` and ``test`` (exit 1, the code of a
    failed task); the other places gave no hint."""
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\n" + tree)
    assert bmtree(["check", str(path)]) == 2
    assert capsys.readouterr().err.replace(str(path), "t.yaml").splitlines()[0] == said



def test_an_output_name_not_of_the_function_is_said_once_not_again_where_its_key_is_read(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  sequence:\n"
                                            "    - call: speech.listen\n      inputs: {seconds: 3}\n"
                                            "      outputs: {txt: heard}\n    - check: 'heard == \"yes\"'\n")
    assert status == 2 and lines == ["t.yaml:6:17: speech.listen has no output 'txt' (did you mean 'text'?)"]


@pytest.mark.parametrize("kind, said", [
    ("RecoveryNode", "repeat: N+1 (number_of_retries + 1) with until: done"),
    ("PipelineSequence", "a parallel with succeed_on: [the last child's name]"),
    ("RateController", "a repeat of a sequence of the child and wait: 1/hz seconds"),
])
def test_nav2_controls_say_the_bmtree_idiom(tmp_path, capsys, kind, said):
    """navigation2's trees are BehaviorTree.CPP's with its own controls: a ported one gets the idiom, not
    only 'unknown node kind'."""
    status, lines = check_counted(tmp_path, capsys, "format: 1\nroot:\n  %s: [{wait: 1}]\n" % kind)
    assert status == 2 and lines[0].startswith("t.yaml:3:3: unknown node kind %r (Nav2's %s has no kind of its own "
                                               "in bmtree: %s" % (kind, kind, said)), lines
