"""modules.actions without ROS: a stand-in actionlib client under the real module runtime (answers,
cancels, the early result, a missing or silent server, feedback)."""
from __future__ import annotations

import logging
import os
import threading
import time

import pytest

from comm import CancelRequest, FunctionResult
from modules.actions import Action, ActionFailed, state_name
from modules.definition import load_definition
from modules.runtime import BasicModule, ModuleServer
from tests.conftest import ROOT

DEFINITION = os.path.join(ROOT, "modules", "example", "mobile_base.json")
TARGET = {"position": {"x": 1.0, "y": 2.0}, "orientation": {"w": 1.0}}
ACTIVE, PREEMPTED, SUCCEEDED, ABORTED, REJECTED, RECALLED, LOST = 1, 2, 3, 4, 5, 8, 9
DONE = 7


class Handle:
    """A ClientGoalHandle's part that Action uses."""

    def __init__(self, transition):
        self.transition = transition
        self.state, self.status, self.text, self.result = 0, ACTIVE, "", None
        self.cancels = 0
        self.on_cancel = None  # what the server does with a cancel

    def end(self, status, text="", result=None):
        self.status, self.text, self.result, self.state = status, text, result, DONE
        self.transition(self)

    def get_comm_state(self):
        return self.state

    def get_goal_status(self):
        return self.status

    def get_goal_status_text(self):
        return self.text

    def get_result(self):
        return self.result

    def cancel(self):
        self.cancels += 1
        if self.on_cancel is not None:
            self.on_cancel(self)


class Client:
    """The ROS client's stand-in: ``behave(handle, feedback)`` is the server, run inside ``send``."""

    where = "/move_base"

    def __init__(self, behave=None, missing="", age=0.1):
        self.behave = behave
        self._missing = missing
        self.age = age
        self.left = ""  # server_left(): why its server is gone
        self.handles = []
        self.goals = []
        self.forgotten = []

    def server_left(self):
        return self.left

    def forget(self, handle):
        self.forgotten.append(handle)

    def missing(self):
        return self._missing

    def status_age(self):
        return self.age

    def send(self, goal, transition, feedback):
        h = Handle(transition)
        self.goals.append(goal)
        self.handles.append(h)
        if self.behave is not None:
            self.behave(h, lambda msg: feedback(h, msg))
        return h

    def shutting_down(self):
        return False


class Base(BasicModule):
    def __init__(self, client, **options):
        super().__init__()
        self.seen = []
        self._move_base = Action(self, "move_base", object, client=client, **options)

    def go_to(self, target):
        return self._move_base.run(("goal", target.position.x), outputs=lambda r: {"success": True, "position": r},
                                   feedback=self._feedback)

    def _feedback(self, msg):
        self.seen.append(msg)


class Served:
    def __init__(self, client, grace=1.0, **options):
        self.results = []
        self.cond = threading.Condition()
        self.impl = Base(client, **options)
        self.server = ModuleServer(load_definition(DEFINITION), self.impl, self._res, lambda t: None,
                                   cancel_grace=grace)

    def _res(self, text):
        with self.cond:
            self.results.append(FunctionResult.decode(text))
            self.cond.notify_all()

    def call(self):
        call = self.server.definition.function("go_to").build_call({"target": TARGET})
        self.server.handle_call(call.encode())
        return call.call_id

    def cancel(self, call_id):
        self.server.handle_cancel(CancelRequest(call_id, "mobile_base", "go_to").encode())

    def result(self, call_id, timeout=5.0):
        with self.cond:
            assert self.cond.wait_for(lambda: any(r.call_id == call_id for r in self.results), timeout), self.results
            return next(r for r in self.results if r.call_id == call_id)


