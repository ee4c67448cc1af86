"""One text for "this value does not fit this ROS type", wherever the mistake is caught: ``bmtree check``,
a scenario (a mock's outputs, a call built while the tree runs), a module runtime answering a call,
``bmtree control``'s set, and ``comm.rostypes.to_message`` itself."""
from __future__ import annotations

import json
import math
import threading
import types

import pytest
import yaml

from comm import FunctionResult, ProtocolError, ValueMisfit, rostypes
from comm.rostypes import message_from_json, resolve_type, to_message
from comm.typewords import misfit_text, said_of, type_words
from coordinator.cli import main as bmtree
from modules.definition import load_definitions
from modules.runtime import BasicModule, ModuleServer

PARAMS = [("target", "geometry_msgs/Point"), ("speed", "std_msgs/UInt8"), ("path", "geometry_msgs/Polygon"),
          ("seconds", "std_msgs/Float64"), ("pose", "geometry_msgs/PoseWithCovariance"),
          ("levels", "std_msgs/Int16MultiArray")]
GOOD = {"target": "{x: 1}", "speed": "3", "path": "{points: []}", "seconds": "1.0", "pose": "{}",
        "levels": "{data: [1]}"}
TYPES = dict(PARAMS)

# (input, the value as a tree writes it, the same value on the wire, what is wrong said after the input)
MISTAKES = [
    ("seconds", "five", {"data": "five"}, "takes a number (std_msgs/Float64), got 'five'"),
    ("target", "{x: far, y: 1}", {"x": "far", "y": 1},
     "(geometry_msgs/Point): field x takes a number (float64), got 'far'"),
    ("target", "{x: 1, yy: 2}", {"x": 1, "yy": 2}, "(geometry_msgs/Point) has no field 'yy' (did you mean 'y'?)"),
    ("speed", "300", {"data": 300}, "takes a whole number from 0 to 255 (std_msgs/UInt8), got 300"),
    ("path", "{points: [{x: 1}, {x: b}]}", {"points": [{"x": 1}, {"x": "b"}]},
     "(geometry_msgs/Polygon): field points[1].x takes a number (float32), got 'b'"),
    ("pose", "{covariance: [0, 0, 0]}", {"covariance": [0, 0, 0]},
     "(geometry_msgs/PoseWithCovariance): field covariance takes a list of 36 items (float64[36]), got 3"),
    ("levels", "{data: [1, 40000]}", {"data": [1, 40000]},
     "(std_msgs/Int16MultiArray): field data[1] takes a whole number from -32768 to 32767 (int16), got 40000"),
]
IDS = [m[3] for m in MISTAKES]


@pytest.fixture
def arm(tmp_path):
    """A module ``arm`` whose function ``move`` takes PARAMS and answers them as its outputs."""
    params = [{"Name": n, "Data-type": t, "Description": ""} for n, t in PARAMS]
    path = tmp_path / "arm.json"
    path.write_text(json.dumps({"Basic Module": "arm", "Brief Description": "", "Hardware Required": [],
                                "Functions": [{"Name": "move", "Exec-condition": "", "Description": "",
                                               "Input-params": params, "Output-params": params}]}))
    return str(path)


def _inputs(name, value):
    return "".join("    %s: %s\n" % (n, value if n == name else GOOD[n]) for n, _ in PARAMS)


@pytest.mark.parametrize("name,written,wire,said", MISTAKES, ids=IDS)
def test_bmtree_check_says_it(tmp_path, capsys, arm, name, written, wire, said):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  call: arm.move\n  inputs:\n" + _inputs(name, written))
    assert bmtree(["check", "--modules", arm, str(path)]) == 2
    line = "t.yaml:%d:" % (4 + [n for n, _ in PARAMS].index(name) + 1)
    assert capsys.readouterr().err.replace(str(path), "t.yaml").splitlines() == [
        line + "%d: input %r %s" % (7 + len(name), name, said)]


