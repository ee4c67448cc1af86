"""TopicSender: what waits for a subscriber waits a bounded time, never goes into a dead subscriber's
socket, and what was taken back is never sent (no ROS master)."""
from __future__ import annotations

import threading
import time

from std_msgs.msg import String

from coordinator.sender import TopicSender
from tests.unit.test_sender import _pair, _Pub, _read_frames


def test_a_message_is_not_written_into_the_socket_of_a_subscriber_that_died():
    """A module node killed while it owed nothing: its connection stays until a write fails, and the
    first write into it 'succeeds'. The call must wait for its next node instead."""
    dead, dead_peer = _pair()
    sender = TopicSender("/bmtree/call/probe", String, pub=_Pub([dead]))
    dead_peer.close()
    sender.publish(String("call"), key="c1")
    assert dead.done and sender.waiting_since() is not None
    conn, theirs = _pair()
    sender.impl.connections.append(conn)
    assert sender.connected() == 1 and _read_frames(theirs, 1) == ["call"]
    sender.unregister()


def test_what_waits_too_long_is_given_up_and_its_keys_told():
    told = []
    done = threading.Event()
    sender = TopicSender("/bmtree/call/probe", String, pub=_Pub([]))
    sender.give_up_after(0.2, lambda keys: (told.append(keys), done.set()))
    sender.publish(String("a"), key="a")
    sender.publish(String("cancel"))  # no key: dropped silently
    started = time.monotonic()
    assert done.wait(5) and 0.15 <= time.monotonic() - started < 2.0
    end = time.monotonic() + 2.0
    while sender.waiting_since() is not None:  # the cancel, published a moment later, goes a moment later
        assert time.monotonic() < end
        time.sleep(0.01)
    assert told == [["a"]]
    conn, theirs = _pair()
    sender.impl.connections.append(conn)
    assert sender.connected() == 0  # given up: never sent to a node that connects later
    sender.unregister()


def test_expire_keeps_the_newer_ones_and_a_later_one_gets_its_own_time():
    sender = TopicSender("/bmtree/call/probe", String, pub=_Pub([]))
    sender.publish(String("old"), key="old")
    cut = time.monotonic()
    time.sleep(0.01)
    sender.publish(String("new"), key="new")
    assert sender.expire(cut) == ["old"] and sender.waiting_since() > cut
    done = threading.Event()
    told = []
    sender.give_up_after(0.1, lambda keys: (told.append(keys), done.set()))
    sender.publish(String("newest"), key="newest")  # arms the bound for what waits now
    assert done.wait(5) and told[0][0] == "new"
    time.sleep(0.3)
    assert sorted(k for keys in told for k in keys) == ["new", "newest"]
    sender.unregister()


def test_a_held_message_can_be_taken_back_before_the_flush():
    """A call and its cancel in one tick while the module's node is not connected: the call is taken
    back from the tick's held messages, so the next node never gets it."""
    sender = TopicSender("/bmtree/call/probe", String, pub=_Pub([]))
    assert sender.publish(String("call"), hold=True, key="c1")
    assert sender.discard("c1")
    sender.flush()
    assert sender.waiting_since() is None
    sender.unregister()


def test_unregister_stops_the_bound():
    told = []
    sender = TopicSender("/bmtree/call/probe", String, pub=_Pub([]))
    sender.give_up_after(0.1, told.append)
    sender.publish(String("a"), key="a")
    sender.unregister()
    time.sleep(0.3)
    assert told == []
