"""A module's node that stops with calls in flight, without ROS (``ModuleServer.stop``, ``modules.nodestop``).

Before, a stopped node ended under its functions: ``self.context.sleep(20)`` never returned, the code after
it never ran, and nobody was answered. Now each call is cancelled as a coordinator's cancel would, its code
has the cancel grace to return, and every call is answered ``cancelled`` saying that the node stops."""
from __future__ import annotations

import logging
import threading
import time

import pytest

from comm import CancelRequest, FunctionResult
from modules.definition import parse_definition
from modules.nodestop import stop_cause
from modules.outcome import succeed
from modules.runtime import BasicModule, ModuleServer

WHY = "the module's node /bm_arm is stopping (SIGINT)"


def _fn(name, inputs=(), concurrent=False):
    fn = {"Name": name, "Exec-condition": "", "Description": "",
          "Input-params": [{"Name": n, "Data-type": t, "Description": ""} for n, t in inputs],
          "Output-params": [{"Name": "success", "Data-type": "std_msgs/Bool", "Description": ""}]}
    if concurrent:
        fn["Concurrent"] = True
    return fn


DEFINITION = parse_definition({
    "Basic Module": "arm", "Brief Description": "", "Hardware Required": [],
    "Functions": [_fn("work", [("seconds", "std_msgs/Float64")]), _fn("stuck", concurrent=True),
                  _fn("later", concurrent=True), _fn("quick"), _fn("park")]})


class Arm(BasicModule):
    def __init__(self):
        super().__init__()
        self.notes = []
        self.hooked = threading.Event()
        self.started = threading.Event()
        self.release = threading.Event()

    def work(self, seconds):
        self.context.on_cancel(self.hooked.set)
        self.started.set()
        ok = self.context.sleep(seconds.data)
        time.sleep(0.05)  # "stop the motors"
        self.notes.append("sleep returned %r, cancelled %r; motors stopped" % (ok, bool(self.context.cancelled)))
        return {"success": ok}

    def stuck(self):
        self.started.set()
        self.release.wait(10)  # never looks at its cancel
        return {"success": True}

    def park(self):  # takes its time to stop
        self.started.set()
        self.context.cancelled.wait(10)
        time.sleep(0.3)
        return {"success": True}

    def later(self):
        return succeed(delay=30.0, success=True)

    def quick(self):
        return {"success": True}


class _Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.DEBUG)
        self.lines = []

    def emit(self, record):
        self.lines.append((record.levelname, record.getMessage()))


@pytest.fixture
def log():
    logger = logging.getLogger("bmtree.module")
    handler, level = _Records(), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    yield handler
    logger.removeHandler(handler)
    logger.setLevel(level)


class Served:
    def __init__(self, grace=0.5):
        self.impl = Arm()
        self.answers = []
        self.cond = threading.Condition()
        self.server = ModuleServer(DEFINITION, self.impl, self._res, lambda text: None, cancel_grace=grace)

    def _res(self, text):
        with self.cond:
            self.answers.append(FunctionResult.decode(text))
            self.cond.notify_all()

    def send(self, function, **inputs):
        call = DEFINITION.function(function).build_call(inputs)
        self.server.handle_call(call.encode())
        return call.call_id

    def of(self, call_id):
        with self.cond:
            return [a for a in self.answers if a.call_id == call_id]

    def wait(self, call_id, timeout=5.0):
        with self.cond:
            assert self.cond.wait_for(lambda: self.of(call_id), timeout), self.answers
        return self.of(call_id)[0]


def test_a_call_in_flight_is_cancelled_its_code_runs_on_and_it_is_answered(log):
    s = Served()
    call_id = s.send("work", seconds=20.0)
    assert s.impl.started.wait(5)
    start = time.monotonic()
    lines = s.server.stop(WHY)
    took = time.monotonic() - start
    assert took < 0.4, took  # the code returned: no need to wait out the grace
    assert s.impl.notes == ["sleep returned False, cancelled True; motors stopped"]
    assert s.impl.hooked.is_set()  # on_cancel callbacks ran
    [answer] = s.of(call_id)  # answered before stop() returned, once
    assert answer.status == "cancelled" and answer.error == WHY + "; its code returned after the cancel", answer
    said = "cancelled call %s of arm.work: %s; its code returned" % (call_id, WHY)
    assert lines == [said] and ("INFO", said) in log.lines, log.lines


def test_code_that_ignores_the_cancel_is_answered_after_the_grace_and_said(log):
    s = Served(grace=0.3)
    call_id = s.send("stuck")
    assert s.impl.started.wait(5)
    start = time.monotonic()
    s.server.stop(WHY)
    took = time.monotonic() - start
    assert 0.25 < took < 0.8, took
    [answer] = s.of(call_id)
    assert answer.status == "cancelled" and answer.error == (
        WHY + ", but its code has not returned 0.3s after the cancel: the node stops without it, and what it drives "
        "may not have stopped"), answer
    said = ("cancelled call %s of arm.stuck: %s, but its code has not returned 0.3s after the cancel; the node stops "
            "without it (what it drives may not have stopped)" % (call_id, WHY))
    assert ("WARNING", said) in log.lines, log.lines
    s.impl.release.set()
    time.sleep(0.1)
    assert len(s.of(call_id)) == 1  # its code returning later answers nothing more


def test_calls_that_are_not_running_code_are_answered_at_once_and_new_calls_are_refused(log):
    s = Served()
    later = s.send("later")  # waits on an outcome's delay: no code runs
    time.sleep(0.1)
    start = time.monotonic()
    s.server.stop(WHY)
    assert time.monotonic() - start < 0.2
    assert s.wait(later).status == "cancelled" and s.wait(later).error == WHY
    refused = s.send("quick")
    answer = s.wait(refused)
    assert answer.status == "rejected" and answer.error == WHY + ": the call was not run", answer
    assert ("INFO", "cancelled call %s of arm.later: %s" % (later, WHY)) in log.lines, log.lines


def test_a_call_waiting_for_a_cancelled_holder_is_answered_and_never_runs():
    s = Served(grace=0.5)
    holder = s.send("park")
    assert s.impl.started.wait(5)
    s.server.handle_cancel(CancelRequest(holder, "arm", "work").encode())  # the coordinator's cancel ...
    waiting = s.send("quick")                                              # ... and the tree goes on
    s.server.stop(WHY)
    assert s.wait(holder).error == "cancelled by the coordinator"  # its coordinator knew already
    answer = s.wait(waiting)
    assert answer.status == "cancelled" and answer.error == WHY, answer
    time.sleep(0.6)  # the waiting call's grace is over: it is neither run nor answered again
    assert len(s.of(waiting)) == 1 and len(s.of(holder)) == 1


def test_an_idle_module_stops_at_once():
    s = Served()
    assert s.wait(s.send("quick")).status == "succeeded"
    start = time.monotonic()
    assert s.server.stop(WHY) == []
    assert time.monotonic() - start < 0.05


@pytest.mark.parametrize("reason, said", [
    ("signal-2", "SIGINT"), ("signal-15", "SIGTERM"),
    ("external shutdown request from [/rosnode_1_2]: [user request]", "a shutdown request from /rosnode_1_2: user request"),
    ("new node registered with same name", "another node registered with its name"),
    ("stopped", "stopped")])
def test_what_stopped_the_node_is_said_in_a_user_s_words(reason, said):
    assert stop_cause(reason) == said