@pytest.mark.parametrize("name,written,wire,said", MISTAKES, ids=IDS)
def test_a_scenario_says_it_of_a_mocks_output(tmp_path, capsys, arm, name, written, wire, said):
    (tmp_path / "t.yaml").write_text("format: 1\nroot:\n  call: arm.move\n  inputs:\n" + _inputs("", ""))
    scenarios = tmp_path / "s.yaml"
    scenarios.write_text("tree: t.yaml\nscenarios:\n  - name: x\n    mocks:\n      arm.move:\n        succeed:\n"
                         "          %s: %s\n" % (name, written))
    assert bmtree(["test", "--modules", arm, str(scenarios)]) == 2
    assert capsys.readouterr().err.replace(str(scenarios), "s.yaml").splitlines() == [
        "s.yaml:7:%d: arm.move output %r %s" % (13 + len(name), name, said)]


@pytest.mark.parametrize("name,written,wire,said", MISTAKES, ids=IDS)
def test_a_scenario_says_it_of_a_call_built_while_the_tree_runs(tmp_path, capsys, arm, name, written, wire, said):
    inputs = _inputs(name, "$given")
    (tmp_path / "t.yaml").write_text("format: 1\ninputs:\n  given: {default: %s}\nroot:\n  call: arm.move\n"
                                     "  inputs:\n%s" % (GOOD[name], inputs))
    scenarios = tmp_path / "s.yaml"
    scenarios.write_text("tree: t.yaml\nscenarios:\n  - name: x\n    inputs: {given: %s}\n"
                         "    expect: {status: success}\n" % written)
    assert bmtree(["test", "--modules", arm, str(scenarios)]) == 1
    out = capsys.readouterr().out
    assert "(arm.move: cannot build the call: input %r %s) at %s:5:3\n" % (name, said, tmp_path / "t.yaml") in out


class _Arm(BasicModule):
    def move(self, **inputs):
        return inputs


@pytest.mark.parametrize("name,written,wire,said", MISTAKES, ids=IDS)
def test_a_module_runtime_answers_it(tmp_path, arm, name, written, wire, said):
    answers = []
    done = threading.Event()

    def answer(text):
        answers.append(FunctionResult.decode(text))
        done.set()

    server = ModuleServer(load_definitions([arm])["arm"], _Arm(), answer, lambda text: None)
    values = {n: wire if n == name else _wire(GOOD[n]) for n, _ in PARAMS}
    server.handle_call(json.dumps({"basic_mod": "arm", "function": "move", "call_id": "c1", "names": list(values),
                                   "rostypes": [TYPES[n] for n in values],
                                   "msgs": [json.dumps(v) for v in values.values()]}))
    assert done.wait(5)
    (result,) = answers
    index = list(values).index(name)
    assert (result.status, result.error) == ("rejected", "bad inputs: arm.move: input %r %s (msgs[%d])" % (
        name, said, index))


def _wire(written):
    """A good value as it travels: a mapping of fields."""
    value = yaml.safe_load(written)
    return value if isinstance(value, dict) else {"data": value}


def test_a_module_runtime_says_it_of_a_legacy_call_by_position(arm):
    answers = []
    server = ModuleServer(load_definitions([arm])["arm"], _Arm(), answers.append, lambda text: None)
    values = [_wire(GOOD[n]) for n, _ in PARAMS]
    values[3] = {"data": "five"}
    server.handle_call(json.dumps({"basic_mod": "arm", "function": "move", "call_id": "c1",
                                   "rostypes": [t for _, t in PARAMS], "msgs": [json.dumps(v) for v in values]}))
    (result,) = [FunctionResult.decode(a) for a in answers]
    assert result.error == "bad inputs: arm.move: msgs[3] takes a number (std_msgs/Float64), got 'five'"