class Logged(logging.Handler):
    """What the module runtime and Action log (pytest's logging plugin is off in this suite)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.text = ""

    def emit(self, record):
        self.text += record.getMessage() + "\n"

    def __enter__(self):
        logging.getLogger("bmtree.module").addHandler(self)
        return self

    def __exit__(self, *exc):
        logging.getLogger("bmtree.module").removeHandler(self)


def later(seconds, fn):
    threading.Timer(seconds, fn).start()


def test_a_result_that_arrives_before_send_returns_is_taken():
    """The early-result race: the goal is DONE inside ``send`` (SimpleActionClient loses this one)."""
    client = Client(lambda h, fb: h.end(SUCCEEDED, result={"x": 3.0}))
    s = Served(client)
    for _ in range(20):
        r = s.result(s.call(), timeout=2.0)
        assert r.status == "succeeded", r.error
        assert dict(zip(r.names, r.msgs))["position"].x == 3.0
    assert client.goals[0] == ("goal", 1.0)


def test_a_goal_that_succeeds_later_with_feedback():
    def behave(h, feedback):
        feedback("halfway")
        later(0.1, lambda: h.end(SUCCEEDED, result={"x": 1.0}))

    s = Served(Client(behave))
    assert s.result(s.call()).status == "succeeded"
    assert s.impl.seen == ["halfway"]


def test_a_feedback_callback_that_raises_is_logged_and_the_goal_goes_on():
    def behave(h, feedback):
        feedback("x")
        h.end(SUCCEEDED, result={"x": 1.0})

    s = Served(Client(behave))
    s.impl.seen = None  # seen.append: AttributeError in the feedback callback
    with Logged() as logged:
        assert s.result(s.call()).status == "succeeded"
    assert "the feedback callback of /move_base raised" in logged.text


@pytest.mark.parametrize("status, text, said", [
    (ABORTED, "no valid plan", "/move_base: goal ABORTED: no valid plan"),
    (ABORTED, "", "/move_base: goal ABORTED (the server gave no status text)"),
    (REJECTED, "target off the map", "/move_base: goal REJECTED: target off the map"),
    (PREEMPTED, "another client sent a goal", "/move_base: goal PREEMPTED: another client sent a goal"),
    (RECALLED, "x", "/move_base: goal RECALLED: x"),
    (LOST, "", "/move_base: goal LOST (the server gave no status text)"),
])
def test_a_goal_that_does_not_succeed_fails_the_call_naming_its_state(status, text, said):
    s = Served(Client(lambda h, fb: later(0.05, lambda: h.end(status, text))))
    r = s.result(s.call())
    assert (r.status, r.error) == ("failed", said)


def test_a_cancelled_call_cancels_the_goal_and_answers_cancelled_once_the_server_ended_it():
    client = Client()
    s = Served(client)
    call = s.call()
    time.sleep(0.2)
    assert client.handles and client.handles[0].cancels == 0
    client.handles[0].on_cancel = lambda h: later(0.05, lambda: h.end(PREEMPTED, "cancelled"))
    t0 = time.monotonic()
    s.cancel(call)
    r = s.result(call)
    assert r.status == "cancelled" and client.handles[0].cancels == 1
    assert time.monotonic() - t0 < 0.5  # when the server ended it, not after the runtime's 1 s grace
    # the module is free: the next call runs
    client.behave = lambda h, fb: h.end(SUCCEEDED, result={"x": 2.0})
    assert s.result(s.call()).status == "succeeded"


def test_a_server_that_ignores_the_cancel_is_waited_for_a_bounded_time():
    client = Client()
    s = Served(client, grace=1.0, cancel_timeout=0.3)
    call = s.call()
    time.sleep(0.1)
    with Logged() as logged:
        t0 = time.monotonic()
        s.cancel(call)
        assert s.result(call).status == "cancelled"
        elapsed = time.monotonic() - t0
        client.behave = lambda h, fb: h.end(SUCCEEDED, result={"x": 2.0})
        assert s.result(s.call()).status == "succeeded"  # not refused busy: the code returned within the grace
    assert 0.25 < elapsed < 0.9
    assert "/move_base did not end the goal within 0.3s of its cancel" in logged.text
    assert "has not returned" not in logged.text  # the runtime's warning of code that ignores cancels
    # the answer says the goal may go on, which bmtree run lists under "may still be running"
    assert s.result(call).error == ("cancelled by the coordinator, but /move_base did not end the goal within 0.3s "
                                    "of its cancel: it may not have stopped")
    assert client.forgotten == [client.handles[1]]  # the ended goal's id is let go; the running one's is kept


def test_a_server_that_ends_the_cancelled_goal_gives_a_plain_cancelled_answer():
    client = Client()
    s = Served(client, cancel_timeout=2.0)
    call = s.call()
    time.sleep(0.1)
    client.handles[0].on_cancel = lambda h: h.end(PREEMPTED, "cancelled by the client")
    s.cancel(call)
    assert s.result(call).error == "cancelled by the coordinator"


def test_the_default_cancel_wait_ends_before_the_runtimes_grace():
    s = Served(Client(), grace=0.5)
    assert s.impl._move_base._cancel_timeout() == pytest.approx(0.4)
    assert Action(BasicModule(), "a", object, client=Client())._cancel_timeout() == pytest.approx(0.8)


def test_no_server_fails_the_call_naming_the_namespace_and_sends_no_goal():
    client = Client(missing="nothing publishes /move_base/status")
    s = Served(client, connect_timeout=0.2)
    r = s.result(s.call())
    assert r.status == "failed"
    assert r.error == "no action server on /move_base within 0.2s: nothing publishes /move_base/status"
    assert client.goals == []


def test_a_call_cancelled_while_connecting_sends_no_goal():
    client = Client(missing="nothing publishes /move_base/status")
    s = Served(client, connect_timeout=30)
    call = s.call()
    time.sleep(0.1)
    s.cancel(call)
    assert s.result(call, timeout=1.0).status == "cancelled"
    assert client.goals == []


def test_a_server_that_falls_silent_loses_the_goal():
    client = Client()
    s = Served(client, silence_timeout=0.3)
    call = s.call()
    time.sleep(0.1)
    client.age = 2.0  # no status for 2 s: the server died
    r = s.result(call, timeout=3.0)
    assert r.status == "failed" and r.error.startswith("/move_base: goal LOST: no status from the server for 2.0s")
    assert client.handles[0].cancels == 1


def test_a_server_whose_process_is_gone_loses_the_goal_without_waiting_for_silence():
    client = Client()
    s = Served(client, silence_timeout=60)
    call = s.call()
    time.sleep(0.1)
    client.left = "its server /move_base closed its connection to /move_base/status: it stopped or died"
    r = s.result(call, timeout=10.0)  # at the next look (0.5 s), not after 60 s of silence
    assert r.status == "failed" and r.error == ("/move_base: goal LOST: its server /move_base closed its connection "
                                                "to /move_base/status: it stopped or died")


def test_a_goal_cancelled_because_the_node_stops_says_so():
    """The node's shutdown hook cancels the goal; the server honours it (PREEMPTED, its own text), which
    must not read as the server's failure. The coordinator did not cancel the call: it answers ``failed``."""
    client = Client()
    s = Served(client)
    call = s.call()
    time.sleep(0.1)
    client.handles[0].on_cancel = lambda h: later(0.05, lambda: h.end(PREEMPTED, "cancelled by the client"))
    stop = threading.Thread(target=s.impl._move_base._cancel_all)  # rospy.on_shutdown runs it (is_shutdown(): False)
    t0 = time.monotonic()
    stop.start()
    r = s.result(call)
    stop.join(2.0)
    assert (r.status, r.error) == ("failed", "/move_base: the module's node stops: goal cancelled")
    assert client.handles[0].cancels == 1  # by the hook only, not again by the call's own wait
    assert not stop.is_alive() and time.monotonic() - t0 < 0.5


