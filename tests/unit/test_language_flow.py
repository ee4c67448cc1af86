"""The tree language's loops, templates, expressions, parameters and switch, run through the mocks
(simulated clock): for_each, text templates, arithmetic and functions, counts and durations from
references, repeat until/while, switch, and the bounds of every loop."""
from __future__ import annotations

import os

import pytest

from coordinator.cli import main as bmtree
from coordinator.errors import TreeErrors
from coordinator.expr import Expr, ExprError
from coordinator.language import load_tree
from coordinator.testing import fail, succeed
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA, TREES, one_file_trees

FIND_APPLE = os.path.join(TREES, "find_apple.yaml")
INVITE = os.path.join(TREES, "invite_to_dining_room.yaml")
DEFS = load_definitions([SIM_DIR, os.path.join(DATA, "modules_lang")])


@pytest.fixture
def tree(tmp_path, bmtree_tree):
    """``tree(root_yaml, inputs_yaml="")`` -> a TreeTest of a one-file tree with the test modules."""
    return one_file_trees(tmp_path, bmtree_tree, DEFS)


def errors_of(tmp_path, text: str):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), DEFS)
    return [str(e).replace(str(path), "bad.yaml") for e in info.value.errors]


def said(run):
    return [c.inputs["text"] for c in run.calls("speech.say")]


# for_each -----------------------------------------------------------------------------------
def test_for_each_over_a_literal_list_binds_each_element(tree):
    t = tree("""
  for_each: [kitchen, bedroom, 3]
  as: room
  child:
    call: speech.say
    inputs: {text: "now {room}"}
""")
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == ["now kitchen", "now bedroom", "now 3"]
    assert run.blackboard["room"] == 3


def test_for_each_all_must_succeed_stops_at_the_first_failure(tree):
    t = tree("""
  for_each: [a, b, c]
  as: room
  policy: all
  child: {call: navigation.go_to, inputs: {place: $room}}
""")
    t.mocks["navigation.go_to"].script(succeed(room="a"), fail("door locked"), succeed(room="c"))
    run = t.run()
    assert run.failed and "door locked" in run.reason
    assert [c.inputs["place"] for c in run.calls("navigation.go_to")] == ["a", "b"]


def test_for_each_until_one_succeeds_over_a_tree_input(bmtree_tree):
    t = bmtree_tree(FIND_APPLE, inputs={"rooms": ["bedroom", "kitchen", "garage"]})
    where = {}
    t.mocks["navigation.go_to"].respond(lambda place: where.update(room=place) or {"room": place})
    t.mocks["vision.find_object"].respond(lambda object: {"success": where["room"] == "kitchen",
                                                          "room": where["room"], "position": {"x": 1.0}})
    run = t.run()
    assert run.succeeded, run.reason
    assert [c.inputs["place"] for c in run.calls("navigation.go_to")] == ["bedroom", "kitchen"]
    assert run.statuses("visit rooms until the apple is seen")[-1] == "SUCCESS"


def test_for_each_over_a_list_a_call_wrote(tree):
    t = tree("""
  sequence:
    - call: house.rooms
      outputs: {rooms: plan}
    - for_each: $plan.name
      as: room
      child:
        call: house.visit
        inputs: {room: $room, note: "{len(plan.name)} rooms, this is {upper(room)}"}
""")
    t.mocks["house.rooms"].succeed(rooms={"name": ["hall", "lab"]})
    run = t.run()
    assert run.succeeded, run.reason
    assert [(c.inputs["room"], c.inputs["note"]) for c in run.calls("house.visit")] == [
        ("hall", "2 rooms, this is HALL"), ("lab", "2 rooms, this is LAB")]


