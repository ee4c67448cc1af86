"""The tree language: every node kind and option, references, data flow, and broken files."""
from __future__ import annotations

import json
import os

import pytest

from coordinator.cli import main as bmtree
from coordinator.errors import TreeErrors
from coordinator.expr import Expr, ExprError
from coordinator.language import load_tree, used_modules, walk
from tests.conftest import DATA, TREES

BAD = os.path.join(DATA, "trees_bad")
with open(os.path.join(BAD, "expected.json")) as _fh:
    EXPECTED = json.load(_fh)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_broken_tree_reports_file_line_column(name, sim_defs):
    path = os.path.join(BAD, name + ".yaml")
    with pytest.raises(TreeErrors) as info:
        load_tree(path, sim_defs)
    where, message = EXPECTED[name]
    lines = [str(e) for e in info.value.errors]
    wanted = (where if ".yaml:" in where else "%s.yaml:%s" % (name, where)) + ": "
    assert any(wanted in line and message in line for line in lines), lines


def test_all_errors_are_reported_at_once(tmp_path, sim_defs, capsys):
    tree = tmp_path / "many.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n    - call: speech.sya\n      inputs: {text: hi}\n"
                    "    - wiat: 1\n    - check: 'x > 1'\n")
    with pytest.raises(TreeErrors) as info:
        load_tree(str(tree), sim_defs)
    assert len(info.value.errors) == 3
    assert bmtree(["check", str(tree)]) == 2
    err = capsys.readouterr().err
    assert "many.yaml:4:13: module 'speech' has no function 'sya' (did you mean 'say'?)" in err
    assert "many.yaml:6:7: unknown node kind 'wiat' (did you mean 'wait'?)" in err
    assert "many.yaml:7:7: reads 'x'" in err and "Traceback" not in err


EVERY_KIND = """
format: 1
name: every kind
inputs:
  who: {default: Ana}
  count: {}
root:
  sequence:
    name: all
    memory: false
    children:
      - set: {greeting: "$$5 off", where: {x: 1.0, y: 2.0, z: 0.0}}
      - parallel:
          - call: speech.say
            inputs: {text: $who}
            timeout: 2.5
            check_success: false
          - wait_event: navigation.arrived
            outputs: {place: arrived_at}
            timeout: 4
        policy: one
        synchronise: false
      - selector:
          - inverter: {check: 'greeting == "x"'}
          - force_failure: {wait: 0}
        memory: false
      - retry: 2
        child:
          repeat: 2
          child:
            timeout: 5
            child:
              call: navigation.approach
              inputs: {target: $where}
              outputs: {position: pos}
      - force_success: {recall: {old: navigation/go_to/room, last: room}, timeout: 1}
      - check: 'pos.x >= 0 and not (count < 0) or $who == "Bob"'
      - include: ../trees/search_room.yaml
        args: {room: kitchen}
        name: kitchen search
      - check: 'object_position.z >= 0'
"""


def test_every_node_kind_and_option(tmp_path, sim_defs):
    path = tmp_path / "every.yaml"
    path.write_text(EVERY_KIND.replace("../trees/search_room.yaml", os.path.join(TREES, "search_room.yaml")))
    tree = load_tree(str(path), sim_defs)
    kinds = {n.kind for n in walk(tree.root)}
    assert kinds == {"sequence", "parallel", "call", "wait_event", "selector", "inverter", "check", "force_failure",
                     "wait", "retry", "repeat", "timeout", "force_success", "recall", "set", "include"}
    root = tree.root
    assert root.name == "all" and root.spec.memory is False
    par = root.children[1]
    assert (par.spec.policy, par.spec.synchronise) == ("one", False)
    say = par.children[0]
    assert say.spec.timeout == 2.5 and say.spec.check_success is False and say.name == "speech.say"
    assert root.children[0].spec["greeting"] == "$5 off"  # a leading $$ escapes
    assert tree.inputs["who"] == "Ana" and tree.required_inputs == {"count"}
    assert used_modules(tree) == ({"speech", "navigation", "vision"}, True)
    assert root.children[-2].name == "kitchen search"


