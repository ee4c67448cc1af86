"""``bmtree check`` knows the kind (number, text, true/false, list) of what a ``set`` writes — a literal, a
``{…}`` template, an expression whose kind is known — so the expression checks report misfits of keys that
only ``set`` writes, as they do for keys a call writes. Writers that disagree on the kind, and tree inputs
(any value may be given), leave a key unknown; call inputs take such keys exactly as before."""
from __future__ import annotations

import json
import os

import pytest

from coordinator.cli import main as bmtree
from coordinator.dataflow import key_types
from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from modules.definition import load_definitions
from modules.sim import SIM_DIR

COUNTER = {
    "Basic Module": "counter",
    "Brief Description": "A counter of the tests: whole numbers and real ones as inputs.",
    "Hardware Required": [],
    "Functions": [
        {"Name": "add", "Exec-condition": "", "Description": "Adds.",
         "Input-params": [{"Name": "n", "Data-type": "std_msgs/Int32", "Description": "how many"},
                          {"Name": "x", "Data-type": "std_msgs/Float64", "Description": "how much"}],
         "Output-params": [{"Name": "total", "Data-type": "std_msgs/Int32", "Description": "the sum"}]},
    ],
}

EXAMPLE = """format: 1
name: settype
root:
  sequence:
    - set: {count: 0, who: "ana"}
    - check: 'count == "3"'      # always false: a number is never text
    - check: 'who + 1 > 2'       # cannot add text and a number
"""


@pytest.fixture(scope="module")
def counter_json(tmp_path_factory):
    path = tmp_path_factory.mktemp("counter") / "counter.json"
    path.write_text(json.dumps(COUNTER))
    return str(path)


@pytest.fixture(scope="module")
def defs(counter_json):
    return load_definitions([SIM_DIR, counter_json])


def found(tmp_path, defs, nodes: str, head: str = "format: 1\n"):
    """The errors and warnings of a tree whose root is a sequence of ``nodes`` (each line indented under
    it), ``file:line:column: message`` with the file shortened to t.yaml; the first node is on line 4
    (after ``head``'s one line)."""
    path = tmp_path / "t.yaml"
    path.write_text(head + "root:\n  sequence:\n" + "".join("    " + line + "\n"
                                                              for line in nodes.strip("\n").split("\n")))
    try:
        tree = load_tree(str(path), defs)
    except TreeErrors as exc:
        return [str(e).replace(str(path), "t.yaml") for e in exc.errors + exc.warnings]
    return [str(e).replace(str(path), "t.yaml") for e in tree.warnings]


# the example: both errors, at their operators, exit 2 -------------------------------------------------
def test_the_example_is_refused_with_both_errors_at_their_operators(tmp_path, capsys):
    path = tmp_path / "x.yaml"
    path.write_text(EXAMPLE)
    status = bmtree(["check", str(path)])
    lines = [line.replace(str(path), "x.yaml") for line in capsys.readouterr().err.splitlines()]
    assert (status, lines) == (2, [
        'x.yaml:6:21: a number == a string is always false (write 3, not "3")',
        "x.yaml:7:19: cannot add a string and a number"])


# kinds through expressions and templates ---------------------------------------------------------------
def test_a_kind_follows_through_an_expression_that_sets_the_key_again(tmp_path, defs):
    assert found(tmp_path, defs, "- set: {n: 0}\n- set: {n: \"$($n + 1)\"}\n- check: 'n == \"x\"'") == [
        "t.yaml:6:17: a number == a string is always false"]


@pytest.mark.parametrize("nodes,expected", [
    ("- set: {xs: [a]}\n- set: {m: \"$(len(xs))\"}\n- check: 'm + \"s\" == \"x\"'",
     "t.yaml:6:17: cannot add a number and a string"),
    ("- set: {xs: [], x: 1}\n- set: {xs: \"$(xs + [x])\"}\n- check: 'xs > 2'",
     "t.yaml:6:18: cannot compare a list > a number"),
    ("- set: {xs: []}\n- set: {ok: \"$(1 < len(xs))\"}\n- check: 'ok == \"yes\"'",
     "t.yaml:6:18: a bool == a string is always false (a true/false value is not text: write ok or not ok, or "
     "compare it with true or false, unquoted)"),
    ("- set: {who: ana}\n- set: {msg: \"hi {who}\"}\n- check: 'msg * 2 > 1'",
     "t.yaml:6:19: cannot multiply a string and a number"),
    ("- set: {flag: yes}\n- check: 'flag < 2'", "t.yaml:5:20: cannot compare a bool < a number"),
])
def test_the_kind_of_a_literal_a_template_or_an_expression_is_checked(tmp_path, defs, nodes, expected):
    assert found(tmp_path, defs, nodes) == [expected]