@pytest.mark.parametrize("name,written,wire,said", MISTAKES, ids=IDS)
def test_bmtree_control_set_says_it(name, written, wire, said):
    from coordinator.control import Controller

    old = resolve_type(TYPES[name])()
    control = Controller(True, lambda *a: None)
    ctx = types.SimpleNamespace(blackboard={name: old}, observers=[],
                                write=lambda k, v: ctx.blackboard.__setitem__(k, v))
    control.ctx, control.root = ctx, object()
    assert control._apply({"command": "set", "key": name, "value": written}) == (False, "%s %s" % (name, said))
    assert ctx.blackboard[name] is old


@pytest.mark.parametrize("name,written,wire,said", MISTAKES, ids=IDS)
def test_to_message_says_it(name, written, wire, said):
    rostype = TYPES[name]
    for value, scalar in ((yaml.safe_load(written), True), (wire, False)):
        with pytest.raises(ValueMisfit) as info:
            to_message(rostype, value, allow_scalar=scalar)
        assert (info.value.said, str(info.value), info.value.rostype) == (said, "value " + said, rostype)
        assert said_of("input %r" % name, info.value) == "input %r %s" % (name, said)
    with pytest.raises(ValueMisfit) as info:
        message_from_json(rostype, json.dumps(wire))
    assert info.value.said == said


@pytest.mark.parametrize("rostype,value,scalar,said", [
    ("geometry_msgs/Point", {"q": 1}, False, "(geometry_msgs/Point) has no field 'q' (its fields: x, y, z)"),
    ("geometry_msgs/Pose", {"position": {"xx": 1}}, False,
     "(geometry_msgs/Pose): field position (geometry_msgs/Point) has no field 'xx' (did you mean 'x'?)"),
    ("geometry_msgs/Pose", {"position": 5}, False,
     "(geometry_msgs/Pose): field position takes a mapping of fields x, y, z (geometry_msgs/Point), got 5"),
    ("geometry_msgs/Point", [1, 2], True, "takes a mapping of fields x, y, z (geometry_msgs/Point), got [1, 2]"),
    ("std_msgs/Float64", 5, False, "takes a mapping of fields data (std_msgs/Float64), got 5"),
    ("std_msgs/Float64", {"dat": 1}, True, "(std_msgs/Float64) has no field 'dat' (did you mean 'data'?)"),
    ("std_msgs/String", {"greeting": "hi"}, True, "takes text (std_msgs/String), got {'greeting': 'hi'}"),
    ("std_msgs/Int32", 1 << 40, True,
     "takes a whole number from -2147483648 to 2147483647 (std_msgs/Int32), got 1099511627776"),
    ("std_msgs/Int32", 1.5, True, "takes a whole number (std_msgs/Int32), got 1.5"),
    ("std_msgs/Bool", "yes", True, "takes true or false (std_msgs/Bool), got 'yes'"),
    ("std_msgs/Float32", 1e300, True, "takes a number from -3.4e38 to 3.4e38 (std_msgs/Float32), got 1e+300"),
    ("std_msgs/Header", {"stamp": {"secs": "a"}}, False,
     "(std_msgs/Header): field stamp.secs takes a whole number (uint32), got 'a'"),
    ("std_msgs/Header", {"stamp": True}, False,
     "(std_msgs/Header): field stamp takes seconds, {secs, nsecs} or now (time), got true (a yes/no)"),
    ("std_msgs/Header", {"stamp": "yesterday"}, False,
     "(std_msgs/Header): field stamp takes seconds, {secs, nsecs} or now (time), got 'yesterday'"),
    ("std_msgs/Duration", "5s", True, "takes seconds, {secs, nsecs} (std_msgs/Duration), got '5s'"),
    ("std_msgs/Time", -1, True, "takes a time from 0 seconds (std_msgs/Time), got -1"),
    ("geometry_msgs/Polygon", [{"x": "b"}], True,
     "(geometry_msgs/Polygon): field points[0].x takes a number (float32), got 'b'"),
    ("std_msgs/Empty", 5, True, "takes an empty mapping (std_msgs/Empty), got 5"),
    # genpy would pack a mistyped flag as 1 or 0: refused for every number field (the converter took it)
    ("std_msgs/Float64", True, True, "takes a number (std_msgs/Float64), got true (a yes/no)"),
    ("std_msgs/Int32", False, True, "takes a whole number (std_msgs/Int32), got false (a yes/no)"),
    ("geometry_msgs/Point", {"x": 1, "y": False}, False,
     "(geometry_msgs/Point): field y takes a number (float64), got false (a yes/no)"),
    ("geometry_msgs/Polygon", [{"x": True}], True,
     "(geometry_msgs/Polygon): field points[0].x takes a number (float32), got true (a yes/no)"),
    ("std_msgs/String", "x" * 80, False, "takes a mapping of fields data (std_msgs/String), got '%s..." % ("x" * 56)),   # long values are cut
])
def test_to_message_says_where_and_what(rostype, value, scalar, said):
    with pytest.raises(ValueMisfit) as info:
        to_message(rostype, value, allow_scalar=scalar)
    assert info.value.said == said


