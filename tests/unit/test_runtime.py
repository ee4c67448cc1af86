"""The module runtime without ROS: binding, checks, statuses, busy, cancel, events; the sim world."""
from __future__ import annotations

import threading
import time

import pytest

from comm import CancelRequest, Event, FunctionCall, FunctionResult, commBM
from modules.runtime import BasicModule, BindingError, Failure, ModuleServer
from modules.sim import Navigation, Speech, Vision, World, WorldError
from modules.sim.robot import RobotState


class Served:
    """A ModuleServer whose outputs land in lists, for assertions."""

    def __init__(self, definition, impl):
        self.results, self.events = [], []
        self.cond = threading.Condition()
        self.server = ModuleServer(definition, impl, self._res, self._ev, cancel_grace=0.5)

    def _res(self, text):
        with self.cond:
            self.results.append(FunctionResult.decode(text))
            self.cond.notify_all()

    def _ev(self, text):
        self.events.append(Event.decode(text))

    def call(self, function, **inputs):
        fn = self.server.definition.function(function)
        call = fn.build_call(inputs)
        self.server.handle_call(call.encode())
        return call.call_id

    def result(self, call_id, timeout=5.0):
        with self.cond:
            ok = self.cond.wait_for(lambda: any(r.call_id == call_id for r in self.results), timeout)
            assert ok, "no result for %s: %s" % (call_id, self.results)
            return next(r for r in self.results if r.call_id == call_id)


def test_binding_errors_name_both_sides(sim_defs):
    class Partial(BasicModule):
        def go_to(self, place):
            return {}

        def fly(self):
            return {}

    with pytest.raises(BindingError) as info:
        ModuleServer(sim_defs["navigation"], Partial(), print, print)
    text = str(info.value)
    assert "function 'approach' of definition" in text and "has no method in class Partial" in text
    assert "method 'fly' of class Partial is not a function of module 'navigation'" in text


def test_calls_rejections_failures_and_exceptions(sim_defs):
    class Voice(BasicModule):
        def say(self, text):
            if text.data == "boom":
                raise RuntimeError("speaker on fire")
            if text.data == "no":
                raise Failure("muted")
            return {"success": True}

        def listen(self, seconds):
            return {"success": True, "text": 3}  # breaks the definition

    s = Served(sim_defs["speech"], Voice())
    assert s.result(s.call("say", text="hola, ¿qué tal?")).status == "succeeded"
    r = s.result(s.call("say", text="boom"))
    assert r.status == "failed" and r.error.startswith("RuntimeError: speaker on fire (test_runtime.py:")
    assert r.error.endswith(" in say)"), r.error  # the line of the method that raised
    assert s.result(s.call("say", text="no")).error == "muted"
    r = s.result(s.call("listen", seconds=1.0))
    assert r.status == "failed" and r.error.startswith("invalid outputs: output 'text'"), r.error
    bad = FunctionCall("speech", "sing", [], names=[], call_id="x1")
    s.server.handle_call(bad.encode())
    r = s.result("x1")
    assert r.status == "rejected" and "module 'speech' has no function 'sing'" in r.error
    s.server.handle_call('{"basic_mod": "speech", "function": "say", "rostypes": ["std_msgs/Bool"],'
                         ' "msgs": ["{\\"data\\": true}"], "names": ["text"], "call_id": "x2"}')
    r = s.result("x2")
    assert r.status == "rejected" and "input 'text' is std_msgs/Bool, the definition says std_msgs/String" in r.error
    n = len(s.results)
    s.server.handle_call(FunctionCall("navigation", "go_to", [], names=[]).encode())  # not ours
    s.server.handle_call("garbage")
    assert s.result(s.call("say", text="still here")).status == "succeeded"
    assert len(s.results) == n + 1


def test_an_answer_over_the_size_limit_fails_with_its_size_instead_of_never_arriving(sim_defs):
    class Chatty(BasicModule):
        def say(self, text):
            return {"success": True}

        def listen(self, seconds):
            return {"success": True, "text": "é" * int(seconds.data)}

    results = []
    server = ModuleServer(sim_defs["speech"], Chatty(), lambda t: results.append(FunctionResult.decode(t, 1 << 20)),
                          print, max_bytes=4096)
    fn = server.definition.function("listen")
    for seconds in (100.0, 3000.0):  # 3,000 two-byte characters: over 4 KiB only as UTF-8
        n = len(results)
        server.handle_call(fn.build_call({"seconds": seconds}).encode())
        deadline = time.monotonic() + 5
        while len(results) == n and time.monotonic() < deadline:
            time.sleep(0.01)
    small, big = results
    assert small.status == "succeeded" and small.values["text"].data == "é" * 100
    assert big.status == "failed" and "over the limit of 4096 bytes" in big.error, big.error


