"""A tree input's value that a call input it is passed to could never take is found before running:
the tree's default and an include's argument by ``bmtree check`` (at the literal, naming the call
input and its field), a ``--set`` value by ``bmtree run`` before the first tick (exit 2), with the
call's own conversion and words. A key some node writes is not checked (it may hold another value by
then), nor ``$( … )`` expressions, and values the call takes (an integer for a float64, ``now`` for a
time, text from a template) are not reported."""
from __future__ import annotations

import json

import pytest

from coordinator.cli import main as bmtree
from coordinator.errors import TreeErrors
from coordinator.inputvalues import set_value_errors
from coordinator.language import load_tree
from modules.search import default_definitions

KIT = {"Basic Module": "kit", "Brief Description": "lists and small numbers", "Hardware Required": [], "Functions": [
    {"Name": "follow", "Exec-condition": "", "Description": "", "Output-params": [], "Input-params": [
        {"Name": "path", "Data-type": "geometry_msgs/PoseArray", "Description": ""}]},
    {"Name": "joints", "Exec-condition": "", "Description": "", "Output-params": [], "Input-params": [
        {"Name": "state", "Data-type": "sensor_msgs/JointState", "Description": ""}]},
    {"Name": "small", "Exec-condition": "", "Description": "", "Output-params": [], "Input-params": [
        {"Name": "n", "Data-type": "std_msgs/UInt8", "Description": ""},
        {"Name": "when", "Data-type": "std_msgs/Time", "Description": ""},
        {"Name": "where", "Data-type": "geometry_msgs/PointStamped", "Description": ""}]},
]}

APPROACH = """format: 1
inputs:
  x: {default: abc}
root:
  call: navigation.approach
  inputs: {target: {x: $x, y: 0.0}}
"""


@pytest.fixture
def kit(tmp_path):
    path = tmp_path / "kit.json"
    path.write_text(json.dumps(KIT))
    return str(path)


def check(tmp_path, capsys, text, *more, name="t.yaml", files=None):
    """``bmtree check`` of ``text`` (and of ``files``, written beside it): exit code and the lines it
    said, sorted, with the folder taken out of the paths."""
    for other, body in (files or {}).items():
        (tmp_path / other).write_text(body)
    path = tmp_path / name
    path.write_text(text)
    code = bmtree(["check", *more, str(path)])
    out = capsys.readouterr()   # (errors at one place come in no particular order)
    return code, sorted(line.replace(str(tmp_path) + "/", "") for line in (out.err + out.out).splitlines())


def test_a_default_that_a_call_input_cannot_take_is_an_error_of_check(tmp_path, capsys):
    code, said = check(tmp_path, capsys, APPROACH)
    assert code == 2
    assert said == ["t.yaml:3:16: input x's default 'abc' is text, but navigation.approach's target.x at "
                    "t.yaml:6:24 takes a number (float64)"]


def test_an_integer_for_a_float_now_for_a_time_templates_and_expressions_are_fine(tmp_path, capsys, kit):
    code, said = check(tmp_path, capsys, """format: 1
inputs:
  x: {default: 1}
  t: {default: now}
  n: {default: 200}
  words: {default: hello}
  bad: {default: abc}
root:
  sequence:
    - call: navigation.approach
      inputs: {target: {x: $x, y: $(len(words)), z: $bad}}
    - call: kit.small
      inputs: {n: $n, when: $t, where: {header: {stamp: $t}, point: {x: $x}}}
    - call: speech.say
      inputs: {text: "{x} and {n}"}
    - call: speech.say
      inputs: {text: $words}
""", "--modules", kit)
    assert code == 2   # only the one that does not fit:
    assert said == ["t.yaml:7:18: input bad's default 'abc' is text, but navigation.approach's target.z at "
                    "t.yaml:11:53 takes a number (float64)"]


def test_nested_fields_and_a_reference_into_the_default(tmp_path, capsys, kit):
    code, said = check(tmp_path, capsys, """format: 1
inputs:
  s: {default: abc}
  p: {default: {x: 1, y: abc}}
  n: {default: 300}
root:
  sequence:
    - call: kit.follow
      inputs: {path: {poses: [{position: {x: 1}}, {position: {x: 1, y: $s}}]}}
    - call: navigation.approach
      inputs: {target: {x: $p.y}}
    - call: kit.small
      inputs: {n: $n, when: 0, where: {point: $p}}
    - call: navigation.approach
      inputs: {target: {x: $s.z}}
""", "--modules", kit)
    assert code == 2
    assert said == sorted([
        "t.yaml:3:16: input s's default 'abc' is text, but kit.follow's path.poses[1].position.y at t.yaml:9:72 "
        "takes a number (float64)",
        "t.yaml:3:16: input s's default 'abc' cannot be read as $s.z by navigation.approach's target.x at "
        "t.yaml:15:28: s has no field 'z': it holds text, which has no fields",
        "t.yaml:4:16: input p's default makes $p.y 'abc', which is text, but navigation.approach's target.x at "
        "t.yaml:11:28 takes a number (float64)",
        "t.yaml:4:16: input p's default {x: 1, y: 'abc'} does not fit kit.small's where.point at t.yaml:13:47: "
        "field y takes a number (float64), got 'abc'",
        "t.yaml:5:16: input n's default 300 is a whole number, but kit.small's n at t.yaml:13:19 takes a whole "
        "number from 0 to 255 (std_msgs/UInt8)",
    ])


