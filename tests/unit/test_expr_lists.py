"""Lists in expressions: ``[a, b]``, ``xs + [x]`` and ``split()``. A receptionist remembers each guest's
name (``set: {guests: "$(guests + [name])"}``) and takes the first word of what it heard; before, a tree
had no way to add an element to a list (``[$xs, $x]`` nests) nor to cut a text into words."""
from __future__ import annotations

import pytest
from std_msgs.msg import String

from coordinator.expr import Expr, ExprError
from coordinator.testing import succeed
from tests.unit.test_check_messages import check
from tests.unit.test_language_flow import tree  # noqa: F401  (its fixture: a one-file tree)

ENV = {"guests": ["Ann"], "heard": String("Bob Smith"), "n": 3, "csv": "a,b,,c", "raw": b"\x01\x02"}.__getitem__


@pytest.mark.parametrize("text,value", [
    ("[]", []),
    ("[1, n + 1, 'x']", [1, 4, "x"]),
    ("guests + [heard]", ["Ann", "Bob Smith"]),   # a one-field message stands for its value in a list too
    ("[heard] + guests", ["Bob Smith", "Ann"]),
    ("raw + [3]", [1, 2, 3]),                     # a uint8[] (bytes) is a list of numbers
    ("len(guests + [heard, 'Zoe'])", 3),
    ("'Ann' in guests + [heard]", True),
    ("'Bob' in guests + [heard]", False),         # in a list: an element equal to it
    ("split(heard)", ["Bob", "Smith"]),
    ("split('  two   words ')", ["two", "words"]),
    ("split(csv, ',')", ["a", "b", "", "c"]),
    ("at(split(heard), 0)", "Bob"),
    ("join(split(heard), '-')", "Bob-Smith"),
])
def test_lists_are_built_joined_and_split(text, value):
    assert Expr.parse(text).value(ENV) == value


@pytest.mark.parametrize("text,error", [
    ("guests + heard", "cannot add list and string 'Bob Smith' (to add an element to a list, write it in "
                       "brackets: names + [name])"),
    ("n + [1]", "cannot add number 3 and list (to add an element"),
    ("[1] - [1]", "cannot subtract list and list"),
    ("split(csv, '')", "split() takes a separator of at least one character, got ''"),
    ("split(n)", "split() takes a string, got number 3"),
    ("split(heard, 1)", "split() takes a string, got number 1"),
])
def test_a_list_used_wrongly_says_what_would_fix_it(text, error):
    with pytest.raises(ExprError) as info:
        Expr.parse(text).value(ENV)
    assert str(info.value).startswith(error), str(info.value)


def test_a_list_literal_is_parsed_with_positions():
    for text, at in (("[1, 2", 5), ("[1 2]", 3), ("[,]", 1)):
        with pytest.raises(ExprError) as info:
            Expr.parse(text)
        assert info.value.offset == at, (text, str(info.value), info.value.offset)
    assert Expr.parse("[a, b.x]").keys == {"a", "b"}


def test_the_types_of_lists_are_known_before_running():
    def kind(ref):
        return {"guests": "list", "heard": "string", "n": "number"}.get(ref.key)

    assert Expr.parse("guests + [heard]").kind(kind) == "list"
    assert Expr.parse("split(heard) + guests").kind(kind) == "list"
    assert Expr.parse("[n]").kind(kind) == "list"
    assert Expr.parse("guests + heard").type_errors(kind) == [
        (7, "cannot add a list and a string (to add an element to a list, write it in brackets: names + [name])")]
    assert Expr.parse("split(n)").type_errors(kind) == [(0, "split() takes a string, not a number")]
    assert Expr.parse("[n + 'x']").type_errors(kind) == [(3, "cannot add a number and a string")]


def test_check_refuses_adding_text_to_a_list_and_looping_over_a_count(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
root:
  sequence:
    - call: speech.listen
      inputs: {seconds: 1}
      outputs: {text: heard}
    - set: {words: "$(split(heard))"}
    - set: {more: "$(split(heard) + heard)"}
    - for_each: "$(len(split(heard)))"
      as: w
      child:
        call: speech.say
        inputs: {text: "{w}"}
""")
    assert status == 2, lines
    assert any(line.startswith("t.yaml:8:") and "cannot add a list and a string (to add an element" in line
               for line in lines), lines
    assert any(line.startswith("t.yaml:9:") and "is a number, not a list" in line for line in lines), lines


def test_a_receptionist_remembers_every_guest_and_greets_each(tree):  # noqa: F811
    t = tree("""  sequence:
    - repeat: 2
      child:
        sequence:
          - call: speech.listen
            inputs: {seconds: 5}
            outputs: {text: heard}
          - set: {guests: "$(guests + [heard])", first: "$(at(split(heard), 0))"}
    - check: '"Carol Ann" in guests'
    - call: speech.say
      inputs: {text: "Hello {join(guests, ' and ')}; {first}, {len(guests)} guests"}
    - for_each: $guests
      as: who
      child:
        call: speech.say
        inputs: {text: "Hi {who}"}
""", "  guests: {default: []}\n")
    t.mocks["speech.listen"].script(succeed(text="Bob"), succeed(text="Carol Ann"))
    t.mocks["speech.say"].script(succeed())
    run = t.run()
    assert run.succeeded, run
    assert run.said() == ["Hello Bob and Carol Ann; Carol, 2 guests", "Hi Bob", "Hi Carol Ann"]


def test_a_list_added_to_itself_in_a_loop_fails_the_node_not_the_machine(tree):  # noqa: F811
    t = tree("""  sequence:
    - repeat: 30
      child: {set: {xs: "$(xs + xs)"}}
""", "  xs: {default: [1, 2, 3, 4]}\n")
    run = t.run()
    assert run.failed and "the value would hold more than 2097152 elements and characters" in run.reason, run.reason
    t = tree("""  sequence:
    - repeat: 150
      child: {set: {xs: "$([xs])"}}
""", "  xs: {default: []}\n")
    run = t.run()
    assert run.failed and "the value would nest more than 100 levels deep" in run.reason, run.reason
