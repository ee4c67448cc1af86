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
import logging
import os
import select
import signal
import sys
import threading
import time
from typing import Any, Callable, Dict, Iterator, List, Optional

__all__ = ["Interrupts", "StopSignals", "registering", "stop_requested", "leave_graph", "bound_master_questions",
           "shut_rospy_down", "before_topics_close", "LEAVE_BOUND"]

log = logging.getLogger("bmtree.nodelife")

#: seconds a signal re-sent after another still counts as the same stop (a parent killed with
#: threads re-sends ``PR_SET_PDEATHSIG`` as each of its threads ends; a person's second Ctrl-C
#: comes later)
BURST = 0.25

_installed: Optional[StopSignals] = None


class StopSignals:
    """Remembers a SIGINT/SIGTERM (or SIGHUP, unless ignored as under nohup); install it before
    ``rospy.init_node`` (main thread only)."""

    def __init__(self) -> None:
        global _installed
        _installed = self
        self._stopped = False
        self.signalled_at: Optional[float] = None  # monotonic time of the (first) stop signal
        self._read_fd, self._write_fd = os.pipe()
        os.set_blocking(self._write_fd, False)
        self.signal: Optional[int] = None
        self._started = threading.Event()  # start-up is over (see init_node)
        self._watch: Any = None  # the start-up's comm.startup.StartupWatch
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
        if self.signalled_at is None:
            self.signalled_at = time.monotonic()
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
        """``rospy.init_node`` without rospy's signal handlers; False when a stop signal came first.

        Start-up lasts until :meth:`started` (or :meth:`spin`): meanwhile a master that does not
        answer is said on stderr every few seconds (:class:`comm.startup.StartupWatch`), and a
        stop signal that a master holds in a registration ends the process (``_stop_start_up``).
        rospy's questions to the master are bounded from here on (a registration is retried, by
        rospy; :func:`comm.startup.patiently` retries the node's own)."""
        import rospy

        from comm.rpc import MASTER_TIMEOUT
        from comm.startup import StartupWatch

        if self.requested or not self._master_for_private_params():
            return False
        bound_master_questions(MASTER_TIMEOUT)
        self._watch = StartupWatch(_node_master(), "node %s" % name).start()
        # without a master, init_node retries its registrations for ever, holding rospy's topic
        # lock, which rospy's own shutdown needs too: a stop then ends the process (below)
        threading.Thread(target=self._stop_start_up, name="bmtree-start-stop", daemon=True).start()
        rospy.init_node(name, disable_signals=True, **kwargs)
        rospy.on_shutdown(self._wake)
        rospy.core.add_shutdown_hook(_wake_registration_thread())  # hooks that run once is_shutdown()
        return not self.requested

    def started(self) -> None:
        """Start-up is over: the node serves (its master watch says from now on when the master is away)."""
        self._started.set()
        if self._watch is not None:
            self._watch.stop()

    def _master_for_private_params(self) -> bool:
        """Wait for the master when the command line has ``_name:=value`` parameters: ``init_node``
        sets them on the master at once and raises if it is not there yet, where a node without
        them waits for it. False if a stop signal came first."""
        import rosgraph

        from comm.nodeopts import node_params
        from comm.rpc import master_answers

        if not node_params(sys.argv[1:], None):  # None: the arguments only, the master is not asked
            return True
        said = False
        while not self._stopped:
            if master_answers(1.0):  # bounded: a master stopped or unreachable must not hold a stop
                return True
            if not said:
                sys.stderr.write("waiting for the ROS master at %s (this node's _name:=value parameters go "
                                 "there) ...\n" % rosgraph.get_master_uri())
                sys.stderr.flush()
                said = True
            select.select([self._read_fd], [], [], 0.5)
        return False

    def _stop_start_up(self, grace: float = 1.0) -> None:
        """While the node starts: after a stop signal start-up has ``grace`` seconds to end (it
        notices the stop, or ends, whenever the master answers, and the node then stops as usual);
        still held after that by a master that does not answer (a registration rospy retries, a
        question asked again), the process exits with 0 (the pipe is watched, never read): what it
        registered stays with that master."""
        while not self._started.is_set() and not self._stopped:
            select.select([self._read_fd], [], [], 0.05)
        if self._started.wait(grace):
            return
        from comm.rpc import master_answers

        while not self._started.wait(0.5):
            if not master_answers(1.0, _node_master()):
                sys.stderr.write("stopped during start-up: no ROS master answered at %s; leaving without "
                                 "unregistering (%s)\n" % (_node_master(), LEFT_BEHIND))
                sys.stderr.flush()
                os._exit(0)

    def wait(self) -> None:
        """Block until a stop signal or :meth:`_wake` (rospy's shutdown)."""
        while not self._stopped:
            os.read(self._read_fd, 64)

    def spin(self) -> None:
        """Block until a stop signal or rospy's shutdown (master kicked us out), then :meth:`leave`."""
        self.started()
        self.wait()
        self.leave()

    def leave(self, cleanup: Optional[Callable[[], None]] = None) -> None:
        """Leave the ROS graph: rospy shut down, then ``cleanup`` (the node's own unregistering),
        bounded by :func:`leave_graph`: a master that does not answer is left without unregistering,
        said on stderr, and a second stop signal leaves at once."""
        import rospy

        self.started()
        if not rospy.core.is_initialized():
            if cleanup is not None:
                cleanup()
            return

        def steps() -> None:
            # a shutdown another thread began (the master kicked this node out) woke us with rospy's
            # first hooks and runs the others still (the node notes why there): shut_rospy_down waits
            shut_rospy_down("signal-%d" % self.signal if self.signal else "stopped")
            if cleanup is not None:
                cleanup()

        def say(text: str) -> None:
            sys.stderr.write(text + "\n")
            sys.stderr.flush()

        leave_graph(steps, say, stopped_at=self.signalled_at)


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


