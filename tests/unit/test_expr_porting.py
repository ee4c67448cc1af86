"""What teams porting SMACH state machines missed in expressions: a choice (``if(c, a, b)``, evaluating only
the branch chosen), yes/no matching by whole words (``words()``: ``"no" in heard`` is true of "I don't
know"), a number with n decimals (``round(x, n)`` for Python's ``{pct:.1f}``), and a field of a function's
result (``at(ps.poses, i).position.z``). Before, each was an error without a way out, or a wrong answer."""
from __future__ import annotations

import json
import os

import pytest
from geometry_msgs.msg import Point, Pose, PoseArray
from std_msgs.msg import String

from coordinator.expr import Expr, ExprError
from coordinator.refs import Ref
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA, one_file_trees
from tests.unit.test_check_messages import check
from tests.unit.test_check_types_more import ARM, found
from tests.unit.test_check_types_propagation import SCAN

POSES = PoseArray(poses=[Pose(), Pose()])
POSES.poses[1].position.z = 1.5
ENV = {"xs": [], "names": ["Ana", "Bob"], "assume_john": True, "heard": String("Yes, please!"), "pct": 42.567,
       "ps": POSES, "pos": Point(1.0, 2.0, 3.0), "i": 1, "n": 20, "d": {"a": {"b": [5, 6]}}}.__getitem__


@pytest.fixture(scope="module")
def defs(tmp_path_factory):
    """The simulated robot's modules, the test house, an arm and a scanner of people (a PoseArray)."""
    folder = tmp_path_factory.mktemp("defs")
    (folder / "arm.json").write_text(json.dumps(ARM))
    (folder / "scan.json").write_text(json.dumps(SCAN))
    return load_definitions([SIM_DIR, os.path.join(DATA, "modules_lang"), str(folder / "arm.json"),
                             str(folder / "scan.json")])


@pytest.fixture
def tree(tmp_path, bmtree_tree, defs):
    return one_file_trees(tmp_path, bmtree_tree, defs)


def value(text):
    return Expr.parse(text).value(ENV)


def error(text):
    """(offset, message) of a malformed expression."""
    with pytest.raises(ExprError) as info:
        Expr.parse(text)
    return info.value.offset, str(info.value)


def run_error(text):
    with pytest.raises(ExprError) as info:
        value(text)
    return str(info.value)


SCANNED = "- call: scan.people\n  outputs: {poses: people}\n"   # lines 14-15 of found()'s tree: the check at 16


# 1. if(condition, then, else) ------------------------------------------------------------------------------
@pytest.mark.parametrize("text,expected", [
    ("if(assume_john, 'John', 'folks')", "John"),
    ("if(not assume_john, 'John', 'folks')", "folks"),
    ("if(len(xs) > 0, at(xs, 0), 'nobody')", "nobody"),        # at(xs, 0) on [] is not worked out
    ("if(len(names) > 0, at(names, 0), 'nobody')", "Ana"),
    ("if(true, 1, 1 / 0) + 1", 2),
    ("if(false, at(xs, 5), heard)", "Yes, please!"),          # a one-field message stands for its value
    ("if(len(xs), 'some', 'none')", "none"),                  # true and false as for 'not', 'and', 'or'
])
def test_if_evaluates_only_the_branch_chosen(text, expected):
    assert value(text) == expected


def test_the_branch_not_chosen_would_have_failed():
    assert value("if(len(xs) > 0, at(xs, 0), 'nobody')") == "nobody"
    assert run_error("at(xs, 0)") == "at(): no position 0 in a list of 0"