def test_shipped_trees_check(capsys):
    assert bmtree(["check", os.path.join(TREES, "find_apple.yaml"),
                   os.path.join(TREES, "invite_to_dining_room.yaml")]) == 0
    assert capsys.readouterr().out.count(": ok") == 2


def test_render_dot_and_svg(tmp_path, capsys):
    dot = tmp_path / "t.dot"
    assert bmtree(["render", os.path.join(TREES, "find_apple.yaml"), "-o", str(dot)]) == 0
    text = dot.read_text()
    assert "visit rooms until the apple is seen" in text and "say I could not find it" in text
    svg = tmp_path / "t.svg"
    assert bmtree(["render", os.path.join(TREES, "find_apple.yaml"), "-o", str(svg)]) == 0
    assert svg.read_text().lstrip().startswith(("<?xml", "<svg"))
    assert bmtree(["render", os.path.join(TREES, "find_apple.yaml"), "-o", str(tmp_path / "t.gif")]) == 2


@pytest.mark.parametrize("text,values,expected", [
    ("a == 1", {"a": 1}, True),
    ("a != 1 or b", {"a": 1, "b": False}, False),
    ("not a < 2.5", {"a": 3}, True),
    ("'yes' in answer", {"answer": "Yes, I am coming"}, True),
    ("p.position.x >= -1 and p.position.x <= 1", {"p": {"position": {"x": 0.5}}}, True),
    ("xs[1] == \"b\"", {"xs": ["a", "b"]}, True),
    ("(a or b) and c == null", {"a": 0, "b": 1, "c": None}, True),
    ("$flag == true", {"flag": True}, True),
])
def test_expressions(text, values, expected):
    e = Expr(text)
    assert e.evaluate(values.__getitem__) is expected


def test_expressions_on_ros_messages_and_errors():
    from geometry_msgs.msg import Point
    from std_msgs.msg import String

    assert Expr('answer == "yes"').evaluate({"answer": String("yes")}.__getitem__)
    assert Expr("p.y < 0").evaluate({"p": Point(0, -1, 0)}.__getitem__)
    with pytest.raises(ExprError, match="has no field 'w'"):
        Expr("p.w").evaluate({"p": Point()}.__getitem__)
    with pytest.raises(ExprError, match="cannot compare"):
        Expr("a < 'x'").evaluate({"a": 1}.__getitem__)
    for bad, where in (("__import__('os')", 0), ("a.__class__(", 11), ("a ==", 4), ("a b", 2), ("(a", 2)):
        with pytest.raises(ExprError) as info:
            Expr(bad)
        assert info.value.offset == where


def test_hostile_yaml_is_a_clean_error(tmp_path, sim_defs):
    bomb = tmp_path / "bomb.yaml"
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    lines += ["a%d: &a%d [*a%d, *a%d, *a%d, *a%d, *a%d, *a%d, *a%d, *a%d, *a%d, *a%d]" % ((i, i) + (i - 1,) * 10)
              for i in range(1, 9)]
    bomb.write_text("\n".join(lines) + "\nformat: 1\nroot: {wait: 1}\n")
    with pytest.raises(TreeErrors, match="expands to more than 200000 YAML nodes"):
        load_tree(str(bomb), sim_defs)
    deep = tmp_path / "deep.yaml"
    deep.write_text("format: 1\nroot: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(TreeErrors, match="nested too deeply|a node must be a mapping"):
        load_tree(str(deep), sim_defs)


def test_run_refuses_missing_required_inputs_before_starting_anything(capsys):
    env_tree = os.path.join(TREES, "search_room.yaml")
    assert bmtree(["run", "--sim", env_tree]) == 2
    assert "needs the input room: give them with --set KEY=VALUE" in capsys.readouterr().err
