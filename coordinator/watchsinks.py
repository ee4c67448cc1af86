"""Where a run's own records go to be seen: its terminal view's state (:class:`StateSink`), and the
``snapshot`` records that catch a watcher up mid-run (:class:`SnapshotSink`)."""
from __future__ import annotations

import threading
import time
from typing import Any, Callable, Dict, Optional

from coordinator.runstream import Sink, to_json
from coordinator.watchstate import WatchState

__all__ = ["StateSink", "SnapshotSink"]


class StateSink(Sink):
    """Feeds the run's own records to a :class:`WatchState` (the run's terminal view)."""

    def __init__(self, state: WatchState):
        self.state = state

    def write(self, channel: str, text: str) -> None:
        self.state.apply_text(text)


class SnapshotSink(StateSink):
    """Keeps the run's state and publishes it as a ``snapshot`` record through ``publish``
    (a latched topic) at the end of a tick, at most every ``interval`` seconds, and at the end.

    A tick that comes too soon after the last snapshot is published ``interval`` later by a
    timer: the engine is event-driven, so while a long call runs there may be no next tick, and
    the latched snapshot must not stay behind the run (a watcher attaching then would load it).

    A snapshot is stamped with the run's time when it is taken (``clock`` is the run's clock:
    its ``tree`` record, on the ``tree`` channel, is the run's time 0), not with its last record's:
    a watcher attaching 3 s into a 5 s wait sees the state of that moment."""

    def __init__(self, publish: Callable[[str], None], interval: float = 0.5,
                 clock: Callable[[], float] = time.monotonic):
        super().__init__(WatchState(recent=0))  # the run's own records, in order: no snapshot comes
        self.publish = publish
        self.interval = interval
        self.clock = clock
        self._zero: Optional[float] = None  # clock() at the run's tree record (its t 0)
        self._last = 0.0
        self._lock = threading.Lock()
        self._timer: Optional[threading.Timer] = None
        self._closed = False

    def snapshot(self) -> Dict[str, Any]:
        """The run's state now, as a ``snapshot`` record whose ``t`` is the run's time now
        (the time of the end for an ended run)."""
        with self.state.lock:
            snap = self.state.snapshot()
            if self._zero is not None and self.state.end is None:
                snap["t"] = max(float(snap["t"]), round(self.clock() - self._zero, 6))
            return snap

    def write(self, channel: str, text: str) -> None:
        if channel == "tree":
            self._zero = self.clock()
        super().write(channel, text)
        if channel == "control":  # while paused there are no ticks: publish now
            with self._lock:
                self._last = 0.0
            self.flush()

    def _publish_now(self) -> None:  # with self._lock held
        self._last = time.monotonic()
        self.publish(to_json(self.snapshot()))

    def flush(self) -> None:
        with self._lock:
            if self._closed:
                return
            wait = self._last + self.interval - time.monotonic()
            if wait <= 0:
                self._publish_now()
            elif self._timer is None:
                self._timer = threading.Timer(wait, self._trailing)
                self._timer.daemon = True
                self._timer.start()

    def _trailing(self) -> None:
        with self._lock:
            self._timer = None
            if not self._closed:
                self._publish_now()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            self._publish_now()
