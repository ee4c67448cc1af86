"""TopicSender: a module's call topic written without ever blocking the caller (no ROS master)."""
from __future__ import annotations

import socket
import struct
import threading

from std_msgs.msg import String

from coordinator.sender import TopicSender


class _Conn:
    """The parts of a rospy TCPROS connection the sender uses."""

    def __init__(self, sock):
        self.socket = sock
        self.done = False
        self.stat_bytes = 0
        self.stat_num_msg = 0

    def close(self):
        self.done = True
        self.socket.close()
        self.socket = None


class _Impl:
    def __init__(self, conns):
        self.connections = conns


class _Pub:
    resolved_name = "/bmtree/call/probe"

    def __init__(self, conns):
        self.impl = _Impl(conns)
        self.unregistered = False

    def get_num_connections(self):
        return len(self.impl.connections)

    def unregister(self):
        self.unregistered = True


def _pair():
    ours, theirs = socket.socketpair()
    return _Conn(ours), theirs


def _read_frames(sock, count):
    """``count`` TCPROS frames of std_msgs/String from ``sock``, as texts."""
    buf = b""
    out = []
    while len(out) < count:
        chunk = sock.recv(1 << 20)
        assert chunk, "the sender closed the connection"
        buf += chunk
        while len(buf) >= 4:
            size = struct.unpack("<I", buf[:4])[0]
            if len(buf) < 4 + size:
                break
            body = buf[4:4 + size]
            out.append(body[4:4 + struct.unpack("<I", body[:4])[0]].decode("utf-8"))
            buf = buf[4 + size:]
    return out


def test_a_reader_that_stops_never_blocks_the_publisher_and_loses_nothing_within_the_limit():
    conn, theirs = _pair()
    sender = TopicSender("/bmtree/call/probe", String, limit=10000, pub=_Pub([conn]))
    texts = ["%04d:" % i + "x" * 100000 for i in range(300)]  # 30 MB: far more than the socket holds
    done = threading.Event()

    def publish_all():
        for t in texts:
            sender.publish(String(t))
        done.set()

    threading.Thread(target=publish_all, daemon=True).start()
    assert done.wait(120), "publish blocked behind a reader that does not read"
    assert _read_frames(theirs, len(texts)) == texts  # all of them, in order, once read again
    sender.unregister()
    assert sender.dropped == 0


def test_past_the_limit_the_oldest_waiting_messages_are_dropped():
    conn, theirs = _pair()
    sender = TopicSender("/bmtree/call/probe", String, limit=5, pub=_Pub([conn]))
    for i in range(200):
        sender.publish(String("%03d:" % i + "y" * 100000))
    assert sender.dropped > 0
    theirs.close()
    sender.unregister(flush=5.0)


def test_held_messages_leave_together_at_flush_in_order():
    conn, theirs = _pair()
    sender = TopicSender("/bmtree/call/probe", String, pub=_Pub([conn]))
    assert sender.publish(String("a"), hold=True) and sender.publish(String("b"), hold=True)
    theirs.setblocking(False)
    try:
        theirs.recv(100)
        raise AssertionError("a held message was sent before flush()")
    except BlockingIOError:
        pass
    theirs.setblocking(True)
    sender.publish(String("c"), hold=True)
    sender.flush()
    assert _read_frames(theirs, 3) == ["a", "b", "c"]
    assert conn.stat_num_msg == 3
    sender.publish(String("d"))  # not held: at once
    assert _read_frames(theirs, 1) == ["d"]
    sender.unregister()


def test_a_broken_connection_is_closed_and_the_others_still_get_their_messages():
    bad, bad_peer = _pair()
    good, good_peer = _pair()
    sender = TopicSender("/bmtree/call/probe", String, pub=_Pub([bad, good]))
    bad_peer.close()
    for i in range(50):
        sender.publish(String("m%d" % i))
    assert _read_frames(good_peer, 50) == ["m%d" % i for i in range(50)]
    assert bad.done
    sender.unregister()


def test_messages_sent_while_nobody_listens_wait_for_a_subscriber_in_order_unless_taken_back():
    """A module's node restarting: its old connection is gone, the new one not made yet. Calls sent
    meanwhile wait (a lost call would wait out its whole timeout) and go, in order, once it connects;
    one taken back (its cancel) or no longer owed does not go."""
    sender = TopicSender("/bmtree/call/probe", String, pub=_Pub([]))
    for key in ("c1", "c2", "c3", "c4"):
        sender.publish(String(key), key=key)
    assert sender.publish(String("c5"), hold=True, key="c5")
    sender.flush()
    assert sender.discard("c2") and not sender.discard("c2") and not sender.discard("nope")
    conn, theirs = _pair()
    sender.impl.connections.append(conn)
    sender.publish(String("c6"), key="c6")   # after the others, though a subscriber is there now
    assert sender.connected(lambda key: key != "c3") == 4
    assert _read_frames(theirs, 4) == ["c1", "c4", "c5", "c6"]
    sender.publish(String("c7"), key="c7")   # connected: at once
    assert _read_frames(theirs, 1) == ["c7"]
    sender.unregister()


def test_a_connection_whose_subscriber_died_is_dropped_and_later_messages_wait_for_a_new_one():
    dead, dead_peer = _pair()
    alive, alive_peer = _pair()
    sender = TopicSender("/bmtree/call/probe", String, pub=_Pub([dead, alive]))
    alive.socket.settimeout(0.5)  # a socket with a timeout (a process-wide default) is not a dead one
    dead_peer.close()
    assert sender.drop_closed() == 1 and dead.done and not alive.done
    alive.close()  # now nobody listens: kept until one connects
    sender.impl.connections[:] = []
    sender.publish(String("retry"), key="k")
    conn, theirs = _pair()
    sender.impl.connections.append(conn)
    assert sender.connected() == 1 and _read_frames(theirs, 1) == ["retry"]
    sender.unregister()
    alive_peer.close()