def shut_rospy_down(reason: str, wait: float = 2.0) -> None:
    """``rospy.signal_shutdown(reason)``, then wait (at most ``wait`` s) for ``rospy.is_shutdown()``.

    A shutdown another thread began (a shutdown request of the node, run in rospy's XML-RPC thread)
    makes ``signal_shutdown`` return at once, that thread still unregistering the node's topics:
    a process that left then would leave its registrations with the master."""
    import rospy

    if rospy.is_shutdown():
        return
    rospy.signal_shutdown(reason)
    deadline = time.monotonic() + wait
    while not rospy.is_shutdown() and time.monotonic() < deadline:
        time.sleep(0.01)


def _first_preshutdown_hook(hook: Callable[[str], None]) -> None:
    """``hook`` among rospy's pre-shutdown hooks, before the others: the first of those (its
    RegManager's, added by ``init_node``) unregisters and closes every topic of the node."""
    import rospy.core

    rospy.core.add_preshutdown_hook(hook)
    hooks = getattr(rospy.core, "_preshutdown_hooks", None)
    lock = getattr(rospy.core, "_shutdown_lock", None)
    if not isinstance(hooks, list) or lock is None:  # another rospy: where add_preshutdown_hook put it
        return
    with lock:
        if hook in hooks:
            hooks.remove(hook)
            hooks.insert(0, hook)


#: ``before_topics_close(hook)``: ``hook(reason)`` runs when rospy shuts down, after its ``on_shutdown`` hooks and
#: before it closes the node's topics (what it publishes still goes out); in the thread that shuts rospy down
before_topics_close = _first_preshutdown_hook


def stop_requested() -> bool:
    """True once the process's :class:`StopSignals` saw a stop: long start-up waits end early."""
    return _installed is not None and _installed.requested