def test_for_each_bounds_and_bad_lists_fail_with_the_reason(tree):
    long = tree("""
  for_each: $(items)
  as: x
  max: 2
  child: {call: speech.say, inputs: {text: "{x}"}}
""", inputs="  items: {default: [1, 2, 3]}\n")
    run = long.run()
    assert run.failed and "the list has 3 elements, more than max 2" in run.reason
    assert run.calls() == []
    scalar = tree("""
  for_each: $items
  as: x
  child: {wait: 0}
""", inputs="  items: {default: kitchen}\n")
    run = scalar.run()
    assert run.failed and "is a string, not a list" in run.reason
    for policy, ok in (("all", True), ("one", False)):
        empty = tree("""
  for_each: []
  as: x
  policy: %s
  child: {wait: 1}
""" % policy)
        assert empty.run().succeeded is ok


# templates ------------------------------------------------------------------------------------
def test_templates_fill_text_and_escape_braces(tree):
    t = tree("""
  sequence:
    - set: {object: apple, room: kitchen, n: 2.0, pos: {x: 1.5}}
    - call: speech.say
      inputs: {text: "I found the {object} in the {room}: {{literally}} {n + 1} at x={pos.x}"}
    - call: speech.say
      inputs: {text: "$$5 for {lower('ABC')}"}
""")
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == ["I found the apple in the kitchen: {literally} 3 at x=1.5", "$5 for abc"]


@pytest.mark.parametrize("doubling", ['"$(s + s)"', '"{s}{s}"'])
def test_a_text_doubled_in_a_loop_fails_at_the_size_limit_instead_of_taking_all_memory(tree, doubling):
    t = tree("  repeat: 64\n  child:\n    set: {s: %s}\n" % doubling, "  s: {default: x}\n")
    run = t.run()
    assert not run.succeeded
    assert "characters long, more than the 1048576 a value may have" in run.reason, run.reason


def test_template_errors_are_found_before_running(tmp_path):
    errs = errors_of(tmp_path, "format: 1\ninputs:\n  object: {default: apple}\nroot:\n"
                               "  call: speech.say\n  inputs: {text: \"the {objet} is {here\"}\n")
    assert any("bad.yaml:6:34: '{' without its '}'" in e for e in errs), errs
    errs = errors_of(tmp_path, "format: 1\ninputs:\n  object: {default: apple}\nroot:\n"
                               "  call: speech.say\n  inputs: {text: \"the {objet}\"}\n")
    assert errs == ["bad.yaml:6:24: reads 'objet', which no node writes and no input declares "
                    "(did you mean 'object'?)"]


def test_dollar_inside_text_warns_with_the_template_form(tmp_path, capsys):
    path = tmp_path / "w.yaml"
    path.write_text("format: 1\ninputs:\n  object: {default: apple}\nroot:\n"
                    "  call: speech.say\n  inputs: {text: \"I found the $object\"}\n")
    assert bmtree(["check", str(path)]) == 0
    err = capsys.readouterr().err
    assert "w.yaml:6:19: warning: '$object' inside text is sent as written, not replaced: write '{object}'" in err
    assert bmtree(["check", "--strict", str(path)]) == 2


# expressions ----------------------------------------------------------------------------------
@pytest.mark.parametrize("text,values,expected", [
    ("1 + 2 * 3", {}, 7),
    ("(1 + 2) * 3 - -1", {}, 10),
    ("a / 4", {"a": 10}, 2.5),
    ("-a + 1", {"a": 3}, -2),
    ("len(xs) - 1", {"xs": [1, 2, 3]}, 2),
    ("lower(s) + upper('b')", {"s": "AbC"}, "abcB"),
    ("str(n) + ' rooms'", {"n": 2.0}, "2 rooms"),
    ("max(a, 3, round(2.6)) + min(1, abs(-4))", {"a": 1}, 4),
    ("b.percentage < 20 and len(name) >= 3", {"b": {"percentage": 12.5}, "name": "Ana"}, True),
])
def test_arithmetic_and_functions(text, values, expected):
    assert Expr(text).value(values.__getitem__) == expected