def test_a_goal_the_server_does_not_end_when_the_node_stops_is_waited_for_a_bounded_time():
    client = Client()
    s = Served(client, cancel_timeout=0.3)
    call = s.call()
    time.sleep(0.1)
    with Logged() as logged:
        s.impl._move_base._cancel_all()
        r = s.result(call, timeout=2.0)
    assert (r.status, r.error) == ("failed", "/move_base: the module's node stops: goal cancelled")
    assert "/move_base did not end the goal within 0.3s of its cancel as the node stops" in logged.text


def test_a_call_while_the_node_stops_sends_no_goal():
    client = Client(missing="nothing publishes /move_base/status")
    s = Served(client, connect_timeout=30)
    s.impl._move_base._cancel_all()
    r = s.result(s.call(), timeout=1.0)
    assert (r.status, r.error) == ("failed", "/move_base: the module's node stops: no goal sent")
    assert client.goals == []


class Link:
    """A rospy subscriber connection's part that _RosClient.missing looks at."""

    def __init__(self, publisher, done=False):
        self.callerid_pub, self.done = publisher, done


def ros_client(status_from, links, stale_after=5.0, age=0.1):
    """A _RosClient over a stand-in actionlib ActionClient: the last status came from ``status_from``
    (None: none came), ``links`` its subscribers' connections."""
    from types import SimpleNamespace as NS

    from modules.actions import _RosClient

    rc = _RosClient.__new__(_RosClient)
    rc.where, rc.stale_after = "/move_base", stale_after
    last = None if status_from is None else NS(_connection_header={"callerid": status_from})
    pub = NS(impl=NS(has_connection=lambda node: node == "/move_base_server"))
    sub = NS(impl=NS(connections=links))
    rc.client = NS(last_status_msg=last, status_at=time.monotonic() - age, status_sub=sub, result_sub=sub,
                   feedback_sub=sub, pub_goal=pub, pub_cancel=pub)
    return rc


