"""Wire protocol v2: typed messages, value conversion, the legacy commBM drop-in."""
from __future__ import annotations

import json
import re

import pytest
from geometry_msgs.msg import Point
from std_msgs.msg import Bool, Float64, String

from comm import (
    BlackboardAnswer,
    BlackboardRequest,
    CancelRequest,
    Event,
    FunctionCall,
    FunctionResult,
    ProtocolError,
    commBM,
)
from comm.rostypes import resolve_type, suggest_type, to_message, type_hint
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import REFERENCE

ALL_DEFS = {}
ALL_DEFS.update(load_definitions([REFERENCE]))
ALL_DEFS.update(load_definitions([SIM_DIR]))
ALL_TYPES = sorted({p.rostype for d in ALL_DEFS.values() for f in d.functions.values()
                    for p in f.inputs + f.outputs} | {p.rostype for d in ALL_DEFS.values()
                                                      for e in d.events.values() for p in e.params})

SAMPLES = {
    "std_msgs/String": {"data": "héllo \"quoted\""},
    "std_msgs/Bool": {"data": True},
    "std_msgs/Float64": {"data": 2.5},
    "geometry_msgs/Point": {"x": 1.5, "y": -2.0, "z": 0.25},
}


def test_every_data_type_is_sampled():
    assert ALL_TYPES, "no definitions found"
    assert set(ALL_TYPES) <= set(SAMPLES), "add samples for %s" % (set(ALL_TYPES) - set(SAMPLES))


@pytest.mark.parametrize("rostype", sorted(SAMPLES))
def test_round_trip_every_message_kind(rostype):
    msg = to_message(rostype, SAMPLES[rostype])
    call = FunctionCall("mod", "fn", [msg], names=["v"])
    back = FunctionCall.decode(call.encode())
    assert back == call and back.rostypes == [rostype]
    res = FunctionResult(["v"], [msg], call_id="c1", basic_mod="mod", function="fn")
    assert FunctionResult.decode(res.encode()) == res
    ev = Event("mod", "ev", ["v"], [msg])
    assert Event.decode(ev.encode()) == ev
    ans = BlackboardAnswer(["v"], [msg], request_id="r1", missing=["w"], sources=[{"call_id": "c1"}])
    assert BlackboardAnswer.decode(ans.encode()) == ans
    # and through the legacy API
    names, ros = commBM.readMsg2Ros(commBM.writeMsgFromRos([msg], ["v"]))
    assert names == ["v"] and ros == [msg]
    bm, fn, ros = commBM.readFunCall(commBM.writeFunCallFromRos("mod", "fn", [msg]))
    assert (bm, fn, ros) == ("mod", "fn", [msg])
    mod, event, names, ros = commBM.readEvent2Ros(commBM.writeEventFromRos("mod", "ev", [msg], ["v"]))
    assert (mod, event, names, ros) == ("mod", "ev", ["v"], [msg])


def test_cancel_and_request_round_trip():
    c = CancelRequest("c1", "navigation", "go_to")
    assert CancelRequest.decode(c.encode()) == c
    r = BlackboardRequest(["a", "m/f/b"], history=3, call_id="c9")
    assert BlackboardRequest.decode(r.encode()) == r


def test_commbm_writes_the_original_keys_and_values():
    p = Point(1.0, 2.0, 3.0)
    text = commBM.writeFunCallFromRos("PYTHON_BM", "putObject", [p])
    assert text.startswith('{\n  "basic_mod"')  # the original indents by 2
    assert json.loads(text) == {"basic_mod": "PYTHON_BM", "function": "putObject",
                                "msgs": ['{"x": 1.0, "y": 2.0, "z": 3.0}'], "rostypes": ["geometry_msgs/Point"]}
    assert json.loads(commBM.writeMsgFromRos([Bool(True), p], ["success", "final_pos"])) == {
        "names": ["success", "final_pos"], "rostypes": ["std_msgs/Bool", "geometry_msgs/Point"],
        "msgs": ['{"data": true}', '{"x": 1.0, "y": 2.0, "z": 3.0}']}
    assert json.loads(commBM.writeVarRequest(["success", "final_pos"])) == {"var_names": ["success", "final_pos"]}
    assert commBM.readVarRequest('{"var_names": ["a"]}') == ["a"]
    assert json.loads(commBM.writeMsgFromJson(['{"data": 1.0}'], ["r"], ["std_msgs/Float64"])) == {
        "names": ["r"], "rostypes": ["std_msgs/Float64"], "msgs": ['{"data": 1.0}']}
    assert json.loads(commBM.writeFunCallFromJson("M", "f", ['{"data": "x"}'], ["std_msgs/String"])) == {
        "basic_mod": "M", "function": "f", "msgs": ['{"data": "x"}'], "rostypes": ["std_msgs/String"]}
    assert commBM.readMsg2Json(commBM.writeMsgFromRos([String("a")], ["t"])) == (
        ["t"], ['{"data": "a"}'], ["std_msgs/String"])
    assert commBM.getRosType(Float64(1.0)) == "std_msgs/Float64"
    assert commBM.json_loads_byteified('{"a": "b"}') == {"a": "b"}