@pytest.mark.parametrize("text,values,message", [
    ("s + 1", {"s": "a"}, "cannot add string 'a' and number 1"),
    ("a / 0", {"a": 1}, "division by zero"),
    ("len(n)", {"n": 5}, "len() takes a string or a list, got number 5"),
    ("lower(n)", {"n": 5}, "lower() takes a string, got number 5"),
    ("-s", {"s": "x"}, "cannot negate string 'x'"),
])
def test_expression_errors_when_running(text, values, message):
    with pytest.raises(ExprError, match=message.replace("(", r"\(").replace(")", r"\)")):
        Expr(text).value(values.__getitem__)


@pytest.mark.parametrize("bad,offset,message", [
    ("lenn(x)", 0, "unknown function 'lenn' (did you mean 'len'?)"),
    ("len(a, b)", 0, "len() takes 1 argument, got 2"),
    ("a +", 3, "expected a value"),
    ("a * * b", 4, "expected a value"),
])
def test_malformed_expressions_say_where(bad, offset, message):
    with pytest.raises(ExprError) as info:
        Expr(bad)
    assert info.value.offset == offset and message in str(info.value)


def test_battery_check_runs_on_a_message_field(tree):
    t = tree("""
  sequence:
    - call: house.battery
      outputs: {state: battery}
    - check: '$battery.percentage < 20'
    - set: {low_by: "$(20 - battery.percentage)"}
""")
    t.mocks["house.battery"].succeed(state={"percentage": 12.5})
    run = t.run()
    assert run.succeeded, run.reason
    assert run.blackboard["low_by"] == 7.5


def test_static_type_errors_name_file_line_column(tmp_path):
    errs = errors_of(tmp_path, """format: 1
root:
  sequence:
    - call: house.battery
      outputs: {state: battery}
    - call: speech.listen
      inputs: {seconds: 1}
      outputs: {text: answer}
    - check: 'battery.percentage + answer > 2'
    - check: 'len(battery.percentage) > 0 and answer < 3'
    - set: {x: "$(answer * 2)", y: "I have {battery + 1}"}
""")
    assert errs == [
        "bad.yaml:9:34: cannot add a number and a string",
        "bad.yaml:10:15: len() takes a string or a list, not a number",
        "bad.yaml:10:54: cannot compare a string < a number",
        "bad.yaml:11:26: cannot multiply a string and a number",
        "bad.yaml:11:53: cannot add a message and a number",
    ], errs


# parameters -----------------------------------------------------------------------------------
def test_counts_and_durations_from_inputs_and_expressions(tree):
    t = tree("""
  sequence:
    - retry: $tries
      child: {call: navigation.go_to, inputs: {place: kitchen}, timeout: $(step * 2)}
    - timeout: $(step * 10)
      child: {wait: $step}
    - repeat: $(tries - 1)
      child: {call: speech.say, inputs: {text: again}}
""", inputs="  tries: {default: 3}\n  step: {default: 1.5}\n")
    t.mocks["navigation.go_to"].script(fail("blocked"), fail("blocked"), succeed(room="kitchen"))
    run = t.run()
    assert run.succeeded, run.reason
    assert [c.status for c in run.calls("navigation.go_to")] == ["failed", "failed", "succeeded"]
    assert said(run) == ["again", "again"]