def test_a_set_expression_with_an_operand_of_the_wrong_kind_is_an_error_even_on_its_own_key(tmp_path, defs):
    assert found(tmp_path, defs, "- set: {who: ana}\n- set: {who: \"$(who + 1)\"}") == [
        "t.yaml:5:25: cannot add a string and a number"]


# writers that disagree, tree inputs --------------------------------------------------------------------
def test_writers_that_disagree_on_the_kind_leave_the_key_unknown(tmp_path, defs):
    assert found(tmp_path, defs, "- set: {v: 0}\n- set: {v: x}\n- check: 'v == \"x\" and v + 1 > 0'") == []
    assert found(tmp_path, defs, "- set: {v: 0, xs: [a]}\n- set: {v: \"$(at(xs, 0))\"}\n"
                                 "- check: 'v == \"x\"'") == []   # an element: its kind is not known


def test_a_number_and_a_real_number_or_a_call_output_of_a_number_agree(tmp_path, defs):
    assert found(tmp_path, defs, "- set: {n: 0}\n- set: {n: 2.5}\n- check: 'n < 3 and n == \"x\"'") == [
        "t.yaml:6:27: a number == a string is always false"]
    assert found(tmp_path, defs, "- set: {pct: 100}\n- call: battery.level\n  outputs: {percentage: pct}\n"
                                 "- check: 'pct < 20 and pct == \"low\"'") == [
        "t.yaml:7:32: a number == a string is always false"]


def test_two_call_outputs_of_numbers_of_different_types_agree_too(tmp_path, defs):
    assert found(tmp_path, defs, "- call: battery.level\n  outputs: {percentage: k}\n"
                                 "- call: counter.add\n  inputs: {n: 1, x: 1}\n  outputs: {total: k}\n"
                                 "- check: 'k.data > 0 and k == \"x\"'") == [
        "t.yaml:9:32: a number == a string is always false"]


def test_a_field_of_a_key_a_call_may_write_is_not_refused(tmp_path, defs):
    assert found(tmp_path, defs, "- set: {pct: 100}\n- call: battery.level\n  outputs: {percentage: pct}\n"
                                 "- set: {p: $pct}\n- check: 'pct.data < 20 and p.data < 20'") == []


def test_a_tree_input_is_not_narrowed(tmp_path, defs):
    head = "format: 1\ninputs:\n  count: {default: 0}\n"
    assert found(tmp_path, defs, "- check: 'count == \"3\"'", head) == []
    assert found(tmp_path, defs, "- set: {count: 5}\n- check: 'count == \"3\"'", head) == []


def test_an_include_argument_leaves_the_subtree_input_unknown(tmp_path, defs):
    (tmp_path / "sub.yaml").write_text("format: 1\ninputs:\n  k: {}\nroot:\n  check: 'k == \"x\"'\n")
    assert found(tmp_path, defs, "- include: sub.yaml\n  args: {k: 0}") == []


# call inputs and parameters ----------------------------------------------------------------------------
def test_a_set_number_is_taken_by_a_float_or_an_int32_call_input_as_before(tmp_path, defs):
    assert found(tmp_path, defs, "- set: {n: 2, x: 2.5}\n- call: counter.add\n  inputs: {n: $n, x: $n}\n"
                                 "- call: speech.listen\n  inputs: {seconds: $n}\n"
                                 "- call: counter.add\n  inputs: {n: $(n + 1), x: $x}") == []


