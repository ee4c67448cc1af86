"""Answers that wait for their asker's subscription.

A node (re)started while a run goes on (a respawned module) gets its first call as soon as it
subscribes to the call topic, often before the caller has connected to the node's result
topic: ROS connects the two directions independently, and a result published in between goes
to nobody, so the call would wait out its whole timeout. :class:`ReplyPublisher` remembers who
sent calls (the ``callerid`` of the connection they came on) and, while one of them is not yet
connected to the answers' topic, holds the answer until it is, for at most ``patience``
seconds. A caller that does not connect in that time (a tool that sends calls and never reads
answers) is not waited for again. Once every caller is connected, publishing costs one set
check more than the plain publisher.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Dict, Optional

__all__ = ["ReplyPublisher", "caller_of"]


def caller_of(msg: Any) -> Optional[str]:
    """The node that published a received rospy message (None when rospy did not say)."""
    header = getattr(msg, "_connection_header", None)
    return header.get("callerid") if isinstance(header, dict) else None


class ReplyPublisher:
    """Wraps a rospy publisher; :meth:`heard` is told of each asker, :meth:`publish` answers."""

    def __init__(self, pub: Any, patience: float = 3.0, poll: float = 0.01):
        self.pub = pub
        self.patience = patience
        self.poll = poll
        self._lock = threading.Lock()
        self._waiting: Dict[str, float] = {}  # caller -> when it was first heard, while not connected
        self._known: Dict[str, bool] = {}  # caller -> connected once (True) or never within patience (False)
        self.held = 0  # answers that waited for their asker (for tests and logs)

    def heard(self, caller: Optional[str]) -> None:
        """A call came from ``caller``: its answers go to it once it is connected."""
        if not caller or caller in self._known:
            return
        with self._lock:
            if caller not in self._known and caller not in self._waiting:
                self._waiting[caller] = time.monotonic()

    def _unconnected(self) -> Dict[str, float]:
        """The callers heard and not connected yet (those now connected, or out of patience, are settled)."""
        with self._lock:
            if not self._waiting:
                return {}
            connected = {c.endpoint_id for c in list(self.pub.impl.connections)}
            now = time.monotonic()
            for caller, since in list(self._waiting.items()):
                if caller in connected:
                    self._known[caller] = True
                elif now - since >= self.patience:
                    self._known[caller] = False
                else:
                    continue
                del self._waiting[caller]
            return dict(self._waiting)

    def publish(self, msg: Any) -> None:
        """Publish once every asker heard is connected (or out of patience)."""
        if self._waiting and self._unconnected():
            self.held += 1
            while self._unconnected():
                time.sleep(self.poll)
        self.pub.publish(msg)

    def unregister(self) -> None:
        self.pub.unregister()
