"""The module events a run received, numbered from the run's start, of which only the recent ones are kept.

A robot's modules send events all the time (a battery level every second, a person detector at 30 Hz),
whether or not a ``wait_event`` waits for them: a run kept every one, about 700 bytes each, so a day's
patrol held hundreds of megabytes it would never read again. A ``wait_event`` reads the events that came
after it started, and, restarted by a loop after taking one, the others that came with it (one moment for
the tree): the events a waiting ``wait_event`` has not read are always kept, and of the others the last
:data:`KEEP`.
"""
from __future__ import annotations

from typing import Any, Dict, List

__all__ = ["KEEP", "Received"]

KEEP = 1000
"""Events kept beyond those a waiting ``wait_event`` has not read yet."""


class Received:
    """Events by their number since the run began (``events[i]``, ``len(events)``), with the tick count when
    each arrived (events of one count came together, between two ticks); the readers (waiting
    ``wait_event`` leaves, by :meth:`read_from`) say from which number they still need them."""

    def __init__(self, keep: int = KEEP):
        self.keep = keep
        self.base = 0            # the number of the first event kept
        self._events: List[Any] = []
        self._ticks: List[int] = []
        self._readers: Dict[Any, int] = {}   # reader -> the first number it still needs

    def __len__(self) -> int:
        return self.base + len(self._events)

    def __getitem__(self, i: int) -> Any:
        return self._events[self._index(i)]

    def tick_of(self, i: int) -> int:
        """The tick count when event ``i`` arrived."""
        return self._ticks[self._index(i)]

    def kept(self, i: int) -> bool:
        """Whether event ``i`` is still held (a number the run gave out, not dropped as old)."""
        return self.base <= i < len(self)

    def _index(self, i: int) -> int:
        if not self.kept(i):
            raise IndexError("event %d is not kept (events %d to %d are)" % (i, self.base, len(self) - 1))
        return i - self.base

    def append(self, event: Any, tick: int) -> None:
        self._events.append(event)
        self._ticks.append(tick)
        if len(self._events) >= 2 * self.keep:   # dropped in batches: each event is moved about once
            self._drop_old()

    def read_from(self, reader: Any, first: int) -> None:
        """``reader`` still needs the events from number ``first`` on."""
        self._readers[reader] = first

    def done(self, reader: Any) -> None:
        """``reader`` needs no event any more (it ended, or was halted)."""
        self._readers.pop(reader, None)

    def _drop_old(self) -> None:
        floor = min([len(self) - self.keep] + list(self._readers.values()))
        cut = floor - self.base
        if cut > 0:
            del self._events[:cut]
            del self._ticks[:cut]
            self.base = floor