@pytest.mark.parametrize("text,offset,message", [
    ("'John' if assume_john else 'folks'", 7, "unexpected 'if' (a choice is written if(condition, then, else))"),
    ("x if (c) else y", 2, "unexpected 'if' (a choice is written if(condition, then, else))"),
    ("(a if c else b)", 3, "unexpected 'if' (a choice is written if(condition, then, else))"),
    ("[1, a if c else b]", 6, "unexpected 'if' (a choice is written if(condition, then, else))"),
    ("if(c, 1)", 0, "if() takes 3 arguments, got 2"),
    ("at(xs)", 0, "at() takes 2 arguments, got 1"),           # was "2 to 2 arguments"
])
def test_pythons_choice_says_how_to_write_it(text, offset, message):
    assert error(text) == (offset, message)


def test_a_choice_in_a_template_is_reported_at_its_column(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
inputs:
  assume_john: {default: false}
root:
  call: speech.say
  inputs: {text: "Hello {'John' if assume_john else 'folks'}!"}
""")
    assert status == 2
    assert lines == ["t.yaml:6:33: in {'John' if assume_john else 'folks'}: unexpected 'if' (a choice is written "
                     "if(condition, then, else))"], lines


def test_the_kind_of_if_is_its_branches_when_they_agree():
    def kind(ref):
        return {"c": "bool", "s": "string", "n": "number"}.get(ref.key)

    assert Expr.parse("if(c, 1, n)").kind(kind) == "number"
    assert Expr.parse("if(c, s, 'x')").kind(kind) == "string"
    assert Expr.parse("if(c, s, n)").kind(kind) is None
    assert Expr.parse("if(c, s, n) + 1").type_errors(kind) == []
    assert Expr.parse("if(c, s, 'x') + 1").type_errors(kind) == [(14, "cannot add a string and a number")]
    assert Expr.parse("if(s + 1, 1, 2)").type_errors(kind) == [(5, "cannot add a string and a number")]
    assert Expr.parse("if(c, s - 1, 2)").type_errors(kind) == [(8, "cannot subtract a string and a number")]


# 2. words(text) -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("text,expected", [
    ("Yes, please!", ["yes", "please"]),
    ("I don't know", ["i", "don't", "know"]),
    ("I don\u2019t know", ["i", "don't", "know"]),              # a typographic apostrophe, as a recognizer writes it
    ("\u00bfS\u00ed?", ["s\u00ed"]),
    ("  'Quoted,' he said...  ", ["quoted", "he", "said"]),
    ("yesterday", ["yesterday"]),
    ("3.5 metres", ["3.5", "metres"]),
    (" ... !", []),
])
def test_words_are_lower_case_without_punctuation_at_their_ends(text, expected):
    assert Expr.parse("words(t)").value({"t": String(text)}.__getitem__) == expected


@pytest.mark.parametrize("text,expected", [
    ("'yes' in words('Yes, please!')", True),
    ("'no' in words(\"I don't know\")", False),
    ("'no' in \"I don't know\"", True),                       # the substring test words() is for
    ("'yes' in words('yesterday')", False),
    ("'yes' in words(heard)", True),
    ("'s\u00ed' in words('\u00bfS\u00ed?')", True),           # a literal's letters beyond Latin-1 are kept
    ("'s\u00ed'", "s\u00ed"),
    ("'caf\\xe9 \\u00e9t\\u00e9\\n'", "caf\u00e9 \u00e9t\u00e9\n"),   # escapes are still read
])
def test_yes_and_no_are_matched_as_whole_words(text, expected):
    assert value(text) == expected


def test_words_takes_text():
    assert run_error("words(n)") == "words() takes a string, got number 20"
    assert Expr.parse("words(n)").type_errors(lambda r: "number") == [(0, "words() takes a string, not a number")]
    assert Expr.parse("words(s)").kind(lambda r: "string") == "list"
    assert Expr.parse("words(s) + 1").type_errors(lambda r: "string") == [
        (9, "cannot add a list and a number (to add an element to a list, write it in brackets: names + [name])")]


# 3. round(x, n) -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("text,expected", [
    ("round(pct, 1)", 42.6),
    ("round(pct, 2)", 42.57),
    ("round(pct)", 43),
    ("round(pct, 0)", 43),
    ("round(pct, 2.0)", 42.57),
    ("round(7, 3)", 7),
    ("str(round(pct, 1)) + ' percent'", "42.6 percent"),
    ("str(round(50.0, 1))", "50"),
])
def test_round_takes_a_number_of_decimals(text, expected):
    got = value(text)
    assert got == expected and type(got) is type(expected), got


@pytest.mark.parametrize("text,message", [
    ("round(pct, n)", "round() takes a whole number of decimals from 0 to 15, got 20"),
    ("round(pct, 1.5)", "round() takes a whole number of decimals from 0 to 15, got 1.5"),
    ("round(pct, -1)", "round() takes a whole number of decimals from 0 to 15, got -1"),
    ("round(pct, '1')", "round() takes a number, got string '1'"),
])
def test_round_refuses_other_decimals(text, message):
    assert run_error(text) == message


def test_round_is_checked_before_running():
    assert error("round(pct, 1, 2)") == (0, "round() takes 1 to 2 arguments, got 3")
    assert Expr.parse("round(pct, 16)").type_errors(lambda r: "number") == [
        (0, "round() takes a whole number of decimals from 0 to 15, got 16")]
    assert Expr.parse("1 + round(pct, s)").type_errors(lambda r: {"pct": "number"}.get(r.key, "string")) == [
        (4, "round() takes a number, not a string")]
    assert Expr.parse("round(pct, 2)").kind(lambda r: "number") == "number"


@pytest.mark.parametrize("text,offset,message", [
    ("pct:.0f", 3, "unexpected character ':' (for a whole number write round(pct))"),
    ("pct:.1f", 3, "unexpected character ':' (for 1 decimal write round(pct, 1))"),
    ("a + b : .2f", 6, "unexpected character ':' (for 2 decimals write round(a + b, 2))"),
    ("pct:>5", 3, "unexpected character ':' (a number is rounded to n decimals with round(x, n), not with ':')"),
])
def test_a_python_format_says_how_to_round(text, offset, message):
    assert error(text) == (offset, message)


def test_a_python_format_in_a_template_is_reported_at_its_column(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
inputs:
  pct: {default: 42.5}
root:
  call: speech.say
  inputs: {text: "Battery at {pct:.1f} percent"}
""")
    assert status == 2
    assert lines == ["t.yaml:6:34: in {pct:.1f}: unexpected character ':' (for 1 decimal write round(pct, 1))"], lines