@pytest.mark.parametrize("node,reason", [
    ("retry: $n\n  child: {call: speech.say, inputs: {text: hi}}", "count of retry $n is 0, not an integer >= 1"),
    ("repeat: $(n - 1)\n  child: {call: speech.say, inputs: {text: hi}}",
     "count of repeat $(n - 1) is -1, not an integer >= 1"),
    ("timeout: $(n * 1.0)\n  child: {call: speech.say, inputs: {text: hi}}",
     "duration of timeout $(n * 1.0) is 0.0, not a positive number of seconds"),
    ("wait: $(n - 2)", "duration of wait $(n - 2) is -2, not a number of seconds >= 0"),
    ("call: speech.say\n  inputs: {text: hi}\n  timeout: $word", "timeout of call $word is 'soon', not a positive"),
    ("recall: {x: thing}\n  timeout: $n", "timeout of recall $n is 0"),
    ("wait_event: navigation.arrived\n  timeout: $word", "timeout of wait_event $word is 'soon'"),
    ("retry: 2\n  delay: $(n - 1)\n  child: {call: speech.say, inputs: {text: hi}}",
     "delay of retry $(n - 1) is -1, not a number of seconds >= 0"),
])
def test_bad_parameters_fail_when_the_node_starts(tree, node, reason):
    t = tree("  " + node + "\n", inputs="  n: {default: 0}\n  word: {default: soon}\n")
    run = t.run()
    assert run.failed and reason in run.reason, run.reason
    assert run.calls() == []


# repeat until / while -------------------------------------------------------------------------
def test_repeat_until_a_condition_holds(tree):
    t = tree("""
  repeat: 5
  until: 'len(answer) > 0'
  child:
    call: speech.listen
    inputs: {seconds: 1}
    outputs: {text: answer}
""")
    t.mocks["speech.listen"].script(succeed(text=""), succeed(text=""), succeed(text="yes"))
    run = t.run()
    assert run.succeeded, run.reason
    assert len(run.calls("speech.listen")) == 3 and run.blackboard["answer"] == "yes"


def test_repeat_while_counts_down_and_may_not_run(tree):
    body = """
  sequence:
    - set: {left: $start}
    - repeat: 10
      while: 'left > 0'
      child:
        sequence:
          - call: speech.say
            inputs: {text: "{left} left"}
          - set: {left: "$(left - 1)"}
"""
    run = tree(body, inputs="  start: {default: 3}\n").run()
    assert run.succeeded, run.reason
    assert said(run) == ["3 left", "2 left", "1 left"]
    run = tree(body, inputs="  start: {default: 0}\n").run()
    assert run.succeeded and said(run) == []


def test_loops_reaching_their_maximum_fail_with_the_reason(tree):
    t = tree("""
  repeat: 3
  until: 'answer == "yes"'
  child: {call: speech.listen, inputs: {seconds: 1}, outputs: {text: answer}}
""")
    t.mocks["speech.listen"].succeed(text="hmm")
    run = t.run()
    assert run.failed and len(run.calls("speech.listen")) == 3
    assert run.reason.endswith("reached its maximum of 3 runs while answer == \"yes\" was still false "
                               "(answer = 'hmm')"), run.reason
    t = tree("""
  repeat: 2
  while: 'true'
  child: {wait: 1}
""")
    run = t.run()
    assert run.failed and "reached its maximum of 2 runs while true still held" in run.reason


def test_invite_listens_again_while_nothing_is_heard(bmtree_tree):
    t = bmtree_tree(INVITE, inputs={"listen_seconds": 3.0})
    t.mocks["vision.find_person"].succeed(person="Ana", position={"x": 2.3})
    t.mocks["speech.listen"].script(succeed(text=""), succeed(text="No thanks"))
    run = t.run()
    assert run.succeeded, run.reason
    assert [c.inputs["seconds"] for c in run.calls("speech.listen")] == [3.0, 3.0]
    assert said(run)[-1] == "All right, maybe later."


# switch ---------------------------------------------------------------------------------------
SWITCH = """
  switch: $(lower(answer))
  match: %s
  cases:
    "yes": {call: speech.say, inputs: {text: "great"}}
    "no": {call: speech.say, inputs: {text: "later"}}
    3: {call: speech.say, inputs: {text: "three"}}
%s"""


@pytest.mark.parametrize("match,answer,default,expected", [
    ("equals", "YES", True, ["great"]),
    ("equals", "yes please", True, ["what?"]),
    ("contains", "Yes please", True, ["great"]),
    ("contains", "well, no", False, ["later"]),
    ("equals", "3", False, ["three"]),
])
def test_switch_runs_the_matching_case_or_the_default(tree, match, answer, default, expected):
    t = tree(SWITCH % (match, '  default: {call: speech.say, inputs: {text: "what?"}}\n' if default else ""),
             inputs="  answer: {default: %r}\n" % answer)
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == expected