def test_the_words_are_the_converters_when_no_reason_is_found(monkeypatch):
    monkeypatch.setattr(rostypes, "misfit_text", lambda *a, **k: "")
    with pytest.raises(ProtocolError) as info:
        to_message("std_msgs/Float64", "five", allow_scalar=True)
    assert not isinstance(info.value, ValueMisfit)
    assert str(info.value) == "std_msgs/Float64: field data must be float type"
    assert said_of("input 'seconds'", info.value) == "input 'seconds': std_msgs/Float64: field data must be float type"
    with pytest.raises(ProtocolError, match="^is not valid JSON for geometry_msgs/Point: field x must be float type$"):
        message_from_json("geometry_msgs/Point", '{"x": "a"}')


def test_a_valid_value_is_never_walked(monkeypatch):
    def walked(*args, **kwargs):
        raise AssertionError("walked a valid value")

    monkeypatch.setattr(rostypes, "misfit_text", walked)
    assert to_message("std_msgs/Float64", 2, allow_scalar=True).data == 2
    assert to_message("geometry_msgs/Pose", {"position": {"x": 1.0}}).position.x == 1.0
    assert message_from_json("std_msgs/Int16MultiArray", '{"data": [1, -32768]}').data == [1, -32768]


def test_a_reference_is_said_in_its_own_words():
    assert misfit_text("std_msgs/String", resolve_type("geometry_msgs/Point")(), got="$p, which holds %s" % (
        type_words("geometry_msgs/Point"))) == "takes text (std_msgs/String), got $p, which holds a mapping of fields x, y, z"
    assert misfit_text("geometry_msgs/Point", {"x": 1.0}) == ""


@pytest.mark.parametrize("rostype,value,said", [
    ("std_msgs/Float64", 10 ** 400, "takes a number from -1.8e308 to 1.8e308 (std_msgs/Float64), got a whole number of "
                                     "401 digits"),
    ("std_msgs/Float32", -10 ** 400, "takes a number from -3.4e38 to 3.4e38 (std_msgs/Float32), got a negative whole "
                                     "number of 401 digits"),
    ("std_msgs/Int32", 10 ** 400, "takes a whole number from -2147483648 to 2147483647 (std_msgs/Int32), got a whole "
                                  "number of 401 digits"),
    ("geometry_msgs/Point", {"x": 10 ** 400}, "(geometry_msgs/Point): field x takes a number from -1.8e308 to 1.8e308 "
                                              "(float64), got a whole number of 401 digits"),
])
def test_a_whole_number_past_a_types_range_is_said_by_its_size(rostype, value, said):
    """It was genpy's struct.error text followed by all 401 digits (and an OverflowError for a Float32)."""
    with pytest.raises(ValueMisfit) as info:
        to_message(rostype, value, allow_scalar=True)
    assert str(info.value) == "value " + said
    assert math.isnan(to_message("std_msgs/Float32", float("nan"), allow_scalar=True).data)  # NaN and inf still pass
    assert to_message("std_msgs/Float32", float("-inf"), allow_scalar=True).data == float("-inf")