# 4. a field or an index of a function's result -------------------------------------------------------------
@pytest.mark.parametrize("text,expected", [
    ("at(ps.poses, 1).position.z", 1.5),
    ("at(ps.poses, i) . position . z", 1.5),
    ("at(ps.poses, -1).position", Point(0.0, 0.0, 1.5)),
    ("split('a b c')[0] + split('a b c')[-1]", "ac"),
    ("(ps.poses)[1].position.z", 1.5),
    ("(d).a.b[1]", 6),
    ("if(assume_john, pos, ps.poses[0].position).y", 2.0),
    ("lower(at(names, 0))[0]", "a"),
])
def test_a_field_follows_a_functions_result(text, expected):
    assert value(text) == expected


def test_a_field_of_a_reference_in_parentheses_is_that_reference():
    e = Expr.parse("(pos).x + (ps.poses)[1].position.z")
    assert e.refs == [Ref("pos", ("x",)), Ref("ps", ("poses", 1, "position", "z"))]
    assert e.tree[2] == ("ref", Ref("pos", ("x",)), 1)
    assert Expr.parse("at(ps.poses, i).position.z").refs == [Ref("ps", ("poses",)), Ref("i")]


@pytest.mark.parametrize("text,message", [
    ("at(ps.poses, 0).position.w", "at(ps.poses, 0).position has no field 'w' (its fields: x, y, z)"),
    ("at(ps.poses, 0).postion", "at(ps.poses, 0) has no field 'postion' (did you mean 'position'?)"),
    ("split('a b')[5]", "split('a b') has no index 5 (it has 2 elements)"),
    ("len(names).x", "len(names) has no field 'x': it holds a number, which has no fields"),
])
def test_a_missing_field_of_a_result_names_it(text, message):
    assert run_error(text) == message


