"""Rate-limited saying of a repeated problem, for every node: the first of each kind at once, then at
most one per ``every`` seconds, which says how many of that kind went unsaid meanwhile. A sender that
repeats a bad message at 1 kHz, or a tree that retries a broken function in a tight loop, must not
flood a log, nor a run's notices."""
from __future__ import annotations

import threading
import time
from typing import Callable, Dict, Hashable, List, Optional

__all__ = ["SAY_EVERY", "SayLimit"]

#: seconds: a repeated problem of one kind is said at most this often, the first at once
SAY_EVERY = 10.0


class SayLimit:
    """:meth:`due` tells whether a line of a kind is to be said now, and what to add to it."""

    def __init__(self, every: float = SAY_EVERY, clock: Optional[Callable[[], float]] = None, kinds: int = 1000):
        self.every = every
        self.clock = clock
        self.kinds = kinds
        self._lock = threading.Lock()
        self._said: Dict[Hashable, List[float]] = {}  # kind -> [when last said, how many unsaid since]

    def due(self, kind: Hashable) -> Optional[str]:
        """None when a line of ``kind`` is not to be said now (it is counted), else the text to add to it:
        ``" (and 3 more like it in the last 10s)"``, or "" when none went unsaid."""
        now = self.clock() if self.clock is not None else time.monotonic()
        with self._lock:
            last = self._said.get(kind)
            if last is not None and now - last[0] < self.every:
                last[1] += 1
                return None
            if len(self._said) >= self.kinds:  # many kinds (random names in bad messages): forget the old ones
                self._said.clear()
            self._said[kind] = [now, 0]
        n = int(last[1]) if last is not None else 0
        return " (and %d more like it in the last %gs)" % (n, self.every) if n else ""
