"""Clocks: the real one, and a simulated one that jumps to the next thing to happen.

The runner waits for messages through the clock, so under :class:`SimClock` a tree
with 30 s timeouts and 5 s module delays finishes in milliseconds, deterministically.
"""
from __future__ import annotations

import abc
import heapq
import itertools
import queue
import time
from typing import Any, Callable, List, Optional, Tuple

__all__ = ["Clock", "RealClock", "SimClock"]


class Clock(abc.ABC):
    @abc.abstractmethod
    def now(self) -> float:
        """Seconds on this clock (monotonic)."""

    @abc.abstractmethod
    def wait(self, inbox: queue.Queue, timeout: float) -> Optional[Any]:
        """The next inbox item, or None after ``timeout`` seconds of this clock."""

    @abc.abstractmethod
    def call_later(self, delay: float, fn: Callable[[], None]) -> None:
        """Run ``fn`` after ``delay`` seconds of this clock."""


class RealClock(Clock):
    def now(self) -> float:
        return time.monotonic()

    def wait(self, inbox: queue.Queue, timeout: float) -> Optional[Any]:
        try:
            return inbox.get(timeout=max(0.0, timeout))
        except queue.Empty:
            return None

    def call_later(self, delay: float, fn: Callable[[], None]) -> None:
        import threading

        t = threading.Timer(delay, fn)
        t.daemon = True
        t.start()


class SimClock(Clock):
    """Time advances only when the runner waits and nothing is in the inbox."""

    def __init__(self, start: float = 0.0):
        self._now = start
        self._timers: List[Tuple[float, int, Callable[[], None]]] = []
        self._seq = itertools.count()

    def now(self) -> float:
        return self._now

    def call_later(self, delay: float, fn: Callable[[], None]) -> None:
        heapq.heappush(self._timers, (self._now + max(0.0, delay), next(self._seq), fn))

    def advance(self, seconds: float) -> None:
        """Run every timer due within ``seconds`` and move time forward."""
        end = self._now + seconds
        while self._timers and self._timers[0][0] <= end:
            at, _, fn = heapq.heappop(self._timers)
            self._now = max(self._now, at)
            fn()
        self._now = end

    def wait(self, inbox: queue.Queue, timeout: float) -> Optional[Any]:
        try:
            return inbox.get_nowait()
        except queue.Empty:
            pass
        end = self._now + max(0.0, timeout)
        while self._timers and self._timers[0][0] <= end:
            at, _, fn = heapq.heappop(self._timers)
            self._now = max(self._now, at)
            fn()
            try:
                return inbox.get_nowait()
            except queue.Empty:
                continue
        self._now = end
        return None