def test_a_server_that_left_is_no_server_though_actionlib_keeps_its_last_status():
    assert ros_client("/move_base_server", [Link("/move_base_server")]).missing() == ""
    assert ros_client(None, []).missing() == "nothing publishes /move_base/status"
    # stopped: rospy dropped (or is closing) the connection; its last status is still there
    assert ros_client("/move_base_server", []).missing() == "nothing publishes /move_base/status"
    assert ros_client("/move_base_server", [Link("/move_base_server", done=True)]).missing() == \
        "nothing publishes /move_base/status"
    # killed, the connection not (yet) dropped: its status is older than the silence timeout
    assert ros_client("/move_base_server", [Link("/move_base_server")], age=7.0).missing() == \
        "its server /move_base_server has published nothing on /move_base/status for 7.0s"
    assert ros_client("/move_base_server", [Link("/move_base_server")], stale_after=None, age=70.0).missing() == ""


def test_action_failed_carries_the_state_and_text():
    exc = ActionFailed("m", "/move_base", ABORTED, "why")
    assert (exc.namespace, exc.state, exc.text, str(exc)) == ("/move_base", ABORTED, "why", "m")
    assert [state_name(n) for n in (3, 4, None, 42)] == ["SUCCEEDED", "ABORTED", "unknown", "status 42"]


def test_the_readme_example_runs(tmp_path):
    import runpy

    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        section = fh.read().split("### Wrapping an actionlib action", 1)[1]
    (tmp_path / "mobile_base.py").write_text(section.split("```python", 1)[1].split("```", 1)[0])
    impl = runpy.run_path(str(tmp_path / "mobile_base.py"))["MobileBase"]()

    def behave(h, feedback):
        fb = type("Feedback", (), {})()
        fb.base_position = type("Pose", (), {"pose": type("P", (), {"position": {"x": 0.9, "y": 2.0, "z": 0.0}})})()
        feedback(fb)
        h.end(SUCCEEDED)

    client = Client(behave)
    impl._move_base = Action(impl, "move_base", object, client=client)
    results = []
    ModuleServer(load_definition(DEFINITION), impl, results.append, lambda t: None).handle_call(
        load_definition(DEFINITION).function("go_to").build_call({"target": TARGET}).encode())
    deadline = time.monotonic() + 5
    while not results and time.monotonic() < deadline:
        time.sleep(0.01)
    r = FunctionResult.decode(results[0])
    assert r.status == "succeeded", r.error
    assert r.values["position"].x == 0.9 and client.goals[0].target_pose.header.frame_id == "map"
