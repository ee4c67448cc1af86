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
    def wait(self, inbox: Any, timeout: float) -> Optional[Any]:
        """The next inbox item, or None after ``timeout`` seconds of this clock."""

    @abc.abstractmethod
    def call_later(self, delay: float, fn: Callable[[], None]) -> None:
        """Run ``fn`` after ``delay`` seconds of this clock."""


class _Timers:
    """Deadlines kept in a heap and run by the waiting (ticking) thread: no timer threads."""

    def __init__(self) -> None:
        self._timers: List[Tuple[float, int, Callable[[], None]]] = []
        self._seq = itertools.count()

    def push(self, at: float, fn: Callable[[], None]) -> None:
        heapq.heappush(self._timers, (at, next(self._seq), fn))

    def next_at(self) -> Optional[float]:
        return self._timers[0][0] if self._timers else None

    def run_due(self, now: float) -> int:
        ran = 0
        while self._timers and self._timers[0][0] <= now:
            _, _, fn = heapq.heappop(self._timers)
            fn()
            ran += 1
        return ran


class RealClock(Clock):
    """Wall time (monotonic); ``call_later`` callbacks run inside :meth:`wait`, in the caller's thread."""

    def __init__(self) -> None:
        self._timers = _Timers()

    def now(self) -> float:
        return time.monotonic()

    def call_later(self, delay: float, fn: Callable[[], None]) -> None:
        self._timers.push(time.monotonic() + max(0.0, delay), fn)

    def wait(self, inbox: Any, timeout: float) -> Optional[Any]:
        end = time.monotonic() + max(0.0, timeout)
        while True:
            now = time.monotonic()
            self._timers.run_due(now)
            try:
                return inbox.get_nowait()
            except queue.Empty:
                pass
            if now >= end:
                return None
            nxt = self._timers.next_at()
            limit = end if nxt is None else min(end, nxt)
            try:
                return inbox.get(timeout=max(0.0, limit - now))
            except queue.Empty:
                continue


class SimClock(Clock):
    """Time advances only when the runner waits and nothing is in the inbox."""

    def __init__(self, start: float = 0.0):
        self._now = start
        self._timers = _Timers()

    def now(self) -> float:
        return self._now

    def call_later(self, delay: float, fn: Callable[[], None]) -> None:
        self._timers.push(self._now + max(0.0, delay), fn)

    def wait(self, inbox: Any, timeout: float) -> Optional[Any]:
        """Jump from one due timer to the next until one of them fills the inbox."""
        end = self._now + max(0.0, timeout)
        while True:
            try:
                return inbox.get_nowait()
            except queue.Empty:
                pass
            nxt = self._timers.next_at()
            if nxt is None or nxt > end:
                self._now = end
                return None
            self._now = max(self._now, nxt)
            self._timers.run_due(self._now)
