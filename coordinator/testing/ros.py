"""Real-ROS helpers for integration tests: a probe node inside the test process.

``rospy.init_node`` works once per process, so the probe is initialised once per
test session against the session's master; nodes under test run as processes.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, Set

from comm import settle_new_connection

__all__ = ["RosProbe", "Collector", "drop_closed", "node_uris", "wait_subscribed"]


class Collector:
    """Every ``std_msgs/String`` payload seen on a topic, in order (thread-safe)."""

    def __init__(self, topic: str):
        self.topic = topic
        self._items: List[str] = []
        self._cond = threading.Condition()
        self.sub: Any = None

    def _add(self, msg: Any) -> None:
        with self._cond:
            self._items.append(msg.data)
            self._cond.notify_all()

    @property
    def items(self) -> List[str]:
        with self._cond:
            return list(self._items)

    def clear(self) -> None:
        with self._cond:
            self._items.clear()

    def wait_for(self, predicate: Callable[[str], bool], timeout: float = 10.0, count: int = 1) -> List[str]:
        """The first ``count`` payloads matching ``predicate``; AssertionError after ``timeout``."""
        end = time.monotonic() + timeout
        with self._cond:
            while True:
                found = [i for i in self._items if predicate(i)]
                if len(found) >= count:
                    return found[:count]
                left = end - time.monotonic()
                if left <= 0:
                    raise AssertionError("%d of %d expected messages on %s within %gs; last seen: %s" % (
                        len(found), count, self.topic, timeout, self._items[-3:]))
                self._cond.wait(left)


class RosProbe:
    """Publish and collect ``std_msgs/String`` payloads from the test process."""

    def __init__(self, name: str = "bmtree_test_probe"):
        import rospy

        if not rospy.core.is_initialized():
            rospy.init_node(name, anonymous=True, disable_signals=True)
        self._pubs: Dict[str, Any] = {}

    def publisher(self, topic: str, subscribers: int = 1, timeout: float = 10.0, latch: bool = False) -> Any:
        """A publisher that is connected to at least ``subscribers`` subscribers."""
        import rospy
        from std_msgs.msg import String

        pub = self._pubs.get(topic)
        if pub is None:
            pub = self._pubs[topic] = rospy.Publisher(topic, String, queue_size=10000, latch=latch)
        end = time.monotonic() + timeout
        while pub.get_num_connections() < subscribers or self._live_connections(pub) < subscribers:
            if time.monotonic() > end:
                raise AssertionError("only %d of %d subscribers connected to %s" % (
                    self._live_connections(pub), subscribers, topic))
            time.sleep(0.02)
        return pub

    @staticmethod
    def _live_connections(pub: Any) -> int:
        """Connections to running nodes that subscribe the topic now: a node that stopped (or was
        killed, and is still registered) leaves its connection in the publisher until a write
        to it fails, and must not be counted."""
        import rosgraph
        import rospy

        from modules.discovery import node_alive

        drop_closed(pub)
        master = rosgraph.Master(rospy.get_name())
        _, subs, _ = master.getSystemState()
        nodes = [n for n in next((n for t, n in subs if t == pub.resolved_name), [])
                 if n != rospy.get_name() and pub.impl.has_connection(n)]  # not this process itself
        live = 0
        for node in nodes:
            try:
                live += node_alive(master.lookupNode(node), 0.5)
            except rosgraph.masterapi.Error:
                pass
        return live

    def publish(self, topic: str, text: str, subscribers: int = 1) -> None:
        from std_msgs.msg import String

        self.publisher(topic, subscribers).publish(String(text))

    def collect(self, topic: str, publishers: int = 0, timeout: float = 10.0, nodes: Sequence[str] = ()) -> Collector:
        """Start collecting ``topic``; with ``publishers``, wait until that many are connected, and
        until each of ``nodes`` is (by name: a count can be made up by other nodes, or by a
        publisher of this very process)."""
        import rospy
        from std_msgs.msg import String

        c = Collector(topic)
        c.sub = rospy.Subscriber(topic, String, c._add, queue_size=100000)
        uris = node_uris(nodes)
        mine = rospy.get_node_uri()  # this process's own publisher of the topic is no peer
        end = time.monotonic() + timeout
        while True:
            peers = {x.endpoint_id for x in c.sub.impl.connections} - {mine}
            if len(peers) >= publishers and uris <= peers:
                if publishers or uris:
                    settle_new_connection()
                return c
            if time.monotonic() > end:
                raise AssertionError("only %d of %d publishers connected to %s (waiting for %s)" % (
                    len(peers), publishers, topic, ", ".join(nodes) or "any"))
            time.sleep(0.02)

    def close_collector(self, c: Optional[Collector]) -> None:
        if c is not None and c.sub is not None:
            c.sub.unregister()


def node_uris(nodes: Sequence[str]) -> Set[str]:
    """The XML-RPC URIs of ``nodes``: a subscriber's connection names its publisher by URI."""
    import rosgraph
    import rospy

    master = rosgraph.Master(rospy.get_name())
    return {master.lookupNode(n) for n in nodes}


def drop_closed(pub: Any) -> None:
    """Close ``pub``'s connections to subscribers that went away (their socket is at EOF): rospy
    keeps them until a write fails, and one to an earlier node of the same name would pass for
    the new node's and swallow the first message."""
    from coordinator.sender import peer_gone

    for c in list(pub.impl.connections):
        sock = getattr(c, "socket", None)
        if sock is not None and peer_gone(sock):
            c.close()


def wait_subscribed(pub: Any, nodes: Sequence[str], timeout: float = 20.0) -> None:
    """Until each of ``nodes`` (by name) is connected to publisher ``pub`` (live connections only)."""
    end = time.monotonic() + timeout
    while True:
        drop_closed(pub)
        if set(nodes) <= {c.endpoint_id for c in pub.impl.connections}:
            return
        if time.monotonic() > end:
            raise AssertionError("%s: not all of %s subscribed" % (pub.resolved_name, ", ".join(nodes)))
        time.sleep(0.02)