def test_basicmodutil_pkg_import_path():
    from basicmodutil_pkg import commBM as legacy

    assert legacy.writeFunCallFromRos is commBM.writeFunCallFromRos


def test_typed_readers_accept_legacy_payloads():
    legacy_call = commBM.writeFunCallFromRos("PYTHON_BM", "graspObject", [Point(1, 2, 3), Float64(0.1)])
    call = FunctionCall.decode(legacy_call)
    assert call.call_id is None and call.names is None and call.rostypes == ["geometry_msgs/Point", "std_msgs/Float64"]
    legacy_result = commBM.writeMsgFromRos([Bool(True), Point(0, 0, 1)], ["success", "final_pos"])
    res = FunctionResult.decode(legacy_result)
    assert res.legacy and res.status == "succeeded" and res.basic_mod is None
    assert res.values["final_pos"] == Point(0, 0, 1)
    assert BlackboardRequest.decode(commBM.writeVarRequest(["x"])).var_names == ["x"]


def test_legacy_readers_accept_payloads_with_new_keys():
    call = FunctionCall("PYTHON_BM", "putObject", [Point(1, 2, 3)], names=["target_pos"])
    assert commBM.readFunCall(call.encode()) == ("PYTHON_BM", "putObject", [Point(1, 2, 3)])
    res = FunctionResult(["success"], [Bool(True)], call_id="c", basic_mod="m", function="f")
    assert commBM.readMsg2Ros(res.encode()) == (["success"], [Bool(True)])


GOOD_CALL = {"basic_mod": "m", "function": "f", "rostypes": ["geometry_msgs/Point"], "msgs": ['{"x": 1.0}']}


def _with(**changes):
    d = dict(GOOD_CALL)
    for k, v in changes.items():
        if v is _DROP:
            d.pop(k)
        else:
            d[k] = v
    return json.dumps(d)


_DROP = object()

MALFORMED = [
    ("not json", "not valid JSON"),
    ("", "not valid JSON"),
    ("[1, 2]", "not a JSON object"),
    ("42", "not a JSON object"),
    (_with(function=_DROP), "missing key 'function'"),
    (_with(basic_mod=_DROP), "missing key 'basic_mod'"),
    (_with(rostypes=_DROP), "missing key 'rostypes'"),
    (_with(msgs=_DROP), "missing key 'msgs'"),
    (_with(function=3), "key 'function' must be a string"),
    (_with(basic_mod=["m"]), "key 'basic_mod' must be a string"),
    (_with(rostypes="geometry_msgs/Point"), "key 'rostypes' must be a list"),
    (_with(msgs={"x": 1}), "key 'msgs' must be a list"),
    (_with(rostypes=[5]), "rostypes[0] must be a string"),
    (_with(rostypes=["std_msgs/Strin"]), "unknown ROS type 'std_msgs/Strin' (did you mean 'std_msgs/String'?)"),
    (_with(rostypes=["float"]), "unknown ROS type 'float'"),
    (_with(rostypes=["os/system"]), "unknown ROS type 'os/system'"),
    (_with(msgs=['{"x": "abc"}']), "msgs[0] (geometry_msgs/Point): field x takes a number (float64), got 'abc'"),
    (_with(msgs=['{"q": 1.0}']), "msgs[0] (geometry_msgs/Point) has no field 'q' (its fields: x, y, z)"),
    (_with(msgs=["{not json"]), "msgs[0] is not valid JSON for geometry_msgs/Point"),
    (_with(msgs=[{"x": 1.0}]), "msgs[0] is not a JSON string for geometry_msgs/Point"),
    (_with(msgs=['[1, 2]']), "msgs[0] takes a mapping of fields x, y, z (geometry_msgs/Point), got [1, 2]"),
    (_with(msgs=[]), "'msgs' has 0 items but 'rostypes' has 1"),
    (_with(names=["a", "b"]), "'names' has 2 items but 'msgs' has 1"),
    (_with(names="a"), "key 'names' must be a list"),
    (_with(call_id=7), "key 'call_id' must be a string"),
    (_with(msgs=['{"x": 1.0, "y": [1]}']), "msgs[0] (geometry_msgs/Point): field y takes a number (float64), got [1]"),
    (_with(names=["goal"], msgs=['{"x": "abc"}']),
     "input 'goal' (geometry_msgs/Point): field x takes a number (float64), got 'abc' (msgs[0])"),
    ('{"basic_mod": "m", "function": "f", "rostypes": [], "msgs": [], "pad": "%s"}' % ("x" * (1 << 20)),
     "exceeds the limit of 1048576 bytes"),
]


