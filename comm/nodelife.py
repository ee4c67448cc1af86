"""A node that a SIGINT or SIGTERM ends cleanly at any moment of its life, start-up included.

rospy's own handlers are installed part-way through ``rospy.init_node`` (a SIGTERM before kills
the process with status -15, one during it raises ``ROSInitException``), and they shut rospy
down *inside the signal handler*: when the signal lands while the main thread is in a master
call (``get_param``, even ``rospy.loginfo``), the handler's own master calls wait for the lock
that call holds, and the node hangs for ever. Launchers and supervisors stop nodes whenever
they like, so :class:`StopSignals` only notes the signal (from before ``init_node`` on, rospy's
handlers disabled) and :meth:`StopSignals.spin` shuts rospy down from the main thread.

A node that does not stop is diagnosed with ``kill -USR1 PID``: it prints every thread's stack
to its stderr (the node's log under roslaunch) and goes on.

The handler takes no lock (a ``threading.Event`` would): signals can come in bursts (a parent
killed with threads re-sends ``PR_SET_PDEATHSIG`` as each of its threads ends), and a handler
that runs again inside itself while holding a lock waits for itself for ever. It sets a flag
and writes a byte to a pipe that :meth:`StopSignals.wait` reads. The kernel may deliver the
signal to any thread of the node (one that happens to check first), which leaves a main thread
blocked in a system call asleep: the pipe is also Python's ``signal.set_wakeup_fd``.
"""
from __future__ import annotations

import contextlib
import faulthandler
import os
import select
import signal
import sys
import threading
from typing import Any, Callable, Dict, Iterator, List, Optional

__all__ = ["Interrupts", "StopSignals", "registering", "stop_requested"]

_installed: Optional[StopSignals] = None


class StopSignals:
    """Remembers a SIGINT/SIGTERM (or SIGHUP, unless ignored as under nohup); install it before
    ``rospy.init_node`` (main thread only)."""

    def __init__(self) -> None:
        global _installed
        _installed = self
        self._stopped = False
        self._read_fd, self._write_fd = os.pipe()
        os.set_blocking(self._write_fd, False)
        self.signal: Optional[int] = None
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._on_signal)
        if signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:  # a closed terminal; nohup ignores it
            signal.signal(signal.SIGHUP, self._on_signal)
        # the kernel may hand the signal to any thread; Python runs handlers in the main thread
        # only, so the C-level handler also writes to the pipe the main thread waits on
        signal.set_wakeup_fd(self._write_fd)
        try:
            faulthandler.register(signal.SIGUSR1, file=sys.stderr, all_threads=True)
        except (AttributeError, ValueError, OSError):  # no usable stderr (closed, or not a file)
            pass

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.signal = signum
        self._wake()

    def _wake(self) -> None:
        self._stopped = True
        try:
            os.write(self._write_fd, b"x")
        except OSError:  # the pipe is full: a wake-up is already waiting to be read
            pass

    @property
    def requested(self) -> bool:
        """A stop signal came, or rospy shut down."""
        return self._stopped

    def init_node(self, name: str, **kwargs: Any) -> bool:
        """``rospy.init_node`` without rospy's signal handlers; False when a stop signal came first."""
        import rospy

        if self.requested or not self._master_for_private_params():
            return False
        # without a master, init_node retries its registrations for ever, holding rospy's topic
        # lock, which rospy's own shutdown needs too: a stop then ends the process (below)
        started = threading.Event()
        threading.Thread(target=self._stop_start_up, args=(started,), name="bmtree-start-stop",
                         daemon=True).start()
        try:
            rospy.init_node(name, disable_signals=True, **kwargs)
        finally:
            started.set()
        rospy.on_shutdown(self._wake)
        rospy.core.add_shutdown_hook(_wake_registration_thread())  # hooks that run once is_shutdown()
        return not self.requested

    def _master_for_private_params(self) -> bool:
        """Wait for the master when the command line has ``_name:=value`` parameters: ``init_node``
        sets them on the master at once and raises if it is not there yet, where a node without
        them waits for it. False if a stop signal came first."""
        import rosgraph

        from comm.nodeopts import node_params

        if not node_params(sys.argv[1:], None):  # None: the arguments only, the master is not asked
            return True
        said = False
        while not self._stopped:
            if rosgraph.is_master_online():
                return True
            if not said:
                sys.stderr.write("waiting for the ROS master at %s (this node's _name:=value parameters go "
                                 "there) ...\n" % rosgraph.get_master_uri())
                sys.stderr.flush()
                said = True
            select.select([self._read_fd], [], [], 0.5)
        return False

    def _stop_start_up(self, started: threading.Event, grace: float = 1.0) -> None:
        """While ``init_node`` runs: after a stop signal it has ``grace`` seconds to return (it
        does whenever the master answers, and the node then stops as usual); if it is still stuck
        in registrations that no master takes, nothing was registered or announced, and the
        process exits with 0 at once (the pipe is watched, never read)."""
        while not started.is_set() and not self._stopped:
            select.select([self._read_fd], [], [], 0.05)
        if not started.wait(grace):
            sys.stderr.write("stopped during start-up: no ROS master answered at %s\n" % os.environ.get(
                "ROS_MASTER_URI", "http://localhost:11311/"))
            sys.stderr.flush()
            os._exit(0)

    def wait(self) -> None:
        """Block until a stop signal or :meth:`_wake` (rospy's shutdown)."""
        while not self._stopped:
            os.read(self._read_fd, 64)

    def spin(self) -> None:
        """Block until a stop signal or rospy's shutdown (master kicked us out), then shut rospy down."""
        import rospy

        self.wait()
        if not rospy.is_shutdown():
            rospy.signal_shutdown("signal-%d" % self.signal if self.signal else "stopped")