def test_switch_without_a_match_or_default_fails_with_the_reason(tree):
    t = tree(SWITCH % ("equals", ""), inputs="  answer: {default: maybe}\n")
    run = t.run()
    assert run.failed and "no case matches 'maybe' (cases: 'yes', 'no', 3) and no default" in run.reason


def test_switch_case_failure_is_the_switch_failure(bmtree_tree):
    t = bmtree_tree(INVITE)
    t.mocks["vision.find_person"].succeed(person="Ana", position={"x": 2.3})
    t.mocks["speech.listen"].succeed(text="yes")
    t.mocks["navigation.go_to"].respond(lambda place: fail("no path") if place == "dining_room" else {})
    run = t.run()
    assert run.failed and "no path" in run.reason
    assert run.statuses("act on the answer")[-1] == "FAILURE" and said(run)[-1] == "Great, please follow me."


def test_static_type_errors_in_loops_switch_and_parameters(tmp_path):
    errs = errors_of(tmp_path, """format: 1
root:
  sequence:
    - call: speech.listen
      inputs: {seconds: 1}
      outputs: {text: answer}
    - retry: $(answer * 2)
      child: {wait: 0}
    - for_each: $(answer - 1)
      as: x
      child: {wait: 0}
    - switch: $(-answer)
      cases: {"a": {wait: 0}}
""")
    assert errs == ["bad.yaml:7:23: cannot multiply a string and a number",
                    "bad.yaml:9:26: cannot subtract a string and a number",
                    "bad.yaml:12:17: cannot negate a string"], errs


@pytest.mark.parametrize("node", ["wait: .inf", "retry: 2\n  delay: .inf\n  child: {wait: 1}",
                                  "timeout: .inf\n  child: {wait: 1}",
                                  "call: speech.say\n  inputs: {text: hi}\n  timeout: .inf"])
def test_endless_seconds_are_refused_by_the_check(tmp_path, node):
    """``.inf`` would make a bounded wait, delay or timeout endless."""
    errs = errors_of(tmp_path, "format: 1\nroot:\n  " + node + "\n")
    assert len(errs) == 1 and "inf" in errs[0] and ("seconds" in errs[0]), errs


def test_for_each_index_pairs_an_element_with_the_same_position_of_another_list(tree):
    """Vision gives names and poses as two lists: `index:` and at() read the same position of both."""
    t = tree("""
  for_each: $names
  as: thing
  index: i
  child:
    call: speech.say
    inputs: {text: "{thing} is in the {at(rooms, i)}, the last is {at(rooms, -1)}"}
""", inputs="  names: {default: [cup, apple]}\n  rooms: {default: [kitchen, hall]}\n")
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == ["cup is in the kitchen, the last is hall", "apple is in the hall, the last is hall"]
    assert run.blackboard["i"] == 1


def test_at_out_of_range_or_of_the_wrong_kind_fails_or_is_an_error(tree, tmp_path):
    t = tree("""
  for_each: [a, b, c]
  as: x
  index: i
  child: {check: 'at(two, i) != ""'}
""", inputs="  two: {default: [p, q]}\n")
    run = t.run()
    assert run.failed and "at(): no position 2 in a list of 2" in run.reason, run.reason
    with pytest.raises(TreeErrors) as err:
        tree("""
  sequence:
    - call: speech.listen
      inputs: {seconds: 1}
      outputs: {success: ok}
    - for_each: [a]
      as: x
      index: x
      child: {check: 'at(ok, 0)'}
""")
    text = str(err.value)
    assert "'index' must be a tree key (an identifier) other than 'as', got 'x'" in text, text
    assert "at() takes a list or a string first, not a bool" in text, text
