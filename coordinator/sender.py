"""Publishing one topic from its own thread, so that the ticking thread never waits on a socket.

rospy's queued publishers also never block, but each ``publish`` ends with
``time.sleep(0)``, which hands the GIL to another thread: with 100 calls sent in one tick
that alone took half a millisecond per call on the CI machine, and a ``parallel`` of 100
calls went out one after another. A :class:`TopicSender` wraps a synchronous rospy
publisher (one writer per topic; a module's own call topic has one subscriber): ``publish``
appends to a bounded queue and wakes the sender's thread, which writes. A subscriber that
stops reading blocks only its own topic's thread; past ``limit`` waiting messages the oldest
is dropped (and logged once), as rospy's queues do.
"""
from __future__ import annotations

import collections
import logging
import threading
from typing import Any, Deque

from comm import sync_publisher

__all__ = ["TopicSender"]

log = logging.getLogger("bmtree.coordinator")


class TopicSender:
    """A publisher of ``std_msgs/String`` whose ``publish`` never blocks (see the module docstring)."""

    def __init__(self, topic: str, data_class: type, limit: int = 10000):
        self.pub: Any = sync_publisher(topic, data_class, tcp_nodelay=True)
        self.resolved_name: str = self.pub.resolved_name
        self.impl = self.pub.impl  # for has_connection()
        self.limit = limit
        self.dropped = 0
        self._queue: Deque[Any] = collections.deque()
        self._cond = threading.Condition()
        self._closed = False
        self._stopped = False  # closed and given up on flushing: drop the rest silently
        self._thread = threading.Thread(target=self._run, name="send %s" % topic, daemon=True)
        self._thread.start()

    def publish(self, msg: Any) -> None:
        with self._cond:
            if len(self._queue) >= self.limit:
                self._queue.popleft()
                self.dropped += 1
                if self.dropped == 1:
                    log.warning("%s: its subscriber does not read; dropping the oldest waiting messages",
                                self.resolved_name)
            self._queue.append(msg)
            self._cond.notify()

    def get_num_connections(self) -> int:
        return self.pub.get_num_connections()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._closed:
                    self._cond.wait()
                if not self._queue:
                    return  # closed, and everything written
                batch = list(self._queue)
                self._queue.clear()
            for msg in batch:
                if self._stopped:
                    return
                try:
                    self.pub.publish(msg)
                except Exception as exc:  # a closed topic at shutdown, a broken connection
                    log.warning("could not publish on %s: %s", self.resolved_name, exc)

    def unregister(self, flush: float = 1.0) -> None:
        """Write what waits (cancels sent as a run ends), for at most ``flush`` seconds, then stop."""
        with self._cond:
            self._closed = True
            self._cond.notify()
        self._thread.join(flush)
        self._stopped = True
        self.pub.unregister()