class Interrupts:
    """SIGINT and SIGTERM raise KeyboardInterrupt in the main thread, which is how ``bmtree run``
    stops a tree (its running calls are cancelled), except inside :func:`registering`.

    rospy registering a topic with the master must not be cut short half-way: the master would
    keep a registration that the process never unregisters (every later run and watch then
    waits for a node that is gone). Inside ``registering()`` the signal is noted and raised
    when the block ends. A registration waits for a master that does not answer (stopped, or its
    machine unreachable) for as long as it does not: a second signal there (not one re-sent in
    the same burst) ends the process at once with ``exit_code``. :meth:`restore` puts the previous
    handlers back.

    With :meth:`stop_on_shutdown_request`, a shutdown of rospy begun outside the main thread
    (``rosnode kill``, a node of the same name) stops the main thread as SIGINT does.
    """

    def __init__(self, exit_code: int = 3) -> None:
        global _interrupts
        self.exit_code = exit_code
        self.last_signal: Optional[float] = None  # monotonic time of the last stop signal
        self._depth = 0
        self._patient = 0  # depth of held(again_exits=False)
        self._pending = False
        self._previous: Dict[int, Any] = {}
        #: called (in the signal handler: take no lock) when a signal is held inside ``registering()``
        self.on_held: List[Callable[[], None]] = []
        #: rospy's reason, once a shutdown of rospy begun in another thread stopped the process
        self.shutdown_request = ""
        self._bound: Callable[[], float] = lambda: 0.0
        self._told: Optional[Callable[[str], None]] = None
        self._done = False  # the work is over: a shutdown request no longer stops it
        self._leaving = threading.Event()  # the process leaves the graph: a held shutdown goes on
        self._request_thread: Optional[threading.Thread] = None  # rospy's thread that runs the request
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.getsignal(sig)
            signal.signal(sig, self._on_signal)
        _interrupts = self

    def _on_signal(self, signum: int, frame: Any) -> None:
        now = time.monotonic()
        again = self.last_signal is not None and now - self.last_signal >= BURST
        if self.last_signal is None or again:
            self.last_signal = now
        if self._depth:
            if self._pending and again and not self._patient:
                _exit_now("interrupted again while registering with the ROS master at %s: exiting at once "
                          "(what this process registered stays there)" % _master_uri(), self.exit_code)
            self._pending = True
            for hook in list(self.on_held):
                hook()
            return
        raise KeyboardInterrupt

    @contextlib.contextmanager
    def held(self, again_exits: bool = True) -> Iterator[None]:
        """A block that a stop signal does not cut short (raised when it ends); with
        ``again_exits``, a second one ends the process at once (a registration that waits for a
        master that does not answer); without, it is held too (a block that cannot hang)."""
        if threading.current_thread() is not threading.main_thread():  # signals reach the main thread only
            yield
            return
        self._depth += 1
        self._patient += 0 if again_exits else 1
        try:
            yield
        finally:
            self._depth -= 1
            self._patient -= 0 if again_exits else 1
            if not self._depth and self._pending:
                self._pending = False
                raise KeyboardInterrupt

    def stop_on_shutdown_request(self, bound: Callable[[], float],
                                 told: Optional[Callable[[str], None]] = None) -> None:
        """Stop the main thread as SIGINT does when rospy's shutdown begins in another thread.

        ``rosnode kill`` (the node's XML-RPC ``shutdown``), or the master when a node of the same
        name registers, makes rospy's XML-RPC thread shut rospy down: its first pre-shutdown hook
        unregisters and closes every topic, and the main thread went on with nothing to send its
        cancels and cleanup on. Here a hook that goes before it tells ``told(reason)`` (in that
        thread; not for a process already stopping), raises KeyboardInterrupt in the main thread
        (held inside :func:`registering` as a signal is), and holds rospy's shutdown, topics open,
        until :meth:`leaving` or for ``bound()`` seconds (asked then: the cleanup's limit, and a
        margin). Call once rospy is initialized. A shutdown this process begins itself (its
        leave, from any thread, after :meth:`leaving`; or in the main thread) is not held."""
        self._bound, self._told = bound, told
        _first_preshutdown_hook(self._on_shutdown_request)

    def _on_shutdown_request(self, reason: str) -> None:
        if self._leaving.is_set() or threading.current_thread() is threading.main_thread():
            return  # this process's own leave: nothing to hold (the main thread would wait for itself)
        self.shutdown_request = reason or "no reason given"
        self._request_thread = threading.current_thread()
        if not self._done and self.last_signal is None:  # not stopping already (Ctrl-C, the run's end)
            if self._told is not None:
                try:
                    self._told(self.shutdown_request)
                except Exception:  # saying so must not keep the stop from happening
                    log.exception("telling of the shutdown request")
            main = threading.main_thread().ident
            if main is not None:
                signal.pthread_kill(main, signal.SIGINT)  # also wakes it from a blocking wait
        try:
            bound = max(0.0, float(self._bound()))
        except Exception:
            log.exception("the bound of a shutdown request")
            bound = 0.0
        if not self._leaving.wait(bound):
            sys.stderr.write("the process did not leave within %g s of the shutdown request (%s): rospy shuts "
                             "down now, its topics closed\n" % (bound, self.shutdown_request))
            sys.stderr.flush()

    def done(self) -> None:
        """The work a shutdown request stops is over: a later one only waits for :meth:`leaving`."""
        self._done = True

    def leaving(self) -> None:
        """The process leaves the ROS graph: a shutdown request held since goes on (rospy shuts
        down), and one that comes later is this process's own."""
        self._done = True
        self._leaving.set()

    def request_answered(self, timeout: float) -> bool:
        """Wait (at most ``timeout`` s) for the thread of a held shutdown request to end: rospy's
        shutdown goes on there after :meth:`leaving`, and only then answers the request (a process
        that exits first drops the answer: ``rosnode kill`` says it failed). True unless it still runs."""
        thread = self._request_thread
        if thread is None or thread is threading.current_thread():
            return True
        thread.join(timeout)
        return not thread.is_alive()

    def restore(self) -> None:
        global _interrupts
        self.leaving()
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        if _interrupts is self:
            _interrupts = None


