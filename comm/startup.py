"""A long-lived node's start-up while the ROS master does not answer: said, waited for, retried.

A module node, a bridge or the Blackboard started while its master is stopped, or on a machine
cut off from the master's, used to sit in ``rospy.init_node`` without a word (rospy's master
proxy has no timeout; with no master at all rospy says once that it keeps trying). Such a node
must come up when the master does, so it waits, but says so: :class:`StartupWatch` asks the
master every second while the node starts and prints, on stderr (rosout needs the master), that
the master does not answer and that the node keeps trying, then again every
:data:`SAY_EVERY` seconds, and when it answers again. Its master questions are bounded
(:func:`comm.nodelife.bound_master_questions`, before ``init_node``): rospy retries a
registration then; :func:`patiently` retries the node's own start-up questions (its
parameters, its announcement).
"""
from __future__ import annotations

import sys
import threading
import time
from typing import Callable, Optional, TypeVar

from comm.rpc import PidLine

__all__ = ["StartupWatch", "patiently", "SAY_EVERY"]

#: seconds between two lines saying that the master still does not answer
SAY_EVERY = 10.0

T = TypeVar("T")


def _stderr(text: str) -> None:
    try:
        sys.stderr.write(text + "\n")
        sys.stderr.flush()
    except (OSError, ValueError):  # no usable stderr
        pass


class StartupWatch:
    """While a node starts (from before ``init_node`` to :meth:`stop`), says that its master does
    not answer, and keeps saying it every ``every`` seconds.

    Args:
        master_uri: the node's master.
        what: the node, for the lines (``node /bm_probe``).
        say: where the lines go (stderr).
        period: seconds between two questions (each bounded by ``timeout``).
    """

    def __init__(self, master_uri: str, what: str, say: Callable[[str], None] = _stderr, every: float = SAY_EVERY,
                 period: float = 1.0, timeout: float = 1.0):
        self.master_uri = master_uri
        self.what = what
        self.say = say
        self.every = every
        self.period = period
        self.timeout = timeout
        self.down = False  # the master did not answer the last question
        self._done = threading.Event()
        self._thread: Optional[threading.Thread] = None

    def start(self) -> StartupWatch:
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="bmtree-startup-watch", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Start-up is over (the node's :class:`comm.masterwatch.MasterWatch` takes over)."""
        self._done.set()
        if self.down:  # it answered, since start-up is over: said before the watch asked again
            self.down = False
            self.say("the ROS master at %s answers again; %s starts" % (self.master_uri, self.what))

    def why_not(self) -> str:
        """Why the master does not answer now ("" when it does)."""
        line = PidLine(self.master_uri, self.timeout, "/bmtree_startup")
        try:
            if line.ask() is not None:
                return ""
            return "does not answer (its process stopped, or its machine cut off from this one?)"
        except ConnectionRefusedError:
            return "cannot be reached (connection refused: is it running?)"
        except OSError as exc:
            return "cannot be reached (%s)" % (getattr(exc, "strerror", None) or exc)
        finally:
            line.close()

    def _loop(self) -> None:
        since: Optional[float] = None  # when the master stopped answering
        said = 0.0
        while not self._done.is_set():
            why = self.why_not()
            if self._done.is_set():
                return
            now = time.monotonic()
            if why and since is None:
                since, said = now, now
                self.down = True
                self.say("the ROS master at %s %s: %s waits for it and keeps trying (Ctrl-C stops it) ..."
                         % (self.master_uri, why, self.what))
            elif why and now - said >= self.every:
                said = now
                self.say("the ROS master at %s still %s, for %.0f s now: %s keeps trying ..."
                         % (self.master_uri, why, now - since if since is not None else 0.0, self.what))
            elif not why and since is not None:
                since = None
                self.down = False
                self.say("the ROS master at %s answers again; %s starts" % (self.master_uri, self.what))
            self._done.wait(self.period)


def patiently(ask: Callable[[], T], retry: float = 0.5) -> T:
    """A start-up question to the master (a parameter, the announcement), asked again while the
    master does not answer it (OSError: each try is bounded, see the module's docstring); the
    process's :class:`StartupWatch` says so meanwhile. A stop signal ends the wait: the process's
    :class:`comm.nodelife.StopSignals` ends a start-up that a master holds."""
    while True:
        try:
            return ask()
        except OSError:
            time.sleep(retry)