def test_a_set_list_is_a_list(tmp_path, defs):
    assert found(tmp_path, defs, "- set: {xs: []}\n- check: 'len($xs) > 0'") == []
    assert found(tmp_path, defs, "- set: {xs: []}\n- check: '$xs + 1 > 0'") == [
        "t.yaml:5:19: cannot add a list and a number (to add an element to a list, write it in brackets: names + "
        "[name])"]


@pytest.mark.parametrize("nodes,expected", [
    ("- set: {who: ana}\n- check: 'who.name == \"x\"'",
     "t.yaml:5:15: reads who.name, but who holds text, which has no fields"),
    ("- set: {xs: [a]}\n- call: speech.say\n  inputs: {text: $xs.name}",
     "t.yaml:6:22: input 'text': reads xs.name, but xs holds a list, which has no fields (an element is xs[0])"),
    ("- set: {n: 3}\n- check: 'n[0] == 1'", "t.yaml:5:15: reads n[0], but n holds a number, which is not a list"),
    ("- set: {who: ana}\n- wait: $who", "t.yaml:5:13: duration of wait $who holds text, not a number of seconds >= 0"),
    ("- set: {n: 3}\n- for_each: $n\n  as: i\n  child: {wait: 0}", "t.yaml:5:17: for_each $n holds a number, not a list"),
    ("- set: {n: 3}\n- switch: $n\n  cases:\n    ok: {wait: 0}\n    \"3\": {wait: 0}",
     "t.yaml:7:9: case 'ok' never matches: $n holds a number, not text"),
])
def test_fields_durations_lists_and_switch_cases_are_checked_with_the_kind(tmp_path, defs, nodes, expected):
    assert found(tmp_path, defs, nodes) == [expected]


def test_what_a_set_may_hold_in_many_ways_is_not_refused(tmp_path, defs):
    assert found(tmp_path, defs, "- set: {who: ana, n: 3, xs: [a], m: {x: 1}, z: null}\n"
                                 "- check: 'who[0] == \"a\" and xs[0] == \"a\" and m.x == 1 and z == \"x\"'\n"
                                 "- for_each: $xs\n  as: e\n  child: {check: 'e.name == 1'}\n"
                                 "- wait: $n") == []


def test_the_ros_types_stay_unknown_and_the_kinds_are_kept_beside_them(tmp_path, defs):
    assert found(tmp_path, defs, "- set: {n: 0}\n- set: {t: \"{n}\", v: $n}\n- set: {n: \"$(n + 1)\"}") == []
    types = key_types(load_tree(str(tmp_path / "t.yaml"), defs))
    assert {k: types[k] for k in "ntv"} == {"n": {None}, "t": {None}, "v": {None}}
    assert {k: types.kinds[k] for k in "ntv"} == {"n": {"number"}, "t": {"string"}, "v": {"number"}}


def test_a_shipped_tree_still_passes(capsys):
    root = os.path.join(os.path.dirname(__file__), "..", "..", "trees")
    trees = sorted(os.path.join(root, f) for f in os.listdir(root) if f.endswith(".yaml"))
    assert bmtree(["check"] + trees) == 0, capsys.readouterr().err


# a bare $key as a call input ------------------------------------------------------------------------------
def test_a_key_only_set_writes_given_to_a_call_input_that_cannot_take_its_kind_is_an_error(tmp_path, defs):
    """``$who`` (text) as a ``geometry_msgs/Point``, ``$n`` (a number) as text: both fail when the call is
    built (``cannot build the call``); they are said before running now."""
    assert found(tmp_path, defs, """
- set: {who: ana, n: 3, xs: [1, 2]}
- call: navigation.approach
  inputs: {target: $who}
- call: speech.say
  inputs: {text: $n}
""") == ["t.yaml:6:24: input 'target' takes a mapping of fields x, y, z (geometry_msgs/Point), got $who, which "
         "holds text",
         "t.yaml:8:22: input 'text' takes text (std_msgs/String), got $n, which holds a number"]


def test_a_key_only_set_writes_given_to_a_call_input_that_takes_its_kind_is_accepted(tmp_path, defs):
    assert found(tmp_path, defs, """
- set: {who: ana, n: 3, real: 2.5}
- call: speech.say
  inputs: {text: $who}
- call: speech.listen
  inputs: {seconds: $n}
- call: counter.add
  inputs: {n: $n, x: $real}
""") == []