def _wake_registration_thread() -> Callable[[str], None]:
    """A shutdown hook that wakes rospy's registration thread, which ``rospy.signal_shutdown``
    joins: the thread looks for the shutdown every half second, so each node took 0.6 s to stop
    (and ``bmtree run --sim`` stops four). rospy keeps its RegManager only among its pre-shutdown
    hooks; without one (another rospy) this does nothing."""
    import rospy.core
    from rospy.impl.registration import RegManager

    found = [getattr(h, "__self__", None) for h in getattr(rospy.core, "_preshutdown_hooks", [])]
    managers = [m for m in found if isinstance(m, RegManager)]

    def wake(reason: str) -> None:
        for manager in managers:
            cond = getattr(manager, "cond", None)
            if cond is not None:
                with cond:
                    cond.notify_all()
    return wake


def stop_requested() -> bool:
    """True once the process's :class:`StopSignals` saw a stop: long start-up waits end early."""
    return _installed is not None and _installed.requested


class Interrupts:
    """SIGINT and SIGTERM raise KeyboardInterrupt in the main thread, which is how ``bmtree run``
    stops a tree (its running calls are cancelled), except inside :func:`registering`.

    rospy registering a topic with the master must not be cut short half-way: the master would
    keep a registration that the process never unregisters (every later run and watch then
    waits for a node that is gone). Inside ``registering()`` the signal is noted and raised
    when the block ends. :meth:`restore` puts the previous handlers back.
    """

    def __init__(self) -> None:
        global _interrupts
        self._depth = 0
        self._pending = False
        self._previous: Dict[int, Any] = {}
        #: called (in the signal handler: take no lock) when a signal is held inside ``registering()``
        self.on_held: List[Callable[[], None]] = []
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.getsignal(sig)
            signal.signal(sig, self._on_signal)
        _interrupts = self

    def _on_signal(self, signum: int, frame: Any) -> None:
        if self._depth:
            self._pending = True
            for hook in list(self.on_held):
                hook()
            return
        raise KeyboardInterrupt

    @contextlib.contextmanager
    def held(self) -> Iterator[None]:
        if threading.current_thread() is not threading.main_thread():  # signals reach the main thread only
            yield
            return
        self._depth += 1
        try:
            yield
        finally:
            self._depth -= 1
            if not self._depth and self._pending:
                self._pending = False
                raise KeyboardInterrupt

    def restore(self) -> None:
        global _interrupts
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        if _interrupts is self:
            _interrupts = None


_interrupts: Optional[Interrupts] = None


def registering() -> Any:
    """A block in which a process's :class:`Interrupts` hold a stop signal until the block ends
    (wrap rospy's ``init_node``, ``Publisher`` and ``Subscriber`` in it); a plain block otherwise."""
    return _interrupts.held() if _interrupts is not None else contextlib.nullcontext()
