"""The start-up guard of ``bmtree run``: a ROS master that stops answering while the run
starts gets ``--wait`` seconds to come back, then start-up ends with :class:`MasterGone`
(exit 3) instead of hanging in rospy's registration retries.
"""
from __future__ import annotations

import contextlib
import socket
import threading
import time
from typing import Any, Callable, Iterator, Optional

from comm.errors import EnvironmentProblem
from comm.rpc import PidLine, wait_closed

__all__ = ["MasterGone", "StartupGuard"]


class MasterGone(EnvironmentProblem):
    """The ROS master stopped answering while ``bmtree run`` was starting (exit 3)."""


def _end_registration_retries() -> None:
    """End rospy's retries of a registration with a master that does not answer.

    ``rospy.Publisher``, ``rospy.Subscriber`` and ``init_node`` (its ``/rosout``) register with the
    master in a loop that only ``rospy.is_shutdown()`` ends, holding rospy's topic lock. Raising
    the shutdown flag ends it; rospy's shutdown hooks are not run, as their unregistering asks the
    master with no timeout (a master that does not answer would hang the process there), and there
    is nothing to unregister from a master that is gone. rospy's other questions to the master (its
    proxy bounded at start-up: :func:`comm.nodelife.bound_master_questions`) fail at once from now
    on. No lock taken: called from a signal handler too."""
    import rospy.core

    from comm.rpc import MasterProxy

    rospy.core._shutdown_flag = True
    for proxy in list(getattr(rospy.core, "_xmlrpc_cache", {}).values()):
        if isinstance(proxy, MasterProxy):
            proxy.sticky = proxy.failed = True


class StartupGuard:
    """Bounds ``bmtree run``'s start-up when the ROS master stops answering meanwhile.

    A thread asks the master for its pid over one kept connection and waits for it to close
    (as :class:`comm.masterwatch.MasterWatch`, which exists only once the node is up): a master
    that stops answering gets ``limit`` seconds to answer again (rospy keeps retrying its
    registrations meanwhile, and they succeed then). After that rospy's retries are ended, and
    :meth:`check` (and :meth:`watching`) raise :class:`MasterGone`. A stop signal held while a
    registration waits for a master that does not answer ends that wait at once.

    Args:
        limit: seconds a master that stopped answering has to answer again (``--wait``).
        say: where the progress lines go (stderr).
        interrupts: the run's :class:`comm.nodelife.Interrupts`, whose held signals end a wait.
    """

    def __init__(self, limit: float, say: Callable[[str], None], interrupts: Any = None, period: float = 0.25,
                 timeout: float = 1.0, master_uri: str = ""):
        import rosgraph

        self.limit = limit
        self.say = say
        self.period = period
        self.timeout = timeout
        self.recheck = 1.0  # s between questions while the master answers (a start-up is short)
        self.master_uri = master_uri or rosgraph.get_master_uri()
        self.down = False  # the master does not answer now
        self.expired = False  # ... and did not answer again within ``limit``: start-up is over
        self._interrupts = interrupts
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._thread: Optional[threading.Thread] = None

    def start(self) -> StartupGuard:
        if self._thread is None:
            if self._interrupts is not None:
                self._interrupts.on_held.append(self._on_held)
            self._thread = threading.Thread(target=self._loop, name="bmtree-startup-guard", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Start-up is over (the run's own master watch takes over)."""
        if self._interrupts is not None and self._on_held in self._interrupts.on_held:
            self._interrupts.on_held.remove(self._on_held)
        self._stop.set()
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass

    def _on_held(self) -> None:
        """A stop signal came inside a registration (signal handler, main thread: no lock taken)."""
        if self.down:
            _end_registration_retries()

    def _loop(self) -> None:
        line = PidLine(self.master_uri, self.timeout, "/bmtree_startup")
        down_since = None
        try:
            while not self._stop.is_set():
                pid = line.pid()
                if self._stop.is_set():
                    return
                if pid is None:
                    now = time.monotonic()
                    if down_since is None:
                        down_since = now
                        self.down = True
                        self.say("the ROS master at %s stopped answering during start-up; waiting up to %g s "
                                 "(--wait) for it to answer again ..." % (self.master_uri, self.limit))
                    elif now - down_since >= self.limit:
                        self.expired = True
                        _end_registration_retries()
                        return
                elif down_since is not None:
                    down_since = None
                    self.down = False
                    self.say("the ROS master at %s answers again; starting goes on" % self.master_uri)
                if down_since is None and line.fileno() >= 0:
                    # asked again every second anyway: a master that is stopped, or whose machine
                    # dropped off the network, keeps the connection open and answers nothing
                    if wait_closed({"master": line}, self.recheck, self._wake_r)[0]:
                        return
                elif self._stop.wait(self.period):
                    return
        finally:
            line.close()

    def answers(self) -> bool:
        """The master answers now (asked afresh)."""
        return PidLine(self.master_uri, self.timeout, "/bmtree_startup").pid() is not None

    def error(self, cause: Any = None) -> MasterGone:
        if self.expired:
            return MasterGone("the ROS master at %s stopped answering during start-up and did not answer again within "
                              "%g s (--wait): nothing was called (start it again, then the run)"
                              % (self.master_uri, self.limit))
        return MasterGone("the ROS master at %s stopped answering during start-up%s: nothing was called (start it "
                          "again, then the run)" % (self.master_uri, " (%s)" % cause if cause else ""))

    def check(self) -> None:
        """MasterGone once the master did not come back in time."""
        if self.expired:
            raise self.error()

    def wait_back(self) -> None:
        """The end of start-up: while the master does not answer, wait for it (bounded: MasterGone)."""
        while self.down and not self.expired and self._thread is not None and self._thread.is_alive():
            time.sleep(0.05)
        self.check()

    @contextlib.contextmanager
    def watching(self) -> Iterator[None]:
        """Start-up steps: what they raise because the master does not answer becomes MasterGone."""
        import rosgraph
        import rospy

        try:
            yield
        except (MasterGone, KeyboardInterrupt):
            raise
        except Exception as exc:
            if self.expired:
                raise self.error() from None
            if isinstance(exc, (OSError, rosgraph.masterapi.Error, rospy.exceptions.ROSException)) and \
                    not self.answers():
                raise self.error(exc) from None
            raise
        self.check()
