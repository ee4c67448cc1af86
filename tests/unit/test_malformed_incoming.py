"""What arrives at the coordinator malformed is refused with why, and costs nothing else: a malformed
answer to a call the run awaits fails that call at once (not at its timeout, nor never with ``timeout:
none``) with a notice naming the sender; an event that breaks its definition is refused and a waiting
``wait_event`` goes on waiting for a good one (an audit found both dropped or taken)."""
from __future__ import annotations

import json
import logging

import pytest

from comm.messages import Event, FunctionResult
from coordinator.runevents import RunObserver
from coordinator.testing.kit import TreeTest
from tests.conftest import log_records

MALFORMED_ANSWER, REFUSED_EVENT = "malformed_answer", "refused_event"   # (coordinator.transport's)


def _tree(tmp_path, body):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n" + body)
    return str(path)


class _Answer(RunObserver):
    """Answers each call, one second after it is sent, with ``payload(call_id)`` as its module would."""

    def __init__(self, payload):
        self.payload = payload
        self.notices = []

    def on_start(self, tree, root, ctx):
        self.ctx = ctx

    def on_call_start(self, record):
        text = self.payload(record.call_id)
        self.ctx.clock.call_later(1.0, lambda: self.ctx.transport._on_result(text))

    def on_notice(self, notice, now):
        self.notices.append((notice, now))


GO_TO = {"basic_mod": "navigation", "function": "go_to", "status": "succeeded", "error": "",
         "names": ["success", "room", "position"], "rostypes": ["std_msgs/Bool", "std_msgs/String",
                                                               "geometry_msgs/Point"],
         "msgs": ['{"data": true}', '{"data": "kitchen"}', '{"x": 1.0, "y": 2.0, "z": 0.0}']}

MALFORMED = {
    "a value that does not fit its type": (lambda cid: json.dumps(dict(GO_TO, call_id=cid, msgs=[
        '{"data": true}', '{"data": "kitchen"}', '{"x": "far", "y": 2.0, "z": 0.0}'])), "output 'position'"),
    "outputs that break the definition": (lambda cid: json.dumps(dict(
        GO_TO, call_id=cid, names=["success"], rostypes=["std_msgs/Bool"], msgs=['{"data": true}'])),
        "outputs that break its definition: navigation.go_to: missing output 'room', 'position'"),
    "a field of the wrong type": (lambda cid: json.dumps(dict(GO_TO, call_id=cid, status=3)),
                                  "key 'status' must be a string, got int"),
    "broken JSON": (lambda cid: '{"call_id": "%s", "basic_mod": "navigation", "msgs": [' % cid,
                    "payload is not valid JSON"),
    "too deep": (lambda cid: '{"call_id": "%s", "x": %s}' % (cid, "[" * 5000 + "]" * 5000),
                 "JSON nested deeper than 100 levels"),
    "an answer of another function": (lambda cid: json.dumps(dict(GO_TO, call_id=cid, function="approach")),
                                      "it answers navigation.approach, not navigation.go_to"),
}


@pytest.mark.parametrize("timeout", ["", "\n      timeout: none"])
@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_a_malformed_answer_fails_its_call_at_once_with_why_and_a_notice(tmp_path, sim_defs, case, timeout):
    payload, why = MALFORMED[case]
    t = TreeTest(_tree(tmp_path, "  sequence:\n    - call: navigation.go_to\n      inputs: {place: kitchen}%s\n"
                                 "    - call: speech.say\n      inputs: {text: hi}\n" % timeout), sim_defs)
    t.mocks["navigation.go_to"].hang()
    answer = _Answer(payload)
    run = t.run(max_duration=100.0, observers=[answer])
    call = run.calls("navigation.go_to")[0]
    assert run.failed and call.status == "failed" and call.duration == pytest.approx(1.0)
    assert call.error.startswith("malformed answer from module navigation: ") and why in call.error, call.error
    assert run.reason == "navigation.go_to failed: %s" % call.error
    [(notice, at)] = answer.notices
    assert notice.what == MALFORMED_ANSWER and notice.call_id == call.call_id and at == pytest.approx(1.0)
    assert notice.text == "navigation.go_to (call %s): %s; the call fails" % (call.call_id, call.error)
    assert not run.calls("speech.say")