def test_a_list_element(tmp_path, capsys, kit):
    code, said = check(tmp_path, capsys, """format: 1
inputs:
  joint: {default: 5}
  angle: {default: 0}
root:
  call: kit.joints
  inputs: {state: {name: [$joint, elbow], position: [$angle, 1.5]}}
""", "--modules", kit)
    assert code == 2
    assert said == ["t.yaml:3:20: input joint's default 5 is a whole number, but kit.joints's state.name[0] at "
                    "t.yaml:7:27 takes text (string) (for text, write it in quotes)"]


def test_a_one_field_message_takes_what_the_call_takes(tmp_path, capsys):
    """``text: $t`` for a std_msgs/String: the call refuses a number (it is not made text), as it would
    when built."""
    code, said = check(tmp_path, capsys, "format: 1\ninputs:\n  t: {default: 5}\nroot:\n  call: speech.say\n"
                                         "  inputs: {text: $t}\n")
    assert code == 2
    assert said == ["t.yaml:3:16: input t's default 5 is a whole number, but speech.say's text at t.yaml:6:18 "
                    "takes text (std_msgs/String) (for text, write it in quotes)"]


@pytest.mark.parametrize("writer", [
    "- set: {x: 1.5}",
    "- call: vision.find_object\n  inputs: {object: apple}\n  outputs: {position: x}",
    "- force_success: {set: {x: 1.5}}",
])
def test_a_key_a_node_writes_is_not_checked(tmp_path, capsys, writer):
    """A node may write the key before the call (here, or on some paths only): it may hold another value
    by then."""
    nodes = "".join("    " + line + "\n" for line in writer.split("\n"))
    code, said = check(tmp_path, capsys, "format: 1\ninputs:\n  x: {default: abc}\n  y: {default: abc}\nroot:\n"
                       "  sequence:\n" + nodes + "    - call: navigation.approach\n      inputs: {target: {x: $x, y: $y}}\n")
    assert code == 2   # y, which no node writes, only
    assert [line.split(": ", 1)[1].split(",")[0] for line in said] == ["input y's default 'abc' is text"]


def test_a_null_default_is_not_checked(tmp_path, capsys):
    """null is the usual 'not given' of an input, which the tree may look at before the call."""
    code, said = check(tmp_path, capsys, """format: 1
inputs:
  target: {default: null}
root:
  selector:
    - sequence:
        - check: 'target != null'
        - call: navigation.approach
          inputs: {target: $target}
    - call: speech.say
      inputs: {text: no target}
""")
    assert (code, said) == (0, ["t.yaml: ok"])


SUB = """format: 1
inputs:
  tx: {}
  ty: {default: 0.0}
root:
  call: navigation.approach
  inputs: {target: {x: $tx, y: $ty}}
"""


def test_include_arguments_and_the_values_they_pass_on(tmp_path, capsys):
    code, said = check(tmp_path, capsys, """format: 1
inputs:
  x: {default: abc}
root:
  sequence:
    - include: sub.yaml
      args: {tx: $x}
    - include: sub.yaml
      args: {tx: 1, ty: oops}
""", name="main.yaml", files={"sub.yaml": SUB})
    assert code == 2
    assert said == [
        "main.yaml:3:16: input x's default 'abc', passed on as argument 'tx' of the include at line 6, is text, "
        "but navigation.approach's target.x at sub.yaml:7:24 takes a number (float64)",
        "main.yaml:9:25: include argument ty: 'oops' is text, but navigation.approach's target.y at sub.yaml:7:32 "
        "takes a number (float64)",
    ]


def test_a_subtrees_default_and_an_input_passed_on_as_itself(tmp_path, capsys):
    """``args: {x: $x}`` does not change the key: the caller's value is followed into the subtree."""
    sub = ("format: 1\ninputs:\n  x: {default: 1.0}\n  z: {default: high}\nroot:\n  call: navigation.approach\n"
           "  inputs: {target: {x: $x, z: $z}}\n")
    code, said = check(tmp_path, capsys, "format: 1\ninputs:\n  x: {default: far}\nroot:\n  include: sub.yaml\n"
                                         "  args: {x: $x}\n", name="main.yaml", files={"sub.yaml": sub})
    assert code == 2
    assert said == [
        "main.yaml:3:16: input x's default 'far', passed on as argument 'x' of the include at line 5, is text, but "
        "navigation.approach's target.x at sub.yaml:7:24 takes a number (float64)",
        "sub.yaml:4:16: input z's default 'high' is text, but navigation.approach's target.z at sub.yaml:7:31 "
        "takes a number (float64)",
    ]