def test_legacy_positional_call_is_served(sim_defs):
    s = Served(sim_defs["speech"], Speech(World.load()))
    s.server.handle_call(commBM.writeFunCallFromJson("speech", "say", ['{"data": "hi"}'], ["std_msgs/String"]))
    with s.cond:
        assert s.cond.wait_for(lambda: s.results, 5)
    r = s.results[0]
    assert r.status == "succeeded" and r.call_id is None and r.basic_mod == "speech"
    assert s.server.impl.said == ["hi"]


def test_busy_and_cancel(sim_defs):
    world = World.load()
    world.speed = 2.0  # the kitchen is ~8 m away: 4 s
    s = Served(sim_defs["navigation"], Navigation(world))
    first = s.call("go_to", place="kitchen")
    second = s.call("approach", target={"x": 1.0})
    r = s.result(second)
    assert r.status == "rejected" and r.error == "busy with call %s (go_to)" % first
    assert s.result(s.call("where_am_i")).status == "succeeded"  # concurrent
    s.server.handle_cancel(CancelRequest(first, "navigation", "go_to").encode())
    r = s.result(first)
    assert r.status == "cancelled"
    pos = s.result(s.call("where_am_i")).values
    assert pos["room"].data == "entrance" and 0.0 <= pos["position"].x < 8.0  # stopped on the way


def test_events_are_checked_and_published(sim_defs):
    state = RobotState("bedroom", 2.0, 6.0)
    s = Served(sim_defs["vision"], Vision(World.load(), state))
    r = s.result(s.call("find_person", name=""))
    assert r.values["person"].data == "Ana"
    assert [(e.event, e.values["person"].data) for e in s.events] == [("personSeen", "Ana")]
    from comm import ProtocolError

    with pytest.raises(ProtocolError, match="has no event 'vanished'"):
        s.server.impl.emit("vanished")


def test_sim_faults_and_world_errors(sim_defs):
    world = World.from_dict(dict(
        rooms={"a": {"x": 0, "y": 0}, "b": {"x": 1, "y": 0}}, start="a", speed=100,
        faults={"navigation.go_to": {"fail": "wheel jammed", "times": 2}, "speech.say": {"crash": "segfault"}}))
    s = Served(sim_defs["navigation"], Navigation(world))
    assert [s.result(s.call("go_to", place="b")).error for _ in range(3)] == [
        "wheel jammed (injected fault)", "wheel jammed (injected fault)", ""]
    assert s.result(s.call("go_to", place="attic")).error.startswith("unknown place 'attic'")
    sp = Served(sim_defs["speech"], Speech(world))
    assert sp.result(sp.call("say", text="x")).error == "RuntimeError: segfault (injected fault)"
    with pytest.raises(WorldError, match="unknown room 'garage'"):
        World.from_dict({"rooms": {"a": {"x": 0, "y": 0}}, "objects": {"car": {"room": "garage", "x": 0, "y": 0}}})
    with pytest.raises(WorldError, match="unknown keys explode"):
        World.from_dict({"rooms": {"a": {"x": 0, "y": 0}}, "faults": {"speech.say": {"explode": True}}})
    with pytest.raises(WorldError, match=r"<world>: unknown key 'fautls' \(did you mean 'faults'\?\)"):
        World.from_dict({"rooms": {"a": {"x": 0, "y": 0}}, "fautls": {}})
    with pytest.raises(WorldError, match=r"faults.navigation.fly: not a function of the simulated robot \(did you"):
        World.from_dict({"rooms": {"a": {"x": 0, "y": 0}}, "faults": {"navigation.fly": {"fail": "x"}}})


def test_recognition_only_sees_the_current_room(sim_defs):
    state = RobotState("living_room", 4.0, 0.0)
    s = Served(sim_defs["vision"], Vision(World.load(), state))
    assert s.result(s.call("find_object", object="apple")).values["success"].data is False
    state.room = "kitchen"
    r = s.result(s.call("find_object", object="apple"))
    assert r.values["success"].data is True and r.values["position"].x == pytest.approx(8.6)


def test_hang_delay_faults_and_module_rejections(sim_defs):
    import time as _time

    from modules.runtime import Rejected

    world = World.from_dict(dict(rooms={"a": {"x": 0, "y": 0}}, start="a", faults={
        "speech.listen": {"hang": True}, "speech.say": {"delay": 0.3, "times": 1}}))
    s = Served(sim_defs["speech"], Speech(world))
    t0 = _time.monotonic()
    assert s.result(s.call("say", text="late")).status == "succeeded"
    assert _time.monotonic() - t0 >= 0.3
    hung = s.call("listen", seconds=1.0)
    _time.sleep(0.2)
    with s.cond:
        assert not any(r.call_id == hung for r in s.results)        # hangs until cancelled
    s.server.handle_cancel(CancelRequest(hung, "speech", "listen").encode())
    assert s.result(hung).status == "cancelled"

    class Picky(BasicModule):
        def say(self, text):
            raise Rejected("the robot is charging")

        def listen(self, seconds):
            return {"success": False, "text": ""}

    p = Served(sim_defs["speech"], Picky())
    r = p.result(p.call("say", text="x"))
    assert (r.status, r.error) == ("rejected", "the robot is charging")


