"""A control request that cannot be read (nested too deep, not JSON, not an object, too large) is refused
as every malformed command is: answered ``malformed command: …`` with why, to its sender's id when it
can be read, and recorded; it raised RecursionError in the subscriber thread (an audit sent one nested
20,000 levels deep)."""
from __future__ import annotations

import json

import pytest
import rospy

from coordinator import controlros
from tests.unit.test_control_malformed import TREE
from tests.unit.test_control_stop import Timed, _run


class _Pub:
    made = []

    def __init__(self, *args, **kwargs):
        self.sent = []
        self.made.append(self)

    def publish(self, msg):
        self.sent.append(json.loads(msg.data))


class _Sub:
    def __init__(self, topic, cls, callback, **kwargs):
        self.callback = callback


class _Msg:
    def __init__(self, data):
        self.data = data
        self._connection_header = {"callerid": "/intruder"}


DEEP = '{"id": "deep-1", "command": "set", "key": "x", "value": %s}' % ("[" * 20000 + "]" * 20000)


@pytest.fixture
def ros_ctl(monkeypatch):
    """``bmtree run --control``'s controller of node /bmtree_run, on stand-ins of rospy's topics."""
    monkeypatch.setattr(_Pub, "made", [])
    monkeypatch.setattr(rospy, "Publisher", _Pub)
    monkeypatch.setattr(rospy, "Subscriber", _Sub)
    monkeypatch.setattr(rospy, "get_name", lambda: "/bmtree_run")
    return controlros.ros_controller(True)


def test_an_unreadable_request_is_refused_in_the_subscriber_thread_without_raising(ros_ctl):
    ctl = ros_ctl
    for text in (DEEP, '{"id": "b-2", "command": ', "[1, 2]"):
        ctl.subscription.callback(_Msg(text))   # rospy's thread: nothing may raise here
    ctl.may_tick()   # the ticking thread answers them
    [pub] = _Pub.made
    assert [(r["id"], r["ok"], r["answer"]) for r in pub.sent] == [
        ("deep-1", False, "malformed command: the request cannot be read: JSON nested deeper than 100 levels"),
        ("b-2", False, "malformed command: the request cannot be read: payload is not valid JSON: Expecting value: "
                       "line 1 column 26 (char 25)"),
        (None, False, "malformed command: the request cannot be read: payload is not a JSON object (got list)")]


def test_an_unreadable_request_for_another_run_is_left_to_it(ros_ctl):
    """Its ``to``, read from its text, names another run's node: every run on the master answered it."""
    ctl = ros_ctl
    for to in ("/bmtree_other", "/bmtree_run"):
        ctl.subscription.callback(_Msg('{"id": "d-%s", "to": "%s", "command": "set", "value": %s' % (
            to[-3:], to, "[" * 200)))
    ctl.may_tick()
    [pub] = _Pub.made
    assert [r["id"] for r in pub.sent] == ["d-run"]


def test_read_request_never_raises():
    from coordinator.control import Unreadable, read_request

    assert read_request('{"command": "pause"}') == {"command": "pause"}
    for text in (DEEP, "x" * 70000, b"\xff", None, '"text"'):
        assert isinstance(read_request(text), Unreadable)


@pytest.fixture
def go_cleanup(tmp_path, sim_defs):
    from coordinator.testing.kit import TreeTest

    path = tmp_path / "go.yaml"
    path.write_text(TREE)
    return TreeTest(str(path), definitions=sim_defs)


def test_an_unreadable_request_is_recorded_and_the_run_goes_on(go_cleanup, monkeypatch):
    from coordinator.control import read_request

    go_cleanup.mocks["navigation.go_to"].succeed(room="kitchen", delay=2.0)

    class _Script(Timed):
        def may_tick(self):
            now = self.ctx.clock.now() - self.ctx.started
            if self.script and self.script[0][0] <= now:
                self.submit(read_request(self.script.pop(0)[1], by="/intruder"))
            return super().may_tick()

    ctl = _Script([(0.5, DEEP)])
    run = _run(go_cleanup, ctl, monkeypatch)
    assert ctl.answers() == [("deep-1", False, "malformed command: the request cannot be read: JSON nested deeper "
                                               "than 100 levels")]
    [record] = run.control_records
    assert (record["command"], record["ok"], record["by"]) == ("?", False, "/intruder")
    assert run.succeeded and run.cleanup_status == "SUCCESS"
