"""``bmtree check``'s messages say where, what and how to fix it: misspelt keys at the reference, type
errors in the tree's words, one error for a misspelt option, warnings beside the errors."""
from __future__ import annotations

import pytest

from coordinator.cli import main as bmtree
from coordinator.errors import TreeErrors
from coordinator.language import load_tree


def check(tmp_path, capsys, text: str):
    """``bmtree check`` of a tree: its exit status and its stderr lines, file names shortened to t.yaml."""
    path = tmp_path / "t.yaml"
    path.write_text(text)
    status = bmtree(["check", str(path)])
    return status, [line.replace(str(path), "t.yaml") for line in capsys.readouterr().err.splitlines()]


# a key read but never written ------------------------------------------------------------------
MISSPELT = """format: 1
root:
  sequence:
    - call: vision.find_object
      inputs: {object: apple}
      outputs: {position: object_position}
    - call: navigation.approach
      name: approach it
      inputs:
        target: $object_positon
"""


def test_a_misspelt_key_is_reported_at_the_reference_as_written_by_no_node(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, MISSPELT)
    assert status == 2
    assert lines == ["t.yaml:10:17: reads 'object_positon', which no node writes and no input declares "
                     "(did you mean 'object_position'?)"]


def test_a_key_written_too_late_still_says_not_on_every_path(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
root:
  sequence:
    - call: speech.say
      inputs: {text: "I see the {thing}"}
    - set: {thing: apple}
""")
    assert status == 2
    assert lines == ["t.yaml:5:34: reads 'thing', which is not written on every path before this node "
                     "(written at line 6, but not before it on every path: write it earlier on every path or "
                     "declare it under 'inputs:')"]


@pytest.mark.parametrize("node,where", [
    ("check: 'objct == \"yes\"'", "6:15"),
    ("set: {a: 1, b: \"$(len(objct) + 1)\"}", "6:29"),
    ("retry: $objct\nchild: {wait: 1}", "6:14"),
    ("for_each: $objct\nas: x\nchild: {wait: 1}", "6:17"),
    ("repeat: 3\nuntil: 'objct == 1'\nchild: {wait: 1}", "7:15"),
])
def test_every_kind_points_at_the_reference_it_reads(tmp_path, capsys, node, where):
    status, lines = check(tmp_path, capsys, "format: 1\ninputs:\n  object: {default: apple}\nroot:\n  sequence:\n"
                                            "    - %s\n" % node.replace("\n", "\n      "))
    assert status == 2
    (line,) = lines
    assert line.startswith("t.yaml:%s: reads " % where), line
    assert "which no node writes and no input declares (did you mean" in line


# type errors in the tree's words ----------------------------------------------------------------
def test_type_errors_say_what_the_input_takes_and_what_it_got(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, """format: 1
root:
  sequence:
    - call: navigation.where_am_i
      outputs: {position: helper_position}
    - call: speech.say
      inputs:
        text: $helper_position
    - call: speech.listen
      inputs:
        seconds: five
    - call: navigation.approach
      inputs:
        target: {x: far, y: 1}
""")
    assert status == 2
    assert lines == [
        "t.yaml:8:15: input 'text' takes text (std_msgs/String), got $helper_position, which holds a mapping of "
        "fields x, y, z (geometry_msgs/Point)",
        "t.yaml:11:18: input 'seconds' takes a number (std_msgs/Float64), got 'five'",
        "t.yaml:14:17: input 'target' (geometry_msgs/Point): field x takes a number (float64), got 'far'"]
    assert not any("must be of type" in line or "float type" in line for line in lines)


def test_an_unknown_field_of_an_input_is_named_with_its_fields(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  call: navigation.approach\n"
                                            "  inputs: {target: {x: 1.0, yy: 2.0}}\n")
    assert status == 2
    assert lines == ["t.yaml:4:20: input 'target' (geometry_msgs/Point) has no field 'yy' (did you mean 'y'?)"]


# a misspelt option: one error -------------------------------------------------------------------
@pytest.mark.parametrize("text,expected", [
    ("  sequence:\n    chilren:\n      - wait: 1\n",
     ["t.yaml:4:5: unknown option 'chilren' for sequence (did you mean 'children'?)"]),
    ("  retry: 3\n  chlid: {wait: 1}\n", ["t.yaml:4:3: unknown option 'chlid' for retry (did you mean 'child'?)"]),
    ("  sequence:\n  children: [{wait: 1}]\n",
     ["t.yaml:4:3: unknown option 'children' for sequence: the children of sequence are its value, a list "
      "(sequence: [...]), or go under 'children:' inside it (sequence: {children: [...]})"]),
])
def test_a_misspelt_option_is_one_error_without_its_consequences(tmp_path, capsys, text, expected):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n" + text)
    assert status == 2
    assert lines == expected


def test_a_missing_children_list_is_still_one_error(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  parallel:\n    name: p\n")
    assert (status, lines) == (2, ["t.yaml:4:5: parallel needs 'children' (a list of nodes)"])


# warnings beside errors ---------------------------------------------------------------------------
def test_warnings_are_shown_with_the_errors(tmp_path, capsys):
    text = """format: 1
inputs:
  object: {default: apple}
root:
  sequence:
    - call: speech.say
      inputs: {text: "I look for $object"}
    - call: speech.sai
"""
    status, lines = check(tmp_path, capsys, text)
    assert status == 2
    assert lines == [
        "t.yaml:7:23: warning: '$object' inside text is sent as written, not replaced: write '{object}' to insert "
        "the value of object",
        "t.yaml:8:13: module 'speech' has no function 'sai' (did you mean 'say'?)"]
    path = tmp_path / "t.yaml"
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), {})
    assert all("warning" not in e.message for e in info.value.errors)   # errors alone: what callers count
    assert [e.message.startswith("warning: ") for e in info.value.warnings] == [True]


def test_an_include_argument_points_at_its_reference(tmp_path, capsys):
    (tmp_path / "sub.yaml").write_text("format: 1\ninputs:\n  room: {}\nroot:\n  call: navigation.go_to\n"
                                       "  inputs: {place: $room}\n")
    status, lines = check(tmp_path, capsys, "format: 1\ninputs:\n  rooms: {default: [kitchen]}\nroot:\n"
                                            "  include: sub.yaml\n  args: {room: \"{rom}\"}\n")
    assert status == 2
    assert lines == ["t.yaml:6:18: reads 'rom', which no node writes and no input declares (did you mean 'room'?)"]


def test_a_value_of_the_wrong_type_found_when_running_is_said_the_same_way(tmp_path, sim_defs):
    from coordinator.testing.kit import TreeTest

    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  sequence:\n    - set: {p: {x: 1.0}}\n    - call: speech.say\n"
                    "      inputs: {text: $p}\n")
    run = TreeTest(str(path), definitions=sim_defs).run()
    assert run.failed
    assert run.reason.endswith("speech.say: cannot build the call: input 'text' takes text (std_msgs/String), "
                               "got {'x': 1.0}"), run.reason


def test_check_says_what_a_file_is_when_it_is_no_tree(tmp_path, capsys):
    """A definition with a JSON mistake is said as JSON (it was a YAML syntax error), and a module's class
    file is not read as a tree (it was ``mapping values are not allowed here``)."""
    bad = tmp_path / "gripper.json"
    bad.write_text('{"Basic Module": "gripper",\n "Functions": [],}\n')
    cls = tmp_path / "gripper.py"
    cls.write_text("class Gripper:\n    def open(self): return {'success': True}\n")
    status = bmtree(["check", str(bad), str(cls)])
    lines = capsys.readouterr().err.splitlines()
    assert status == 2
    assert lines[0].startswith("%s:2:18: invalid JSON: " % bad), lines
    assert lines[1] == ("%s: not a tree or a module definition but a Python module's class; bmtree check reads "
                        "trees (.yaml) and module definitions (.json): bmtree-module --definition DEF.json "
                        "--class %s:CLASS checks the class against the definition before it connects to a "
                        "master" % (cls, cls)), lines


def test_check_of_cpp_source_says_what_checks_it(tmp_path, capsys):
    src = tmp_path / "gripper.cpp"
    src.write_text("#include <bmtree/basic_module.h>\n")
    assert bmtree(["check", str(src)]) == 2
    assert capsys.readouterr().err.strip() == (
        "%s: not a tree or a module definition but C++ source; bmtree check reads trees (.yaml) and module "
        "definitions (.json): the C++ module is checked against its definition when it runs: bmtree-bridge "
        "--definition DEF.json compares the topics and types its node declares (BM_info) with the definition's, "
        "and says what differs" % src)