@pytest.mark.parametrize("payload,expected", MALFORMED, ids=[e for _, e in MALFORMED])
def test_malformed_payloads_raise_protocol_error(payload, expected):
    with pytest.raises(ProtocolError) as info:
        FunctionCall.decode(payload)
    assert expected in str(info.value)
    # the legacy API keeps the original conventions; it ignores the keys it never knew
    if any(k in expected for k in ("'names'", "'call_id'")):
        assert commBM.readFunCall(payload)[:2] == ("m", "f")
    else:
        assert commBM.readFunCall(payload) == []


def test_result_status_and_size_limit_are_checked():
    with pytest.raises(ProtocolError, match="status 'done' is not one of"):
        FunctionResult.decode(json.dumps({"names": [], "rostypes": [], "msgs": [], "status": "done"}))
    small = FunctionResult(["t"], [String("x" * 200)]).encode()
    with pytest.raises(ProtocolError, match="exceeds the limit of 100 bytes"):
        FunctionResult.decode(small, max_bytes=100)
    with pytest.raises(ProtocolError, match="must be an integer from 1"):
        BlackboardRequest.decode('{"var_names": ["a"], "history": 0}')
    with pytest.raises(ProtocolError, match="not UTF-8"):
        FunctionCall.decode(b"\xff\xfe")


def test_legacy_writers_return_empty_string_on_bad_input():
    assert commBM.writeMsgFromRos([1], ["a"]) == ""
    assert commBM.writeMsgFromRos([String("a")], ["a", "b"]) == ""
    assert commBM.writeMsgFromRos("x", ["a"]) == ""
    assert commBM.writeFunCallFromRos(1, "f", []) == ""
    assert commBM.writeFunCallFromRos("m", "f", [object()]) == ""
    assert commBM.writeFunCallFromJson("m", "f", ["{}"], []) == ""
    assert commBM.writeMsgFromJson(["{}"], [1], ["std_msgs/String"]) == ""
    assert commBM.writeVarRequest("a") == "" and commBM.writeVarRequest([1]) == ""
    assert commBM.writeEventFromRos("m", "e", [String("a")], []) == ""
    assert commBM.readMsg2Ros("{}") == [] and commBM.readMsg2Json(5) == [] and commBM.readVarRequest(None) == []
    assert commBM.readEvent2Ros('{"basic_mod": "m"}') == []


def test_type_resolution_and_suggestions():
    assert resolve_type("geometry_msgs/Point") is Point
    assert resolve_type("geometry_msgs/Nope") is None and resolve_type("nodots") is None
    assert resolve_type("a/b/c") is None and resolve_type("os.path/x") is None
    assert suggest_type("float") == "std_msgs/Float64"
    assert suggest_type("std_msgs/string") == "std_msgs/String"
    # ROS field types where a whole message is meant: the std_msgs wrapper, of a list too
    assert suggest_type("uint8") == "std_msgs/UInt8" and suggest_type("time") == "std_msgs/Time"
    assert suggest_type("uint8[]") == "std_msgs/UInt8MultiArray"
    assert suggest_type("float64[3]") == "std_msgs/Float64MultiArray"
    assert suggest_type("double[]") == "std_msgs/Float64MultiArray"
    assert suggest_type("string[]") is None  # not std_msgs/String: that is one text
    assert "no list of string: use a message type with a string[] field" in type_hint("string[]")
    assert type_hint("float") == " (did you mean 'std_msgs/Float64'?)" and type_hint("zzzzzz") == ""
    assert to_message("std_msgs/String", "hi", allow_scalar=True) == String("hi")
    with pytest.raises(ProtocolError, match=re.escape("takes a mapping of fields x, y, z (geometry_msgs/Point), got 1.0")):
        to_message("geometry_msgs/Point", 1.0, allow_scalar=True)
    with pytest.raises(ProtocolError, match=re.escape("takes a number (std_msgs/Float64), got 'fast'")):
        to_message("std_msgs/Float64", "fast", allow_scalar=True)