@pytest.fixture
def warnings():
    with log_records("bmtree.coordinator", logging.WARNING) as records:
        yield records


def test_a_malformed_answer_to_no_awaited_call_is_a_rate_limited_warning(warnings):
    from coordinator.transport import Screen

    screen = Screen()
    for _ in range(5):
        assert screen.result('{"names": [', node="/bm_x") == []   # no call_id to be read
    assert screen.result('{"call_id": "c9", "msgs": 1}', node="/bm_x") == []   # a call this run never made
    said = [r.getMessage() for r in warnings]
    assert said == ["ignored a malformed answer from node /bm_x: payload is not valid JSON: Expecting value: line 1 "
                    "column 12 (char 11)"]


def test_refusals_say_the_first_at_once_then_one_per_period_with_the_count():
    from comm.saylimit import SayLimit

    now = [0.0]
    said = SayLimit(every=10.0, clock=lambda: now[0])
    assert [said.due("a"), said.due("a"), said.due("b"), said.due("a")] == ["", None, "", None]
    now[0] = 10.5
    assert [said.due("a"), said.due("a"), said.due("b")] == [" (and 2 more like it in the last 10s)", None, ""]


class _Emit(RunObserver):
    """Sends event payloads (``(at, text)``) as a module's node would, at their times."""

    def __init__(self, payloads):
        self.payloads = payloads
        self.notices = []

    def on_start(self, tree, root, ctx):
        for at, text in self.payloads:
            ctx.clock.call_later(at, lambda text=text: ctx.transport._on_event(text))

    def on_notice(self, notice, now):
        self.notices.append((notice, now))


def _seen(person, **changes):
    out = {"basic_mod": "vision", "event": "personSeen", "names": ["person", "position"],
           "rostypes": ["std_msgs/String", "geometry_msgs/Point"],
           "msgs": [json.dumps({"data": person}), '{"x": 1.0, "y": 0.0, "z": 0.0}']}
    out.update(changes)
    return json.dumps(out)


def test_an_event_that_breaks_its_definition_is_refused_and_the_wait_goes_on(tmp_path, sim_defs):
    t = TreeTest(_tree(tmp_path, "  wait_event: vision.personSeen\n  where: 'person == \"Ana\"'\n"
                                 "  outputs: {person: who, position: where}\n"), sim_defs)
    emit = _Emit([(1.0, _seen("Ana", names=["person"], rostypes=["std_msgs/String"], msgs=['{"data": "Ana"}'])),
                  (1.5, _seen("Ana", rostypes=["std_msgs/String", "std_msgs/String"], msgs=['{"data": "Ana"}', '{"data": "here"}'])),
                  (2.0, _seen("Ana", names=["name", "position"])),
                  (2.5, _seen("Ana", msgs=['{"data": "Ana"}', '{"x": "far"}'])),
                  (3.0, _seen("Ana"))])
    run = t.run(max_duration=100.0, observers=[emit])
    assert run.succeeded and run.duration == pytest.approx(3.0), run.reason
    assert run.blackboard["who"] == "Ana" and run.blackboard["where"]["x"] == 1.0
    texts = [n.text for n, _ in emit.notices]
    assert all(n.what == REFUSED_EVENT for n, _ in emit.notices) and len(texts) == 1   # one per period
    assert texts[0] == ("refused vision.personSeen from module vision: it breaks the definition: missing param "
                        "'position'")


