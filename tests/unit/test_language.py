"""The tree language: every node kind and option, references, data flow, and broken files."""
from __future__ import annotations

import json
import os

import pytest

from coordinator.cli import main as bmtree
from coordinator.errors import TreeErrors
from coordinator.expr import Expr, ExprError
from coordinator.language import (
    MAX_INCLUDE_DEPTH,
    MAX_REPEATED_NODES,
    MAX_TREE_DEPTH,
    load_tree,
    used_modules,
    walk,
)
from coordinator.yamlsrc import MAX_BYTES
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
    assert "many.yaml:7:15: reads 'x'" in err and "Traceback" not in err


EVERY_KIND = """
format: 1
name: every kind
inputs:
  who: {default: Ana}
  count: {}
root:
  sequence:
    name: all
    memory: true
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


def test_an_unknown_module_is_one_error_that_says_how_to_give_its_definition(tmp_path, sim_defs):
    path = tmp_path / "grip.yaml"
    path.write_text("format: 1\nroot:\n  sequence:\n    - call: gripper.open\n      outputs: {width: w}\n"
                    "    - check: 'w > 0'\n    - call: speech.shout\n      outputs: {volume: v}\n"
                    "    - check: 'v > 1'\n")
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), sim_defs)
    assert [str(e) for e in info.value.errors] == [
        "%s:4:13: unknown module 'gripper' (known: battery, navigation, speech, vision; give your module's definition "
        "with --modules FILE.json or a folder of them, or source the catkin workspace of the package that exports "
        "it)" % path,
        "%s:7:13: module 'speech' has no function 'shout' (functions: say, listen)" % path]


def test_every_node_kind_and_option(tmp_path, sim_defs):
    path = tmp_path / "every.yaml"
    path.write_text(EVERY_KIND.replace("../trees/search_room.yaml", os.path.join(TREES, "search_room.yaml")))
    tree = load_tree(str(path), sim_defs)
    kinds = {n.kind for n in walk(tree.root)}
    assert kinds == {"sequence", "parallel", "call", "wait_event", "selector", "inverter", "check", "force_failure",
                     "wait", "retry", "repeat", "timeout", "force_success", "recall", "set", "include"}
    root = tree.root
    assert root.name == "all" and root.spec.memory is True and root.children[2].spec.memory is False
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


def test_render_draws_a_switch_with_its_case_values_and_no_glyph_the_fonts_lack(tmp_path):
    dot = tmp_path / "invite.dot"
    assert bmtree(["render", os.path.join(TREES, "invite_to_dining_room.yaml"), "-o", str(dot)]) == 0
    text = dot.read_text()
    assert '"act on the answer" [label="act on the answer\\nswitch $(lower(answer))", shape=diamond' in text, text
    assert '"act on the answer" -> "\'yes\' → answered yes";' in text and "default → force_failure" in text, text
    assert "Ⓜ" not in text


def test_render_labels_say_what_names_hide_and_no_uniqueness_stars(tmp_path):
    """py_trees makes repeated names unique with '*' and shows names only: a label is the node's
    own name, then what a name hides (a named node's kind and parameters, a call's inputs)."""
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nname: t\nroot:\n  sequence:\n"
                    "    - call: speech.say\n      inputs: {text: hi}\n"
                    "    - call: speech.say\n      inputs: {text: $who}\n"
                    "    - timeout: 300\n      name: follow until stop\n"
                    "      child: {call: speech.say, inputs: {text: x}}\n"
                    "inputs:\n  who: {default: Ana}\n")
    dot = tmp_path / "t.dot"
    assert bmtree(["render", str(tree), "-o", str(dot)]) == 0
    text = dot.read_text()
    assert '"speech.say" [label="speech.say\\ntext: \'hi\'"' in text, text
    assert '"speech.say*2" [label="speech.say\\ntext: $who"' in text, text
    assert '[label="follow until stop\\ntimeout 300s"' in text, text
    assert 'label="speech.say*' not in text


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


SAY = "{call: speech.say, inputs: {text: hi}}"


def _chain_file(path, levels, inner=SAY, name="t"):
    """A tree file whose root nests ``levels`` inverters around ``inner``."""
    path.write_text("format: 1\nname: %s\nroot: %s%s%s\n" % (name, "{inverter: " * levels, inner, "}" * levels))
    return str(path)


def test_a_tree_deeper_than_the_limit_is_an_error_at_the_node_that_crosses_it(tmp_path, sim_defs, capsys):
    deep = _chain_file(tmp_path / "d.yaml", 250)   # crashed the parser with RecursionError
    with pytest.raises(TreeErrors) as info:
        load_tree(deep, sim_defs)
    column = len("root: ") + 1 + MAX_TREE_DEPTH * len("{inverter: ")
    assert [str(e) for e in info.value.errors] == [
        "%s:3:%d: the tree nests deeper than %d levels" % (deep, column, MAX_TREE_DEPTH)]
    assert bmtree(["check", deep]) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_a_tree_at_the_depth_limit_builds_runs_and_displays(tmp_path):
    """py_trees ticks, visits, stops and displays recursively, one level at a time: the limit must fit."""
    import py_trees

    from coordinator.cli import offline_tree
    from coordinator.testing.kit import TreeTest

    kinds = ["{inverter: %s}", "{sequence: [%s]}", "{force_failure: %s}", "{timeout: 50, child: %s}",
             "{selector: [%s]}", "{force_success: %s}", "{parallel: [%s]}", "{repeat: 1, child: %s}"]
    body = SAY
    for i in range(MAX_TREE_DEPTH - 1):
        body = kinds[i % len(kinds)] % body
    path = tmp_path / "limit.yaml"
    path.write_text("format: 1\nname: at the limit\nroot: %s\n" % body)
    test = TreeTest(str(path))
    run = test.run()
    assert run.said() == ["hi"] and run.status in (py_trees.common.Status.SUCCESS, py_trees.common.Status.FAILURE)
    _, root = offline_tree(str(path), test.definitions)
    depth, b = 1, root
    while b.children:
        depth, b = depth + 1, b.children[0]
    assert depth == MAX_TREE_DEPTH
    assert py_trees.display.unicode_tree(root).count("\n") >= MAX_TREE_DEPTH - 1
    assert py_trees.display.dot_tree(root, collapse_decorators=False).to_string()


def test_includes_count_toward_the_depth_limit(tmp_path, sim_defs):
    sub = _chain_file(tmp_path / "sub.yaml", 59, name="sub")   # 60 levels
    # read first at level 2 (fits), then included again below 50 inverters: 52 + 60 levels
    top = tmp_path / "top.yaml"
    top.write_text("format: 1\nname: top\nroot:\n  sequence:\n    - include: sub.yaml\n    - %s{include: sub.yaml}%s\n"
                   % ("{inverter: " * 50, "}" * 50))
    with pytest.raises(TreeErrors) as info:
        load_tree(str(top), sim_defs)
    assert [str(e) for e in info.value.errors] == [
        "%s:6:%d: the tree nests deeper than %d levels: sub.yaml adds 60 levels below level 52"
        % (top, 7 + 50 * len("{inverter: ") + len("{include: "), MAX_TREE_DEPTH)]
    # read first where it does not fit: the node that crosses is in sub.yaml
    top.write_text("format: 1\nname: top\nroot: %s{include: sub.yaml}%s\n" % ("{inverter: " * 50, "}" * 50))
    with pytest.raises(TreeErrors) as info:
        load_tree(str(top), sim_defs)
    assert [str(e) for e in info.value.errors] == [
        "%s:3:%d: the tree nests deeper than %d levels (counting the files that include this one)"
        % (sub, 7 + 49 * len("{inverter: "), MAX_TREE_DEPTH)]


def test_a_long_include_chain_is_an_error_at_the_include_that_crosses_the_limit(tmp_path, sim_defs, capsys):
    for i in range(200):   # 200 files, each including the next: a RecursionError before
        inner = "{include: c%d.yaml}" % (i + 1) if i < 199 else SAY
        (tmp_path / ("c%d.yaml" % i)).write_text("format: 1\nname: c%d\nroot: %s\n" % (i, inner))
    with pytest.raises(TreeErrors) as info:
        load_tree(str(tmp_path / "c0.yaml"), sim_defs)
    last = MAX_INCLUDE_DEPTH - 1
    assert [str(e) for e in info.value.errors] == [
        "%s:3:17: includes nest deeper than %d files: this one makes a chain of %d "
        "(c0.yaml -> c1.yaml -> … -> c%d.yaml -> c%d.yaml)" % (tmp_path / ("c%d.yaml" % last), MAX_INCLUDE_DEPTH,
                                                              MAX_INCLUDE_DEPTH + 1, last, last + 1)]
    assert load_tree(str(tmp_path / ("c%d.yaml" % (200 - MAX_INCLUDE_DEPTH))), sim_defs).root.kind == "include"
    assert bmtree(["check", str(tmp_path / "c0.yaml")]) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_repeated_includes_cannot_blow_the_tree_up(tmp_path, sim_defs):
    for i in range(7):   # each file includes the next ten times: 10^6 copies of the last one's leaf
        root = "{sequence: [%s]}" % ", ".join(["{include: f%d.yaml}" % (i + 1)] * 10) if i < 6 else SAY
        (tmp_path / ("f%d.yaml" % i)).write_text("format: 1\nname: f%d\nroot: %s\n" % (i, root))
    with pytest.raises(TreeErrors, match="includes of files already included expand the tree by more than %d "
                                         "nodes" % MAX_REPEATED_NODES) as info:
        load_tree(str(tmp_path / "f0.yaml"), sim_defs)
    assert len(info.value.errors) == 1


def test_file_size_cap_devices_and_bad_characters_are_one_line_positioned_errors(tmp_path, sim_defs):
    big = tmp_path / "big.yaml"
    big.write_bytes(b"format: 1\nroot: {wait: 0}\n#" + b"x" * MAX_BYTES)
    for path, message in ((str(big), "%s:1:1: cannot read %s: larger than 16 MiB" % (big, big)),
                          ("/dev/zero", "/dev/zero:1:1: cannot read /dev/zero: not a regular file")):
        with pytest.raises(TreeErrors) as info:
            load_tree(path, sim_defs)
        assert str(info.value) == message
    ctl = tmp_path / "ctl.yaml"
    ctl.write_bytes(b'format: 1\nname: x\nroot: {call: speech.say, inputs: {text: "a\x01b"}}\n')
    with pytest.raises(TreeErrors) as info:
        load_tree(str(ctl), sim_defs)
    assert str(info.value) == ("%s:3:43: YAML error: unacceptable character #x0001: control characters are not "
                               "allowed" % ctl)
    sub = tmp_path / "sub.yaml"   # in an included file: where it is in that file
    sub.write_bytes(b"format: 1\nname: sub\n\n# \xc3\xa9\xc3\xa9\nroot: {call: speech.say, inputs: {text: \"\xe9\"}}\n")
    top = tmp_path / "top.yaml"
    top.write_text("format: 1\nname: top\nroot: {include: sub.yaml}\n")
    with pytest.raises(TreeErrors) as info:
        load_tree(str(top), sim_defs)
    assert str(info.value) == "%s:5:42: not UTF-8 text: byte 0xe9" % sub