_interrupts: Optional[Interrupts] = None


def registering() -> Any:
    """A block in which a process's :class:`Interrupts` hold a stop signal until the block ends
    (wrap rospy's ``init_node``, ``Publisher`` and ``Subscriber`` in it); a plain block otherwise."""
    return _interrupts.held() if _interrupts is not None else contextlib.nullcontext()


def _node_master() -> str:
    """This node's master (``__master:=`` first, as rospy)."""
    import rosgraph

    return str(rosgraph.get_master_uri())


def _master_uri() -> str:
    return os.environ.get("ROS_MASTER_URI", "http://localhost:11311/")


def _exit_now(text: str, code: int) -> None:
    """End the process from a signal handler: one line to stderr's descriptor (the main thread may
    be inside a write to ``sys.stderr``), no clean-up (it could wait for the master again)."""
    try:
        sys.stdout.flush()
    except Exception:  # interrupted inside a write of its own
        pass
    try:
        os.write(2, (text + "\n").encode("utf-8", "replace"))
    except OSError:
        pass
    os._exit(code)


#: seconds the master has to answer each question of a process that leaves the graph
LEAVE_BOUND = 2.0
#: seconds after which leaving is given up whatever it waits for (a lock that a thread stuck
#: in a master question holds)
LEAVE_LIMIT = 10.0
#: what a master that does not answer keeps of a process that left without unregistering
LEFT_BEHIND = ("should it answer again, it keeps this node's registrations until `rosnode cleanup`, a restarted "
               "master has none; bmtree passes over nodes that do not answer")


