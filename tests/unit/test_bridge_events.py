"""bmtree-bridge's side of C++ events, without ROS: a BM_event payload (what basic_module_calls.h's emit()
sends: per param its name, ROS type, md5sum and ros::serialization bytes in base64) read with genpy,
checked against the definition, passed on as a bmtree Event, or dropped with a warning."""
from __future__ import annotations

import base64
import io
import json
import logging
import os

import pytest
from geometry_msgs.msg import Point, Pose
from std_msgs.msg import Float64

from comm.errors import ProtocolError
from comm.messages import Event
from modules.bridge import make_bridge
from modules.cppinfo import cpp_event, event_topic
from modules.definition import load_definition
from modules.runtime import ModuleServer
from tests.conftest import ROOT

GRIPPER = os.path.join(ROOT, "modules", "cpp", "example", "gripper.json")


def _param(name, msg, rostype=None, md5sum=None, data=None):
    buff = io.BytesIO()
    msg.serialize(buff)
    return {"name": name, "type": rostype or msg._type, "md5sum": md5sum or msg._md5sum,
            "data": data if data is not None else base64.b64encode(buff.getvalue()).decode("ascii")}


def _touched(force=2.5, x=0.3, **changes):
    params = [_param("force", Float64(force)), _param("position", Point(x, -0.1, 0.5))]
    return dict({"event": "touched", "params": params}, **changes)


def test_a_payload_of_the_cpp_library_becomes_messages_by_name():
    event, params = cpp_event(_touched(), load_definition(GRIPPER))
    assert event == "touched" and set(params) == {"force", "position"}
    assert params["force"].data == 2.5 and (params["position"].x, params["position"].y) == (0.3, -0.1)
    assert event_topic("gripper") == "/gripper/BM_event"


@pytest.mark.parametrize("change, said", [
    ({"event": "toched"}, "module 'gripper' has no event 'toched' (did you mean 'touched'?)"),
    ({"event": ""}, "key 'event' must be an event's name"),
    ({"params": {"force": 1}}, "event 'touched': key 'params' must be a list, got dict"),
    ({"params": [_param("force", Float64(2.0))]}, "event 'touched': missing param 'position'"),
    ({"params": [_param("force", Float64(2.0)), _param("position", Point()), _param("where", Point())]},
     "event 'touched': unknown param 'where'"),
    ({"params": [_param("force", Float64(2.0)), _param("force", Float64(3.0)), _param("position", Point())]},
     "param 'force' is given twice"),
    ({"params": [_param("force", Float64(2.0)), _param("position", Pose())]},
     "param 'position' is a geometry_msgs/Pose in the C++ node, but the definition's Event-params say "
     "geometry_msgs/Point"),
    ({"params": [_param("force", Float64(2.0)), _param("position", Point(), md5sum="0" * 32)]},
     "param 'position': the C++ node was built with another definition of geometry_msgs/Point (md5sum "
     + "0" * 32),
    ({"params": [_param("force", Float64(2.0), data="AAAA!"), _param("position", Point())]},
     "param 'force': 'data' is not base64"),
    ({"params": [_param("force", Float64(2.0), data="AAAA"), _param("position", Point())]},
     "param 'force': its 3 bytes are not a serialized std_msgs/Float64"),
    ({"params": [_param("force", Float64(2.0)), ["position"]]}, "params[1] is not {\"name\", \"type\""),
])
def test_what_does_not_match_the_definition_is_named(change, said):
    with pytest.raises(ProtocolError) as exc:
        cpp_event(_touched(**change), load_definition(GRIPPER))
    assert said in str(exc.value), str(exc.value)


def test_a_module_without_events_says_so():
    d = load_definition(os.path.join(ROOT, "tests", "data", "cpp", "oddities.json"))
    with pytest.raises(ProtocolError, match="module 'oddities' has no event 'touched' \\(it has no events\\)"):
        cpp_event(_touched(), d)


class _Said(logging.Handler):
    """The bridge's warnings (pytest's logging plugin is off in this project)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.records = []

    def emit(self, record):
        self.records.append(record)


@pytest.fixture
def said_log():
    handler = _Said()
    logger = logging.getLogger("bmtree.bridge")
    logger.addHandler(handler)
    try:
        yield handler
    finally:
        logger.removeHandler(handler)


class _Msg:
    def __init__(self, data, sender="/gripper"):
        self.data = data
        self._connection_header = {"callerid": sender}


def _bridge():
    sent = []
    d = load_definition(GRIPPER)
    bridge = make_bridge(d)
    ModuleServer(d, bridge, lambda t: None, sent.append)
    bridge.cpp_node = "/gripper"
    return bridge, sent


def test_the_bridge_passes_a_good_event_on_and_drops_bad_ones_with_a_warning(said_log):
    bridge, sent = _bridge()
    bridge._on_event(_Msg(json.dumps(_touched())))
    assert len(sent) == 1
    ev = Event.decode(sent[0])
    assert (ev.basic_mod, ev.event, ev.names) == ("gripper", "touched", ["force", "position"])
    assert ev.msgs[0].data == 2.5 and ev.msgs[1].x == 0.3

    bridge._on_event(_Msg("{not json"))
    bridge._on_event(_Msg(json.dumps(_touched(event="toched"))))
    bridge._on_event(_Msg(json.dumps(_touched()), sender="/impostor"))
    bridge._on_event(_Msg("x" * (2 << 20)))
    assert len(sent) == 1
    said = [r.getMessage() for r in said_log.records]
    assert said[0].startswith("dropped an event from the C++ node /gripper of module 'gripper': payload is not "
                              "valid JSON"), said
    assert said[1] == ("dropped an event from the C++ node /gripper of module 'gripper': module 'gripper' has no "
                       "event 'toched' (did you mean 'touched'?): add it to the definition's Events, or emit one "
                       "of those"), said
    assert said[2] == ("dropped an event from /impostor on /gripper/BM_event, which is not the C++ node of module "
                       "'gripper' (/gripper): events are taken from the C++ node only"), said
    assert "exceeds the limit of 1048576 bytes" in said[3], said


def test_a_wrong_event_sent_again_and_again_is_said_once_per_period(said_log, monkeypatch):
    import modules.bridgeoutput as bridgeoutput

    bridge, sent = _bridge()
    clock = [100.0]
    monkeypatch.setattr(bridgeoutput.time, "monotonic", lambda: clock[0])
    for _ in range(30):  # a timer at 10 Hz for 3 s
        bridge._on_event(_Msg(json.dumps(_touched(event="toched"))))
        clock[0] += 0.1
    clock[0] += 10.0
    bridge._on_event(_Msg(json.dumps(_touched(event="toched"))))
    said = [r.getMessage() for r in said_log.records]
    assert len(said) == 2 and not sent, said
    assert said[1].endswith("(and 29 more like it in the last 10s)"), said


def test_an_event_before_the_cpp_node_is_found_is_ignored_quietly(said_log):
    bridge, sent = _bridge()
    bridge.cpp_node = ""
    bridge._on_event(_Msg(json.dumps(_touched())))
    assert not sent and not said_log.records