def test_the_readme_module_example_binds_and_serves(tmp_path):
    import json
    import os
    import runpy

    from modules.definition import parse_definition
    from tests.conftest import DATA, ROOT

    with open(os.path.join(ROOT, "README.md")) as fh:
        section = fh.read().split("## Writing a basic module", 1)[1]
    code = section.split("```python", 1)[1].split("```", 1)[0]
    (tmp_path / "gripper.py").write_text(code)
    Gripper = runpy.run_path(str(tmp_path / "gripper.py"))["Gripper"]
    written = json.loads(section.split("```json", 1)[1].split("```", 1)[0])   # the README's gripper.json
    with open(os.path.join(DATA, "gripper", "gripper.json")) as fh:
        assert written == json.load(fh)   # the one the tests use
    definition = parse_definition(written)
    s = Served(definition, Gripper())
    assert s.result(s.call("open", width=0.2)).error == "the gripper opens 10 cm at most"
    assert s.result(s.call("open", width=0.05)).status == "succeeded"
    assert s.result(s.call("close")).values["holding"].data is True


def test_a_calls_cancelled_flag_reads_as_true_only_once_cancelled():
    """``if self.context.cancelled:`` is what authors write (a plain Event would always be true)."""
    from modules.basicmodule import CallContext

    ctx = CallContext("c1", "go_to")
    assert not ctx.cancelled and not ctx.cancelled() and not ctx.cancelled.is_set()
    assert ctx.cancel()
    assert ctx.cancelled and ctx.cancelled() and ctx.cancelled.wait(0)


def test_a_stopping_node_can_wait_for_the_answers_of_its_calls_in_flight(sim_defs):
    """What a node's shutdown hook uses (modules.actions): the answers its stop caused go out before rospy
    closes the topics."""
    world = World.from_dict(dict(rooms={"a": {"x": 0, "y": 0}}, start="a", faults={"speech.listen": {"hang": True}}))
    s = Served(sim_defs["speech"], Speech(world))
    hung = s.call("listen", seconds=1.0)
    calls = s.server.in_flight()
    assert [c.ctx.call_id for c in calls] == [hung]
    assert not s.server.answers_sent(calls, 0.1)       # no answer yet: the time runs out
    s.server.handle_cancel(CancelRequest(hung, "speech", "listen").encode())
    assert s.server.answers_sent(calls, 5.0)
    assert s.result(hung).status == "cancelled"


def test_a_function_that_returns_early_on_cancel_is_answered_cancelled_without_an_outputs_warning(sim_defs):
    """The README's pattern (``if not self.context.sleep(…): return``) returns no outputs: the call was
    cancelled, so they are not the author's bug (the sim's go_to logged "invalid outputs" on every halt)."""
    import logging

    class Kept(logging.Handler):
        def __init__(self):
            super().__init__(logging.WARNING)
            self.messages = []

        def emit(self, record):
            self.messages.append(record.getMessage())

    kept = Kept()
    logging.getLogger("bmtree.module").addHandler(kept)
    try:
        world = World.load()
        world.speed = 2.0
        s = Served(sim_defs["navigation"], Navigation(world))
        first = s.call("go_to", place="kitchen")
        time.sleep(0.1)
        s.server.handle_cancel(CancelRequest(first, "navigation", "go_to").encode())
        assert s.result(first).status == "cancelled"
    finally:
        logging.getLogger("bmtree.module").removeHandler(kept)
    assert not [m for m in kept.messages if "invalid outputs" in m], kept.messages


def test_the_simulated_speech_logs_what_it_says_and_hears(sim_defs, monkeypatch):
    """Under --sim nothing showed what the robot said (only replay --at did): bm_speech.out now does."""
    from modules.sim import robot

    said = []

    class Log:
        @staticmethod
        def info(text, *args):
            said.append(text % args)

    monkeypatch.setattr(robot, "log", Log)
    world = World.from_dict(dict(rooms={"a": {"x": 0, "y": 0}, "b": {"x": 1, "y": 0}}, start="a",
                                 people={"Bob": {"room": "a", "x": 0, "y": 0, "answers": ["lemonade"]}}))
    s = Served(sim_defs["speech"], Speech(world))
    s.result(s.call("say", text="Here is your lemonade, Bob."))
    s.result(s.call("listen", seconds=1.0))
    assert said == ["says 'Here is your lemonade, Bob.'", "hears Bob say 'lemonade'"]
