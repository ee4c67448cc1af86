"""One module runtime: mocks are the real ModuleServer on the simulated clock, and answer as a robot does."""
from __future__ import annotations

import json
import os
import queue
import re
import threading
import time

import pytest
import yaml

from comm import CallStatus, CancelRequest, FunctionCall, FunctionResult
from coordinator.clock import SimClock
from coordinator.testing import MockError, TreeTest, fail, hang, reject, respond, succeed
from coordinator.testing.mocks import Mocks, mock_module
from modules.execution import ClockExecutor, TimerThread, WorkerThreads
from modules.outcome import Outcome, OutcomeKind, outcome_from_dict, outcome_to_dict
from modules.runtime import ModuleServer
from modules.sim.world import World, WorldError
from tests.conftest import DATA

# two non-concurrent functions of one module at once: the case
with open(os.path.join(DATA, "parallel_go_to_approach.yaml")) as _fh:
    PARALLEL = _fh.read()


def tree(tmp_path, body):
    path = tmp_path / "t.yaml"
    path.write_text(body)
    return str(path)


def test_parallel_calls_of_one_module_are_refused_as_busy_as_on_the_robot(tmp_path):
    """The issue's case: the mocked test used to pass where the simulated robot refuses."""
    t = TreeTest(tree(tmp_path, PARALLEL))
    run = t.run()
    assert run.failed
    go_to, approach = run.calls()
    assert (approach.status, approach.error) == ("rejected", "busy with call %s (go_to)" % go_to.call_id)
    assert go_to.status == "halted"                          # the parallel failed and halted it
    assert "busy with call" in run.reason


def test_concurrent_functions_and_other_modules_run_alongside(tmp_path):
    t = TreeTest(tree(tmp_path, """format: 1
root:
  parallel:
    policy: all
    children:
      - call: navigation.go_to
        inputs: {place: kitchen}
      - call: navigation.where_am_i
      - call: speech.say
        inputs: {text: on my way}
      - call: speech.say
        inputs: {text: still on my way}
      - call: vision.find_object
        inputs: {object: apple}
"""))
    t.mocks["navigation.go_to"].succeed(delay=3.0, room="kitchen")
    run = t.run()
    assert run.succeeded, run.reason
    assert [c.status for c in run.calls()] == ["succeeded"] * 5
    assert run.duration == pytest.approx(3.0)


def test_one_call_after_another_is_not_busy(tmp_path):
    t = TreeTest(tree(tmp_path, PARALLEL.replace("parallel:\n    policy: all\n    children:", "sequence:")))
    t.mocks["navigation.go_to"].succeed(delay=2.0, room="kitchen")
    run = t.run()
    assert run.succeeded and run.duration == pytest.approx(2.0)


def test_a_halted_call_frees_its_module_at_once(tmp_path):
    t = TreeTest(tree(tmp_path, """format: 1
root:
  sequence:
    - force_success:
        timeout: 2
        child: {call: navigation.go_to, inputs: {place: kitchen}}
    - call: navigation.approach
      inputs: {target: {x: 1.0}}
"""))
    t.mocks["navigation.go_to"].hang()
    run = t.run()
    assert run.succeeded, run.reason
    assert [(c.target, c.status) for c in run.calls()] == [("navigation.go_to", "halted"),
                                                           ("navigation.approach", "succeeded")]


class Answers:
    """A ModuleServer of mocked navigation; its results by call id (and into ``inbox``, if given)."""

    def __init__(self, defs, mocks, executor=None, scheduler=None, inbox=None):
        self.results = {}
        self.inbox = inbox
        self.cond = threading.Condition()
        self.server = ModuleServer(defs["navigation"], mock_module(mocks, "navigation"), self._res, lambda t: None,
                                   cancel_grace=0.2, executor=executor, scheduler=scheduler)

    def _res(self, text):
        r = FunctionResult.decode(text)
        with self.cond:
            self.results[r.call_id] = r
            self.cond.notify_all()
        if self.inbox is not None:
            self.inbox.put(r)

    def wait(self, call_id, timeout=10.0):
        with self.cond:
            assert self.cond.wait_for(lambda: call_id in self.results, timeout), "no answer to %s" % call_id
            return self.results[call_id]


def _script(defs):
    mocks = Mocks(defs)
    by_place = {"kitchen": succeed(delay=0.3, room="kitchen"), "hall": hang(), "attic": fail("wheel jammed")}
    mocks["navigation.go_to"].respond(lambda place: by_place[place])
    mocks["navigation.approach"].script(reject("too far"))
    return mocks