def test_refused_events_are_said_per_kind_with_what_is_wrong(sim_defs, warnings):
    from coordinator.transport import Screen

    screen = Screen(sim_defs)
    bad_type = screen.event(_seen("Ana", rostypes=["std_msgs/String", "std_msgs/String"], msgs=['{"data": "Ana"}', '{"data": "x"}']),
                            node="/bm_vision")
    unknown = screen.event(_seen("Ana", event="personSen"), node="/bm_vision")
    misfit = screen.event(_seen("Ana", event="lostPerson", names=["person"], rostypes=["std_msgs/Float64"],
                                msgs=['{"data": "Ana"}']), node="/bm_vision")
    foreign = screen.event(_seen("Ana", basic_mod="elsewhere", names=["x"]), node="/other")
    good = screen.event(_seen("Ana"), node="/bm_vision")
    assert [n.text for n in bad_type + unknown + misfit] == [
        "refused vision.personSeen from node /bm_vision: it breaks the definition: param 'position' is "
        "std_msgs/String, the definition says geometry_msgs/Point",
        "refused vision.personSen from node /bm_vision: it breaks the definition: module vision has no event "
        "'personSen' (did you mean 'personSeen'?)",
        "refused vision.lostPerson from node /bm_vision: event param 'person' takes a number (std_msgs/Float64), "
        "got 'Ana' (msgs[0])"]
    assert foreign == [] and len(good) == 1 and isinstance(good[0], Event) and good[0].publisher == "/bm_vision"
    assert len(warnings) == 4   # the foreign module's too, in the log only


def test_a_good_answer_passes_and_a_late_malformed_one_is_not_a_failure(sim_defs):
    from comm.messages import FunctionCall
    from coordinator.transport import Screen

    screen = Screen(sim_defs)
    screen.sent(FunctionCall("navigation", "go_to", [], [], call_id="c1"))
    [result] = screen.result(json.dumps(dict(GO_TO, call_id="c1")), node="/bm_navigation")
    assert isinstance(result, FunctionResult) and result.status == "succeeded" and result.publisher == "/bm_navigation"
    screen.sent(FunctionCall("navigation", "go_to", [], [], call_id="c2"))
    screen.ended(["c2"])   # cancelled (timed out): a malformed answer now fails nothing
    assert screen.result(json.dumps(dict(GO_TO, call_id="c2", status=3))) == []


class _Msg:
    def __init__(self, data, node):
        self.data = data
        self._connection_header = {"callerid": node}


def test_over_ros_a_malformed_answer_fails_its_call_naming_the_node_and_bad_events_are_refused(sim_defs):
    from comm.messages import FunctionCall
    from coordinator.ros_transport import RosTransport
    from coordinator.runevents import Notice

    transport = RosTransport(liveness=0)
    got = []
    transport._deliver = got.append
    transport.screen.know({"vision": sim_defs["vision"]})   # as the preflight gives the run's modules
    call = FunctionCall("navigation", "go_to", [], [], call_id="c1")
    transport.screen.sent(call)
    transport.watchdog.call_sent("c1", "navigation")
    on_result = transport._on(FunctionResult, transport._take_ping)
    on_result(_Msg(json.dumps(dict(GO_TO, call_id="c1", error=["x"])), "/bm_navigation"))
    notice, failed = got
    assert isinstance(notice, Notice) and notice.what == MALFORMED_ANSWER
    assert isinstance(failed, FunctionResult) and (failed.call_id, failed.status) == ("c1", "failed")
    assert failed.error == ("malformed answer from node /bm_navigation (module navigation): key 'error' must be a "
                            "string, got list")
    assert not transport.watchdog.owes("c1")   # answered: its node is no longer watched for it
    del got[:]
    on_event = transport._on(Event)
    on_event(_Msg(_seen("Ana", names=["person", "where"]), "/bm_vision"))
    on_event(_Msg(_seen("Ana"), "/bm_vision"))
    refused, event = got
    assert refused.what == REFUSED_EVENT and refused.text == (
        "refused vision.personSeen from node /bm_vision: it breaks the definition: unknown param 'where'; missing "
        "param 'position'")
    assert isinstance(event, Event) and event.publisher == "/bm_vision"