@pytest.mark.parametrize("text,offset,message", [
    ("at(xs, 0).", 10, "expected a field name after '.'"),
    ("at(xs, 0).$x", 10, "expected a field name after '.'"),
    ("split(s)[i]", 9, "expected an integer index"),
    ("split(s)[1.5]", 9, "expected an integer index"),
    ("split(s)[0", 10, "expected ']', found 'end of expression'"),
    ("at(xs, 0).x(1)", 11, "unexpected '('"),
    ("'text'.x", 6, "unexpected '.'"),
])
def test_a_malformed_field_of_a_result_says_where(text, offset, message):
    assert error(text) == (offset, message)


@pytest.mark.parametrize("node,expected", [
    ("- check: 'at(people.poses, 0).position.z + \"a\" > 0'", ["t.yaml:16:46: cannot add a number and a string"]),
    ("- set: {z: \"$(at(people.poses, 0).position.z)\"}\n- check: 'z == \"a\"'",
     ["t.yaml:17:17: a number == a string is always false"]),
    ("- check: 'at(js.name, 0) + 1 > 0'", ["t.yaml:16:30: cannot add a string and a number"]),
    ("- check: 'len(people.poses).x > 0'",
     ["t.yaml:16:15: reads len(people.poses).x, but len(people.poses) is a number, which has no fields"]),
    ("- check: 'split(answer).x == \"a\"'",
     ["t.yaml:16:15: reads split(answer).x, but split(answer) is a list, which has no fields (an element is "
      "split(answer)[0])"]),
    ("- check: 'at(people.poses, 0)[0] == 1'",
     ["t.yaml:16:15: reads at(people.poses, 0)[0], but at(people.poses, 0) is a message, which is not a list"]),
    ("- check: '(people).poses[0].position.w > 0'",
     ["t.yaml:16:16: reads people.poses[0].position.w, but people.poses[0].position holds a geometry_msgs/Point, "
      "which has no field 'w' (its fields: x, y, z)"]),
    ("- check: 'at(people.poses, 0).position.z > 0 and lower(at(js.name, 0)) == \"a\"'", []),
])
def test_the_kind_of_a_field_of_a_result_is_known_before_running(tmp_path, defs, node, expected):
    assert found(tmp_path, defs, SCANNED + node) == expected


# the four together, in a run ------------------------------------------------------------------------------
PORTED = """
  sequence:
    - call: scan.people
      outputs: {poses: people}
    - call: speech.listen
      inputs: {seconds: 1}
      outputs: {text: heard}
    - call: house.battery
      outputs: {state: battery}
    - set:
        said_yes: "$('yes' in words(heard))"
        said_no: "$('no' in words(heard))"
    - call: speech.say
      inputs: {text: "{if(said_yes, 'Great', 'Pity')}, {if(len(names) > 0, at(names, 0), 'nobody')}: battery at
        {round(battery.percentage, 1)} %, the first person {round(at(people.poses, 0).position.z, 2)} m up"}
"""


@pytest.mark.parametrize("heard,names,said,yes,no", [
    ("Yes, please!", [], "Great, nobody: battery at 42.6 %, the first person 1.23 m up", True, False),
    ("I don't know", ["Ana"], "Pity, Ana: battery at 42.6 %, the first person 1.23 m up", False, False),
])
def test_a_ported_state_machine_says_what_it_means(tree, heard, names, said, yes, no):
    t = tree(PORTED, inputs="  names: {default: %s}\n" % json.dumps(names))
    t.mocks["scan.people"].succeed(poses={"poses": [{"position": {"z": 1.2345}}]})
    t.mocks["speech.listen"].succeed(text=heard)
    t.mocks["house.battery"].succeed(state={"percentage": 42.567})
    run = t.run()
    assert run.succeeded, run.reason
    assert [c.inputs["text"] for c in run.calls("speech.say")] == [said]
    assert (run.blackboard["said_yes"], run.blackboard["said_no"]) == (yes, no)