def test_byte_fields_take_a_list_of_numbers_bytes_or_base64_text_at_any_depth():
    """``uint8[]`` as a tree or JSON writes it (a list of numbers): the converter alone made a
    bytearray genpy cannot serialise, so every Image or UInt8MultiArray given that way was refused."""
    from comm.rostypes import from_message, to_message

    for given in ([1, 2, 255], b"\x01\x02\xff", "AQL/"):
        assert to_message("std_msgs/UInt8MultiArray", {"data": given}).data == b"\x01\x02\xff"
        assert to_message("sensor_msgs/Image", {"height": 1, "width": 3, "data": given}).data == b"\x01\x02\xff"
    assert from_message(to_message("sensor_msgs/Image", {"data": [7, 8]}))["data"] == "Bwg="

    class Stereo:  # a message holding images (stereo_msgs is not installed here)
        __slots__ = ["left", "views", "name"]
        _slot_types = ["sensor_msgs/Image", "sensor_msgs/Image[]", "string"]

    from comm.rostypes import _prepared, _special

    assert _special(Stereo) and _prepared(Stereo, {"left": {"data": [7, 8]}, "views": [{"data": b"\x01"}, 5],
                                                              "name": [1]}) == {
        "left": {"data": "Bwg="}, "views": [{"data": "AQ=="}, 5], "name": [1]}
    with pytest.raises(ProtocolError, match=r"field data\[1\] takes a whole number from 0 to 255 \(uint8\), got 300"):
        to_message("std_msgs/UInt8MultiArray", {"data": [1, 300]})


def test_a_time_given_as_now_is_the_wall_clock_in_a_process_that_is_no_ros_node():
    """``bmtree check`` and tree tests build messages without a node: rospy's clock raised there."""
    import time

    from comm.rostypes import to_message

    before = time.time()
    stamp = to_message("std_msgs/Header", {"stamp": "now", "frame_id": "map"}).stamp.to_sec()
    assert before - 1 <= stamp <= time.time() + 1
    assert to_message("sensor_msgs/Image", {"header": {"stamp": "now"}, "data": [1]}).header.stamp.to_sec() >= before - 1
    assert to_message("std_msgs/Header", {"frame_id": "now"}).frame_id == "now"  # only a time field means the time


def test_a_misspelt_key_of_a_time_is_refused_not_dropped():
    """The converter dropped a time's unknown keys: ``{sec: 5}`` was time 0, silently."""
    from comm.rostypes import to_message

    with pytest.raises(ProtocolError, match=r"field stamp \(time\) has no field 'sec' \(did you mean 'secs'\?\)"):
        to_message("std_msgs/Header", {"stamp": {"sec": 5}})
    with pytest.raises(ProtocolError, match=r"has no field 'at' \(its fields: secs, nsecs\)"):
        to_message("std_msgs/Header", {"stamp": {"secs": 5, "at": 1}})
    assert to_message("std_msgs/Header", {"stamp": {"secs": 5, "nsecs": 7}}).stamp.to_nsec() == 5000000007


@pytest.mark.parametrize("value,seconds", [({"secs": 100, "nsecs": 5}, 100.000000005), (100.5, 100.5), (0, 0.0)])
def test_a_time_input_takes_seconds_or_secs_and_nsecs(value, seconds):
    """As a call's input (a one-field std_msgs/Time written as its time) and as a field."""
    from comm.rostypes import to_message

    assert to_message("std_msgs/Time", value, allow_scalar=True).data.to_sec() == pytest.approx(seconds)
    assert to_message("std_msgs/Header", {"stamp": value}).stamp.to_sec() == pytest.approx(seconds)
    assert to_message("std_msgs/Duration", value, allow_scalar=True).data.to_sec() == pytest.approx(seconds)


@pytest.mark.parametrize("rostype,value", [("std_msgs/Time", "2024-01-01"), ("std_msgs/Duration", "5s"),
                                           ("std_msgs/Duration", "now"), ("std_msgs/Time", float("inf"))])
def test_a_time_given_as_other_text_is_refused_not_made_zero(rostype, value):
    """The converter made any text but ``now`` time 0, silently."""
    from comm.rostypes import to_message

    with pytest.raises(ProtocolError, match="takes"):
        to_message(rostype, value, allow_scalar=True)


def test_bytes_given_as_text_that_is_not_base64_say_what_a_byte_field_takes():
    from comm.rostypes import to_message

    with pytest.raises(ProtocolError, match=r"field data takes a list of numbers 0-255, or base64 text \(uint8\[\]\), "
                                            r"got 'abc'"):
        to_message("std_msgs/UInt8MultiArray", {"data": "abc"})
