"""How a module runtime runs work and keeps time, so one runtime serves a robot and a unit test.

On the robot a :class:`ModuleServer` runs the author's code on :class:`WorkerThreads` and
keeps time with a :class:`TimerThread`. In a unit test it runs on the coordinator's
simulated clock: the clock is the scheduler (anything with ``now()`` and
``call_later(delay, fn)``, such as ``coordinator.clock.SimClock``) and
:class:`ClockExecutor` runs work on it cooperatively, as soon as the clock lets it.
"""
from __future__ import annotations

import abc
import heapq
import itertools
import logging
import queue
import threading
import time
from typing import Any, Callable, List, Protocol, Tuple

__all__ = ["Executor", "Scheduler", "WorkerThreads", "ClockExecutor", "TimerThread"]

log = logging.getLogger("bmtree.module")


class Scheduler(Protocol):
    """A clock that runs callbacks later: ``TimerThread`` on the robot, the run's clock in a test."""

    def now(self) -> float:
        """Seconds on this clock."""

    def call_later(self, delay: float, fn: Callable[[], None]) -> None:
        """Run ``fn`` after ``delay`` seconds of this clock."""


class Executor(abc.ABC):
    """Where a call's work (the author's code) runs."""

    @abc.abstractmethod
    def submit(self, fn: Callable[..., None], *args: Any) -> None:
        """Run ``fn(*args)`` soon, never in the caller's stack (a call is answered after it is taken)."""


class WorkerThreads(Executor):
    """Reusable threads: a call never waits for a thread, and no thread is started per call
    while one is idle (a function may block: it owns its thread until it returns)."""

    def __init__(self, name: str, idle_seconds: float = 30.0):
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()  # in C: a far cheaper hand-off than queue.Queue
        self._idle = 0
        self._lock = threading.Lock()
        self._name = name
        self._idle_seconds = idle_seconds

    def submit(self, fn: Callable[..., None], *args: Any) -> None:
        with self._lock:
            start = self._idle == 0
            if not start:
                self._idle -= 1
        self._jobs.put((fn, args))
        if start:
            threading.Thread(target=self._loop, name=self._name, daemon=True).start()

    def _loop(self) -> None:
        while True:
            try:
                fn, args = self._jobs.get(timeout=self._idle_seconds)
            except queue.Empty:
                with self._lock:
                    if self._idle > 0 and self._jobs.empty():
                        self._idle -= 1
                        return
                continue
            try:
                fn(*args)
            except BaseException:  # noqa: B036 - SystemExit from a callback must not end the thread
                log.exception("a call's work raised")
            with self._lock:
                self._idle += 1


class ClockExecutor(Executor):
    """Work runs in the scheduler's own turn, at the current time of its clock.

    With a simulated clock that is the coordinator's waiting thread, after the tick that sent
    the call: calls sent in one tick all reach their modules (and are accepted or refused as
    busy) before any of them runs, as on a robot where a function takes time. Work must not
    block: a function waits by returning an Outcome with a delay.
    """

    def __init__(self, scheduler: Scheduler):
        self._scheduler = scheduler

    def submit(self, fn: Callable[..., None], *args: Any) -> None:
        self._scheduler.call_later(0.0, lambda: fn(*args))


class TimerThread:
    """Wall-clock scheduler: one daemon thread (started on first use) runs callbacks at their time."""

    def __init__(self, name: str = "bmtree-timer"):
        self._timers: List[Tuple[float, int, Callable[[], None]]] = []
        self._seq = itertools.count()
        self._cond = threading.Condition()
        self._thread: Any = None
        self._name = name

    def now(self) -> float:
        return time.monotonic()

    def call_later(self, delay: float, fn: Callable[[], None]) -> None:
        with self._cond:
            heapq.heappush(self._timers, (time.monotonic() + max(0.0, delay), next(self._seq), fn))
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, name=self._name, daemon=True)
                self._thread.start()
            self._cond.notify()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while True:
                    if not self._timers:
                        self._cond.wait()
                        continue
                    left = self._timers[0][0] - time.monotonic()
                    if left <= 0:
                        _, _, fn = heapq.heappop(self._timers)
                        break
                    self._cond.wait(min(left, threading.TIMEOUT_MAX))  # inf or 1e300 s: OverflowError
            try:
                fn()
            except BaseException:  # noqa: B036 - the one timer thread serves every cancel's grace
                log.exception("a timer callback raised")