def test_a_missing_field_of_a_result_fails_the_node_with_the_reason(tree):
    t = tree("""
  sequence:
    - call: scan.people
      outputs: {poses: people}
    - check: 'at(people.poses, 0).postion.z > 0'
""")
    t.mocks["scan.people"].succeed(poses={"poses": [{"position": {"z": 1.0}}]})
    run = t.run()
    assert run.failed
    assert "at(people.poses, 0) has no field 'postion' (did you mean 'position'?)" in run.reason, run.reason


# numbers with an exponent ------------------------------------------------------------------------
@pytest.mark.parametrize("text, expected", [("1e3 + 1", 1001.0), ("2E-1 * 10", 2.0), ("1.5e3", 1500.0)])
def test_a_number_with_an_exponent_is_one_number(text, expected):
    """As YAML 1.2 reads ``1e3`` (was: ``1`` then an unknown name ``e3``)."""
    assert value(text) == expected


@pytest.mark.parametrize("text", ["1e999 > 1", "x > 1.0e400"])
def test_a_number_past_a_float64_is_an_error_where_it_is(text):
    with pytest.raises(ExprError) as info:
        Expr.parse(text)
    assert str(info.value).startswith("the number 1") and "is out of range" in str(info.value)
    assert info.value.offset == text.index("1")


# - * / with one side known not to be a number ------------------------------------------------------
@pytest.mark.parametrize("expr, col, said", [
    ('people - [\\"John\\"]', 29, "cannot subtract a value and a list: '-' takes numbers (a list has no '-': build "
                                  "the list you want, e.g. with for_each and set)"),
    ('\\"ab\\" * people', 27, "cannot multiply a string and a value: '*' takes numbers"),
])
def test_minus_times_divide_with_one_side_not_a_number_is_an_error_before_running(tmp_path, capsys, expr, col, said):
    """A tree input's kind is not known; a list or a text on the other side is enough: it fails when run."""
    status, lines = check(tmp_path, capsys, "format: 1\ninputs:\n  people: {default: [John, Ana]}\nroot:\n"
                                            "  sequence:\n    - set: {left: \"$(%s)\"}\n" % expr)
    assert status == 2 and lines == ["t.yaml:6:%d: %s" % (col, said)], lines


def test_plus_with_one_side_unknown_is_left_to_the_run(tmp_path, capsys):
    """``+`` joins texts and lists too: an unknown side may be either."""
    status, lines = check(tmp_path, capsys, "format: 1\ninputs:\n  people: {default: [John, Ana]}\nroot:\n"
                                            "  set: {more: \"$(people + [\\\"Bob\\\"])\"}\n")
    assert status == 0, lines


def test_a_python_format_as_a_whole_quoted_value_gets_the_round_hint(tmp_path, capsys):
    """``text: "{pct:.0f}"`` was taken for a mapping written in quotes ("write the mapping without quotes")."""
    status, lines = check(tmp_path, capsys, 'format: 1\nroot:\n  sequence:\n    - set: {pct: 42.5}\n'
                                            '    - call: speech.say\n      inputs: {text: "{pct:.0f}"}\n')
    assert status == 2 and lines == [
        "t.yaml:6:27: in {pct:.0f}: unexpected character ':' (for a whole number write round(pct))"], lines


def test_range_says_what_counts_instead():
    at, said = error("len(range(3))")
    assert at == 4 and said.startswith("unknown function 'range' ("), said
    assert said.endswith("): to count, write repeat: N with index: KEY (its run's number, 0 for the first)"), said