def _exchange(answers, wait):
    """The same calls and cancels; the answers in call order."""
    server = answers.server

    def send(name, function, **inputs):
        server.handle_call(server.definition.function(function).build_call(inputs, call_id=name).encode())

    send("a", "go_to", place="kitchen")            # takes 0.3 s
    send("b", "approach", target={"x": 1.0})       # busy
    send("c", "where_am_i")                        # concurrent
    wait("a")
    send("d", "approach", target={"x": 1.0})       # its script rejects
    wait("d")
    send("e", "go_to", place="hall")               # hangs
    server.handle_cancel(CancelRequest("e", "navigation", "go_to").encode())
    wait("e")
    send("f", "go_to", place="attic")              # free again: fails
    server.handle_call(FunctionCall("navigation", "fly", [], names=[], call_id="g").encode())
    server.handle_call('{"basic_mod": "navigation", "function": "go_to", "call_id": "h", '
                       '"names": ["place"], "rostypes": ["std_msgs/Bool"], "msgs": ["{\\"data\\": true}"]}')
    return [(name, str(wait(name).status), wait(name).error) for name in "abcdefgh"]


def test_the_runtime_answers_alike_on_threads_and_on_a_simulated_clock(sim_defs):
    threaded = Answers(sim_defs, _script(sim_defs))
    on_threads = _exchange(threaded, threaded.wait)

    clock = SimClock()
    inbox: queue.Queue = queue.Queue()
    simulated = Answers(sim_defs, _script(sim_defs), executor=ClockExecutor(clock), scheduler=clock, inbox=inbox)

    def wait_simulated(name):
        while name not in simulated.results:
            assert clock.wait(inbox, 60.0) is not None, "no answer to %s" % name
        return simulated.results[name]

    on_clock = _exchange(simulated, wait_simulated)
    assert on_threads == on_clock == [
        ("a", "succeeded", ""),
        ("b", "rejected", "busy with call a (go_to)"),
        ("c", "succeeded", ""),
        ("d", "rejected", "too far"),
        ("e", "cancelled", "cancelled by the coordinator"),
        ("f", "failed", "wheel jammed"),
        ("g", "rejected", "module 'navigation' has no function 'fly'"),
        ("h", "rejected", "bad inputs: navigation.go_to: input 'place' is std_msgs/Bool, the definition says "
                          "std_msgs/String"),
    ]
    assert clock.now() == pytest.approx(0.3)                  # simulated time: nothing waited for real


def cancelled_while_it_runs(sim_defs):
    """A navigation.go_to whose code runs until ``release`` is set, cancelled at once, on worker
    threads and the wall clock: (release, Answers, the navigation definition, the call)."""
    release = threading.Event()
    mocks = Mocks(sim_defs)
    mocks["navigation.go_to"].respond(lambda place: {"room": place} if release.wait(10) else {})
    a = Answers(sim_defs, mocks, executor=WorkerThreads("t"), scheduler=TimerThread())
    nav = sim_defs["navigation"]
    go = nav.function("go_to").build_call({"place": "kitchen"})
    a.server.handle_call(go.encode())
    a.server.handle_cancel(CancelRequest(go.call_id, "navigation", "go_to").encode())
    return release, a, nav, go


def test_a_running_function_is_answered_after_the_cancel_grace_and_keeps_its_module(sim_defs):
    release, a, nav, go = cancelled_while_it_runs(sim_defs)
    assert a.wait(go.call_id).status == "cancelled"          # after the grace: the function ignores it
    busy = nav.function("approach").build_call({"target": {"x": 1.0}})
    a.server.handle_call(busy.encode())
    said = re.fullmatch(r"busy with call %s \(go_to\): it was cancelled (\d+\.\d) s ago and its code has not "
                        r"returned; navigation refuses calls until it does, or until its node is restarted"
                        % go.call_id, a.wait(busy.call_id).error)
    assert said and float(said.group(1)) >= 0.2, a.wait(busy.call_id).error
    time.sleep(0.5)   # a call much later (the next run's) says how long ago it really was, not "within the grace"
    again = nav.function("approach").build_call({"target": {"x": 1.0}})
    a.server.handle_call(again.encode())
    later_said = re.search(r"it was cancelled (\d+\.\d) s ago", a.wait(again.call_id).error)
    assert later_said and float(later_said.group(1)) >= 0.7, a.wait(again.call_id).error
    release.set()
    deadline = time.monotonic() + 10
    while True:  # free once the function has returned
        later = nav.function("approach").build_call({"target": {"x": 1.0}})
        a.server.handle_call(later.encode())
        if a.wait(later.call_id).status == "succeeded":
            break
        assert time.monotonic() < deadline, "the module stayed busy after its function returned"
        release.wait(0.01)


