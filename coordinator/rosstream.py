"""The run stream over ROS topics (README, "Run stream"): one topic per channel, written
without ever slowing the tick.
"""
from __future__ import annotations

import logging
import time
from typing import Any, Set

from comm import sync_publisher
from comm.nodelife import registering
from comm.rpc import master_api
from coordinator.runstream import CHANNELS, Sink
from modules.discovery import node_alive

__all__ = ["RosStreamSink"]

log = logging.getLogger("bmtree.coordinator")


class RosStreamSink(Sink):
    """Publishes run-stream records, one topic per channel. ``tree`` and ``end`` (once per run)
    are latched, so a viewer that connects late still gets the tree and the result, and written
    at once; the frequent channels are queued, so a slow viewer never slows the tick, and
    drained (bounded) at the end of the run."""

    _ONCE = ("tree", "end")

    def __init__(self, namespace: str, string_cls: Any):
        import rospy

        self._String = string_cls
        self._pubs = {}
        with registering():
            for c in CHANNELS:
                topic = "%s/%s" % (namespace.rstrip("/"), c)
                self._pubs[c] = (sync_publisher(topic, string_cls, latch=True) if c in self._ONCE else
                                 rospy.Publisher(topic, string_cls, queue_size=1000))

    def write(self, channel: str, text: str) -> None:
        self._pubs[channel].publish(self._String(text))

    def close(self, timeout: float = 1.0) -> None:
        end = time.monotonic() + timeout
        for c, pub in self._pubs.items():
            if c in self._ONCE:
                continue
            for conn in list(getattr(pub.impl, "connections", [])):
                while getattr(conn, "_queue", None) and time.monotonic() < end:
                    time.sleep(0.005)

    def settle(self, timeout: float = 3.0) -> bool:
        """Wait (bounded) until every viewer already subscribed is connected, so that it misses
        nothing of the run; True if all are.

        A subscriber whose node does not answer its XML-RPC (``getPid``) is left out: a viewer or
        run killed outright stays registered with the master for ever, and would otherwise cost
        every later run the whole wait for a connection that never comes."""
        master = master_api("/bmtree_stream")
        end = time.monotonic() + timeout
        dead: Set[str] = set()
        alive: Set[str] = set()
        while True:
            try:
                subs = {t: list(n) for t, n in master.getSystemState()[1]}
            except Exception:
                return False
            missing = {n for p in self._pubs.values() for n in subs.get(p.resolved_name, ())
                       if not p.impl.has_connection(n)} - dead
            for node in sorted(missing - alive):  # each asked once
                try:
                    answers = node_alive(master.lookupNode(node), 0.5)
                except Exception:  # no longer registered
                    answers = False
                (alive if answers else dead).add(node)
                if not answers:
                    log.debug("run stream: subscriber %s is registered but does not answer: not waited for", node)
            if not missing - dead:
                return True
            if time.monotonic() >= end:
                return False
            time.sleep(0.02)