def leave_graph(steps: Callable[[], None], say: Callable[[str], None], master_down: bool = False,
                stopped_at: Optional[float] = None, bound: float = LEAVE_BOUND) -> bool:
    """Leave the ROS graph: ``steps`` (unregister this process's topics, shut rospy down), bounded.

    rospy asks the master with no timeout, and a master that does not answer (its machine off
    the network, its process stopped) held a leaving process for minutes, Ctrl-C and SIGTERM
    included. Here rospy's questions to the master give up after ``bound`` seconds, and once one
    went unanswered (or at once with ``master_down``, when it is known not to answer) the others
    fail at once: the process says so in one line and leaves without unregistering. The process's
    :class:`~comm.masterwatch.MasterWatch` is stopped first (it would register again what is
    being unregistered).

    ``steps`` run in a thread of their own; the main thread waits for them and notes SIGINT and
    SIGTERM meanwhile: a second stop (one after ``stopped_at``, the monotonic time of the signal
    that stopped the process, if one did) ends the wait at once. Signals re-sent within
    :data:`BURST` seconds count once. True when every question was answered.
    """
    from comm.masterwatch import current_watch

    watch = current_watch()
    if watch is not None:
        master_down = master_down or watch.down
        watch.stop()
    proxies = bound_master_questions(bound, sticky=True, dead=master_down)
    done = threading.Event()

    def work() -> None:
        try:
            steps()
        except Exception as exc:  # a master that went away: what is left is the process's end
            log.debug("leaving the ROS graph: %s", exc)
        finally:
            done.set()

    last = [stopped_at]
    count = [0]

    def on_signal(signum: int, frame: Any) -> None:
        now = time.monotonic()
        if last[0] is None or now - last[0] >= BURST:
            last[0] = now
            count[0] += 1

    previous: Dict[int, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, on_signal)
    why = ""
    try:
        threading.Thread(target=work, name="bmtree-leave", daemon=True).start()
        start = time.monotonic()
        failed_at: Optional[float] = None
        told = False
        while not done.wait(0.05):
            now = time.monotonic()
            if count[0] >= (1 if stopped_at is not None else 2):
                why = "stopped"
                break
            if count[0] and not told:
                say("leaving the ROS graph (unregistering from the master); a second Ctrl-C leaves at once ...")
                told = True
            if failed_at is None and any(p.failed for p in proxies):
                failed_at = now
            if (failed_at is not None and now - failed_at > bound) or now - start > LEAVE_LIMIT:
                why = "stuck"
                break
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    unanswered = master_down or any(p.failed for p in proxies)
    if why:
        _abandon()
    if why == "stopped":
        say("stopped again: leaving without unregistering from the ROS master at %s (%s)" % (_master_uri(),
                                                                                           LEFT_BEHIND))
    elif unanswered:
        say("the ROS master at %s does not answer: leaving without unregistering (%s)" % (_master_uri(),
                                                                                        LEFT_BEHIND))
    elif why:
        say("leaving the ROS graph did not end within %g s: leaving as it is" % LEAVE_LIMIT)
    return not why and not unanswered


def bound_master_questions(timeout: float, sticky: bool = False, dead: bool = False) -> List[Any]:
    """Give rospy's questions to the master (registering, unregistering, parameters) a timeout:
    a :class:`comm.rpc.MasterProxy` in place of rospy's proxy of the master, which rospy looks up
    (``rospy.core.xmlrpcapi(master_uri)``) for every question; before ``init_node`` too. The
    proxies put in place; [] without rospy."""
    try:
        import rosgraph
        import rospy.core
        from rospy.impl.registration import RegManager

        cache = rospy.core._xmlrpc_cache
        lock = rospy.core._xmlrpc_lock
    except (ImportError, AttributeError):
        return []
    from comm.rpc import MasterProxy

    managers = [getattr(h, "__self__", None) for h in getattr(rospy.core, "_preshutdown_hooks", [])]
    uris = {rosgraph.get_master_uri()} | {m.master_uri for m in managers if isinstance(m, RegManager) and m.master_uri}
    proxies = []
    with lock:
        for uri in uris:
            cache[uri] = MasterProxy(uri, timeout, sticky, dead)
            proxies.append(cache[uri])
    return proxies


def _abandon() -> None:
    """Leaving was given up: rospy's exit handler must not ask the master again (no timeout)."""
    try:
        import rospy.core

        rospy.core._shutdown_flag = True
    except ImportError:
        pass