def test_a_call_sent_while_the_holder_is_being_cancelled_waits_for_it_and_runs(sim_defs):
    """The tree halts a call and goes on at once (a retry, the next child): the module's cancelled code
    needs a moment to stop, and the next call waits for it instead of being refused busy."""
    release, a, nav, go = cancelled_while_it_runs(sim_defs)
    nxt = nav.function("approach").build_call({"target": {"x": 1.0}})
    a.server.handle_call(nxt.encode())
    third = nav.function("approach").build_call({"target": {"x": 2.0}})
    a.server.handle_call(third.encode())       # one call waits; a second is refused, naming the waiting one
    assert a.wait(third.call_id).error == "busy with call %s (approach)" % nxt.call_id
    release.wait(0.05)                          # within the grace (0.2 s here)
    release.set()                               # the cancelled code returns: the waiting call runs
    assert a.wait(go.call_id).status == "cancelled"
    assert a.wait(nxt.call_id).status == "succeeded"
    # a waiting call that is itself cancelled never runs
    release.clear()
    go = nav.function("go_to").build_call({"place": "hall"})
    a.server.handle_call(go.encode())
    a.server.handle_cancel(CancelRequest(go.call_id, "navigation", "go_to").encode())
    nxt = nav.function("approach").build_call({"target": {"x": 1.0}})
    a.server.handle_call(nxt.encode())
    a.server.handle_cancel(CancelRequest(nxt.call_id, "navigation", "approach").encode())
    assert a.wait(nxt.call_id).status == "cancelled"
    release.set()
    assert a.wait(go.call_id).status == "cancelled"


def test_respond_gets_plain_inputs_and_its_outputs_are_checked(tmp_path):
    t = TreeTest(tree(tmp_path, "format: 1\nroot:\n  call: navigation.go_to\n  inputs: {place: kitchen}\n"
                                "  outputs: {room: room}\n"))
    t.mocks["navigation.go_to"].respond(lambda place: {"room": place.upper()}, delay=1.5)
    run = t.run()
    assert run.succeeded and run.blackboard["room"] == "KITCHEN" and run.duration == pytest.approx(1.5)
    t.mocks["navigation.go_to"].respond(lambda place: {"rooom": place})
    with pytest.raises(MockError, match="unknown output 'rooom'"):
        t.run()


def test_statuses_and_outcome_kinds_are_text_enums():
    r = FunctionResult(status="failed", error="x")
    assert r.status is CallStatus.FAILED and r.status == "failed" and str(r.status) == "failed"
    assert json.loads(r.encode())["status"] == "failed"
    assert FunctionResult.decode(r.encode()).status is CallStatus.FAILED
    assert yaml.safe_dump({"status": r.status}) == "status: failed\n"
    assert "failed" in {r.status} and r.status in {"failed"}
    o = outcome_from_dict({"fail": "blocked", "delay": 2})
    assert o.kind is OutcomeKind.FAIL and o.kind == "fail" and o.delay == 2.0
    assert outcome_to_dict(o) == {"fail": "blocked", "delay": 2.0}
    assert Outcome("hang").kind is OutcomeKind.HANG
    with pytest.raises(ValueError):
        outcome_from_dict({"explode": True})
    with pytest.raises(MockError, match="cannot be sent to a mock node"):
        from coordinator.testing.mocks import outcome_to_dict as to_dict

        to_dict(respond(lambda: {}))


def test_sim_faults_are_outcomes():
    world = World.from_dict(dict(rooms={"a": {"x": 0, "y": 0}}, faults={
        "navigation.go_to": {"reject": "map not loaded", "times": 1},
        "speech.say": {"crash": "segfault", "delay": 0.5},
        "speech.listen": {"delay": 2.0},
        "vision.find_object": {"hang": True}}))
    f = world.faults
    assert f["navigation.go_to"].outcome.kind == "reject" and f["navigation.go_to"].times == 1
    assert f["speech.say"].outcome.kind == "respond" and f["speech.say"].outcome.delay == 0.5
    assert f["speech.listen"].outcome.kind == "respond" and f["speech.listen"].outcome.fn is None
    assert f["vision.find_object"].outcome.kind == "hang"
    with pytest.raises(WorldError, match="faults.speech.say: an outcome has one of"):
        World.from_dict({"rooms": {"a": {"x": 0, "y": 0}}, "faults": {"speech.say": {"fail": "a", "hang": True}}})
