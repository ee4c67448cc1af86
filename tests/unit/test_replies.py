"""ReplyPublisher: an answer waits (bounded) for its asker's connection (no ROS master)."""
from __future__ import annotations

import threading
import time

from comm.replies import ReplyPublisher, caller_of


class _Conn:
    def __init__(self, endpoint_id):
        self.endpoint_id = endpoint_id


class _Impl:
    def __init__(self):
        self.connections = []


class _Pub:
    def __init__(self):
        self.impl = _Impl()
        self.sent = []

    def publish(self, msg):
        self.sent.append((msg, [c.endpoint_id for c in self.impl.connections]))


def test_an_answer_waits_for_its_caller_to_connect_and_then_goes_at_once():
    pub = _Pub()
    replies = ReplyPublisher(pub, patience=10.0)
    replies.heard("/coordinator")
    timer = threading.Timer(0.2, lambda: pub.impl.connections.append(_Conn("/coordinator")))
    timer.start()
    replies.publish("answer 1")
    assert pub.sent == [("answer 1", ["/coordinator"])] and replies.held == 1
    replies.heard("/coordinator")  # known now: no more waiting
    replies.publish("answer 2")
    assert pub.sent[-1] == ("answer 2", ["/coordinator"]) and replies.held == 1


def test_a_caller_that_never_reads_answers_is_waited_for_once():
    pub = _Pub()
    pub.impl.connections.append(_Conn("/blackboard"))
    replies = ReplyPublisher(pub, patience=0.2)
    replies.heard("/rostopic_pub")
    start = time.monotonic()
    replies.publish("a")
    waited = time.monotonic() - start
    replies.heard("/rostopic_pub")
    replies.publish("b")  # not held again
    assert waited >= 0.2 and replies.held == 1 and [m for m, _ in pub.sent] == ["a", "b"]


def test_without_callers_heard_it_is_the_plain_publisher():
    pub = _Pub()
    replies = ReplyPublisher(pub)
    replies.heard(None)
    replies.publish("x")
    assert pub.sent == [("x", [])] and replies.held == 0


def test_caller_of_reads_the_connection_header():
    class Msg:
        _connection_header = {"callerid": "/bmtree_1"}

    assert caller_of(Msg()) == "/bmtree_1" and caller_of(object()) is None