# bmtree run --set ------------------------------------------------------------------------------------------
def test_set_values_are_checked_like_the_defaults(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text(APPROACH.replace("{default: abc}", "{default: 1.5}"))
    tree = load_tree(str(path), default_definitions(), given={"x"})
    assert set_value_errors(tree, {"x": "abc"}) == [
        "--set x: 'abc' is text, but navigation.approach's target.x at %s:6:24 takes a number (float64)" % path]
    assert set_value_errors(tree, {"x": 2}) == [] and set_value_errors(tree, {}) == []
    path.write_text("format: 1\ninputs:\n  t: {}\nroot:\n  call: speech.say\n  inputs: {text: $t}\n")
    tree = load_tree(str(path), default_definitions(), given={"t"})
    assert set_value_errors(tree, {"t": 5}) == [
        "--set t: 5 is a whole number, but speech.say's text at %s:6:18 takes text (std_msgs/String) (for text, "
        "quote it: --set t='\"5\"')" % path]


def test_a_default_the_run_sets_is_not_checked_but_its_set_value_is(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text(APPROACH)
    with pytest.raises(TreeErrors):
        load_tree(str(path), default_definitions())
    tree = load_tree(str(path), default_definitions(), given={"x"})   # --set x=…: the default is not used
    assert set_value_errors(tree, {"x": 0.5}) == []


def test_run_refuses_a_set_value_before_anything_starts(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("ROS_MASTER_URI", "http://127.0.0.1:9/")   # nothing listens there
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\ninputs:\n  x: {default: 1.5}\nroot:\n  sequence:\n    - call: speech.say\n"
                    "      inputs: {text: going}\n    - call: navigation.approach\n      inputs: {target: {x: $x}}\n")
    assert bmtree(["run", "--sim", "--no-record", "--set", "x=abc", str(path)]) == 2
    out = capsys.readouterr()
    assert out.err.strip() == ("error: --set x: 'abc' is text, but navigation.approach's target.x at %s:9:28 takes "
                               "a number (float64)" % path)
    assert "starting the simulated robot" not in out.out and "running" not in out.out


def test_set_values_for_counts_and_durations_are_checked_before_the_run(tmp_path):
    """A count or duration a --set value could never be (retry: $n, timeout: $secs) was found mid-run, after the
    robot had started and its cleanup had run: exit 1, not 2."""
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\ninputs:\n  secs: {default: 5}\n  n: {default: 2}\nroot:\n  retry: $n\n  child:\n"
                    "    timeout: $secs\n    child: {wait: 1}\n")
    tree = load_tree(str(path), default_definitions(), given={"secs", "n"})
    assert set_value_errors(tree, {"secs": "abc", "n": -2}) == [
        "%s:6:10: count of retry $n is -2 (--set n), not an integer >= 1: give --set n a value that is one" % path,
        "%s:8:14: duration of timeout $secs is 'abc' (--set secs), not a positive number of seconds: give --set secs "
        "a value that is one" % path]
    assert set_value_errors(tree, {"secs": 3, "n": 1}) == []


# for_each's elements ---------------------------------------------------------------------------------------
WAITS = """format: 1
inputs:
  waits: {default: [0.2, "slow"]}
root:
  for_each: $waits
  as: d
  child:
    call: speech.listen
    inputs: {seconds: $d}
"""


def test_each_element_of_a_for_each_list_is_checked_against_the_call_input_it_is_passed_to(tmp_path, capsys):
    """A C++ audit's default [0.2, "slow"] passed check and the second call was refused when built."""
    code, said = check(tmp_path, capsys, WAITS)
    assert code == 2
    assert said == ["t.yaml:3:20: element 1 of input waits's default 'slow' is text, but speech.listen's seconds at "
                    "t.yaml:9:23 takes a number (std_msgs/Float64)"]
    code, said = check(tmp_path, capsys, WAITS.replace("for_each: $waits", 'for_each: [0.2, 1, "slow"]'))
    assert code == 2
    assert said == ["t.yaml:5:13: element 2 of the for_each's list 'slow' is text, but speech.listen's seconds at "
                    "t.yaml:9:23 takes a number (std_msgs/Float64)"]
    assert check(tmp_path, capsys, WAITS.replace('"slow"', "0.5")) == (0, ["t.yaml: ok"])
    # the as key written elsewhere too may hold another value by then: not followed
    other = WAITS.replace("  child:\n    call:", "  child:\n   sequence:\n    - set: {d: 1.0}\n    - call:").replace(
        "    inputs: {seconds", "      inputs: {seconds")
    assert check(tmp_path, capsys, other)[0] == 0


def test_set_list_elements_are_checked_like_the_defaults(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text(WAITS.replace('"slow"', "0.5"))
    tree = load_tree(str(path), default_definitions(), given={"waits"})
    assert set_value_errors(tree, {"waits": [1, "x"]}) == [
        "element 1 of --set waits: 'x' is text, but speech.listen's seconds at %s:9:23 takes a number "
        "(std_msgs/Float64)" % path]
