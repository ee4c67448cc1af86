"""What a template or ``str()`` writes for a list, a mapping or a message (YAML's flow style, as a tree
writes one; it was Python's ``['apple', 'cup']`` next to YAML's ``null``), and ``join()`` for a robot
to say a list."""
from __future__ import annotations

import pytest
from geometry_msgs.msg import Point, Pose

from coordinator.expr import Expr, ExprError, text_of
from coordinator.testing import succeed
from tests.unit.test_check_messages import check
from tests.unit.test_language_flow import tree  # noqa: F401  (its fixture: a one-file tree)


def test_lists_mappings_and_messages_are_written_in_yaml_flow_style():
    assert text_of(["apple", "cup"]) == "[apple, cup]"
    assert text_of({"a": 1.0, "b": True, "c": None}) == "{a: 1, b: true, c: null}"
    assert text_of(Point(1.0, 2.5, 0.0)) == "{x: 1, y: 2.5, z: 0}"
    assert text_of(Pose()) == "{position: {x: 0, y: 0, z: 0}, orientation: {x: 0, y: 0, z: 0, w: 0}}"


def test_join_says_a_list():
    names = {"names": ["apple", "cup"], "n": 3}.__getitem__
    assert Expr.parse("join(names)").value(names) == "apple, cup"
    assert Expr.parse("join(names, ' and ')").value(names) == "apple and cup"
    with pytest.raises(ExprError, match=r"join\(\) takes a list first, got number 3"):
        Expr.parse("join(n)").value(names)


def test_a_template_says_a_list_as_a_robot_would(tree):  # noqa: F811
    t = tree("""  sequence:
    - set: {names: [apple, cup]}
    - call: speech.say
      inputs: {text: "I saw {join(names, ' and ')}; all: {names}"}
""")
    t.mocks["speech.say"].script(succeed())
    assert t.run().said() == ["I saw apple and cup; all: [apple, cup]"]


def test_join_of_a_number_is_an_error_at_check(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
root:
  sequence:
    - call: speech.listen
      inputs: {seconds: 1}
      outputs: {text: heard}
    - call: speech.say
      inputs: {text: "{join(heard)}"}
""")
    assert status == 2 and any("join() takes a list first, not a string" in line for line in lines), lines
