"""Liveness: a module (or the Blackboard) that dies mid-call is noticed within half a second.

ROS 1 tells a subscriber nothing when a publisher's process dies, so a call to a killed
module would wait out its whole timeout. The watchdog asks the node of every module that
has calls in flight (and the Blackboard while requests are open) for its pid over the
node's own XML-RPC API, and keeps that connection open: a process that dies closes it, and
the watchdog, waiting on every kept connection at once, asks again at that moment (a node
that does not keep connections open is asked every ``period`` seconds). A node whose port
refuses connections, that is no longer registered, or that answers with another pid than
when the watch on it began (it was restarted and forgot the call) is *lost*: its open calls
are reported at once as :class:`ModuleLost` (requests as :class:`BlackboardLost`). A node
that is merely slow to answer (busy, or stopped with SIGSTOP) is not lost: the call's own
timeout covers it.

Only modules with a call in flight for at least one period are watched: most calls are
answered sooner, and asking every busy node every period (three XML-RPCs each, to the
master and to the node) cost more than the calls themselves when a ``parallel`` kept 50
modules busy. So a death within a call's first period is noticed one to two periods after the
call was sent; a later one at once. A restart within the call's first period, before the watch
on the node began, is left to the call's timeout (as a restart before the first check always was).
"""
from __future__ import annotations

import logging
import socket
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Set, Tuple

from comm.rpc import PidLine, wait_closed

__all__ = ["ModuleLost", "BlackboardLost", "Watchdog", "NodeWatch", "DEFAULT_PERIOD"]

log = logging.getLogger("bmtree.coordinator")

DEFAULT_PERIOD = 0.25
BLACKBOARD = "\0blackboard"  # the watchdog's key for the Blackboard node


@dataclass
class ModuleLost:
    """The node serving ``module`` died or restarted while ``call_ids`` were in flight."""

    module: str
    node: str
    reason: str
    call_ids: List[str] = field(default_factory=list)
    #: seconds its node had not answered, when that (not a process found gone) is why: ``unanswered``
    unanswered: float = 0.0


@dataclass
class BlackboardLost:
    """The Blackboard node died or restarted while ``request_ids`` were open."""

    node: str
    reason: str
    request_ids: List[str] = field(default_factory=list)


class Watchdog:
    """Watches the nodes that owe answers; ``deliver`` gets ModuleLost/BlackboardLost items.

    Args:
        resolve: maps a module name (or :data:`BLACKBOARD`) to its node name, or None.
        lookup: maps a node name to its XML-RPC URI (raises or returns None if unregistered).
        period: seconds between checks (a call is watched once it is a period old).
        line: makes the connection that asks a node (URI, timeout, caller id) for its pid: a
            :class:`~comm.rpc.PidLine`.
        say: log each loss.
        unregistered_lost: a node the master does not know is lost (False: only a process seen gone is;
            a restarted master knows no node until each registers again).
        restart_grace: seconds a call sent after its node's process was found gone waits for the node
            to be started again (a respawn, a retry sent at once), while ``registered(node)`` says the
            master still has the dead process (killed outright or crashed: it stays registered until its
            successor registers, and the call would be lost on the old one). A node stopped cleanly
            unregistered: a call to it is lost at once.
        unanswered: seconds after which a node that does not answer (its machine cannot be reached, or
            its process is stopped) is lost as well, its calls then delivered with ``unanswered`` set;
            0: never (its calls' own timeouts cover it). Its node is then asked every period, also over a
            kept connection (which a dropped link leaves open for the ~11 s of keepalive probes).

    A module node uses one over the callers of its running calls (keys are then node names):
    a call whose caller's process is gone is cancelled.
    """

    def __init__(self, deliver: Callable[[Any], None], resolve: Callable[[str], Optional[str]],
                 lookup: Callable[[str], Optional[str]], period: float = DEFAULT_PERIOD,
                 ping_timeout: float = 0.5, line: Callable[[str, float, str], Any] = PidLine, say: bool = True,
                 unregistered_lost: bool = True, restart_grace: float = 0.0,
                 registered: Callable[[str], bool] = lambda node: True, unanswered: float = 0.0):
        self.deliver = deliver
        self.say = say  # log each loss (a module node watching its callers says it in its own words)
        self.unregistered_lost = unregistered_lost
        self.resolve = resolve
        self.lookup = lookup
        self.period = period
        self.ping_timeout = ping_timeout
        self._line = line
        self._lines: Dict[str, Any] = {}  # key -> the connection kept to its node (watching thread only)
        self._lock = threading.Lock()
        self._calls: Dict[str, Tuple[str, float]] = {}  # call_id -> (module, when it was sent)
        self._requests: Set[str] = set()
        self._known: Dict[str, Tuple[str, str, int]] = {}  # module -> (node, uri, pid)
        self.restart_grace = restart_grace
        self.registered = registered
        self._gone: Dict[str, Tuple[str, float]] = {}  # key -> (URI of a process found gone, when found)
        self.unanswered = unanswered
        self._heard: Dict[str, float] = {}  # key -> when its node last answered (or was first asked)
        self._stop = threading.Event()
        self._owing = threading.Event()  # set while something is owed (and on stop): an idle watchdog sleeps
        self._thread: Optional[threading.Thread] = None

    def start(self) -> None:
        if self._thread is None and self.period > 0:
            self._thread = threading.Thread(target=self._loop, name="bmtree-liveness", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._owing.set()

    # bookkeeping, from any thread ----------------------------------------------------
    def gone_since(self, key: str) -> Optional[float]:
        """Seconds since the process of ``key``'s node was found gone, while no new one is known; else None."""
        gone = self._gone.get(key)
        return time.monotonic() - gone[1] if gone is not None else None

    def call_sent(self, call_id: str, module: str) -> None:
        with self._lock:
            self._calls[call_id] = (module, time.monotonic())
        if not self._owing.is_set():  # the watching thread sleeps: wake it (once, not per call)
            self._owing.set()

    def owes(self, call_id: str) -> bool:
        """True while the call is in flight (sent, neither answered nor given up as lost)."""
        with self._lock:
            return call_id in self._calls

    def call_done(self, call_id: Optional[str]) -> None:
        if call_id is not None:
            with self._lock:
                self._calls.pop(call_id, None)

    def request_sent(self, request_id: str) -> None:
        with self._lock:
            self._requests.add(request_id)
        self._owing.set()

    def request_done(self, request_id: Optional[str]) -> None:
        if request_id is not None:
            with self._lock:
                self._requests.discard(request_id)

    # the watching thread ------------------------------------------------------------
    def _loop(self) -> None:
        try:
            while not self._stop.is_set():
                self._wait()
                if self._stop.is_set():
                    return
                try:
                    self.check()
                except Exception as exc:  # the master may be away; try again next period
                    log.debug("liveness check failed: %s", exc)
        finally:
            for line in self._lines.values():
                line.close()

    def _wait(self) -> None:
        """Wait a period, or less when a kept connection closes (that line is dropped: its node
        is asked afresh); while nothing is owed, until something is (an idle node costs nothing)."""
        with self._lock:
            idle = not self._calls and not self._requests
            if idle:
                self._owing.clear()
        if idle and not self._lines:
            self._owing.wait()
            return
        kept = {key: line for key, line in self._lines.items() if line.fileno() >= 0}
        if not kept:
            self._stop.wait(self.period)
            return
        for key in wait_closed(kept, self.period)[1]:
            self._lines.pop(key, None)

    def check(self) -> None:
        """One round: every module with calls in flight for a period, and the Blackboard if asked
        (a node whose kept connection is still open lives, and is not asked)."""
        with self._lock:
            due = time.monotonic() - self.period  # calls younger than a period are not watched yet
            owing = {m for m, _ in self._calls.values()}
            busy = sorted({m for m, sent in self._calls.values() if sent <= due})
            if self._requests:
                busy.append(BLACKBOARD)
                owing.add(BLACKBOARD)
        # Forget the process of a node that owes nothing: restarted between two calls (a respawn),
        # it must not be taken for one that forgot a call.
        for key in set(self._known) - owing:
            del self._known[key]
        for key in set(self._heard) - owing:
            del self._heard[key]
        for key in set(self._lines) - set(self._known):
            self._lines.pop(key).close()
        for key in busy:
            lost = self._lost(key)
            silent = 0.0
            if lost is None and self.unanswered > 0:
                lost, silent = self._silent(key)
            if lost is None:
                continue
            node, reason = lost
            self._known.pop(key, None)
            self._heard.pop(key, None)
            with self._lock:
                if key == BLACKBOARD:
                    ids = sorted(self._requests)
                    self._requests.clear()
                else:
                    ids = [c for c, (m, _) in self._calls.items() if m == key]
                    for c in ids:
                        del self._calls[c]
            if not ids:
                continue
            if key == BLACKBOARD:
                log.warning("Blackboard node %s lost: %s", node, reason)
                self.deliver(BlackboardLost(node=node, reason=reason, request_ids=ids))
            else:
                if self.say:
                    log.warning("module %s (node %s) lost: %s", key, node, reason)
                self.deliver(ModuleLost(module=key, node=node, reason=reason, call_ids=ids, unanswered=silent))

    def _ask(self, key: str, uri: str) -> Optional[int]:
        """The pid of the node of ``key`` at ``uri``, over the connection kept to it (made if needed).

        Raises:
            OSError: refused or broken (its process is gone).
        """
        line = self._lines.get(key)
        if line is None:
            line = self._lines[key] = self._line(uri, self.ping_timeout, "/bmtree_liveness")
        now = time.monotonic()
        self._heard.setdefault(key, now)
        try:
            pid = line.ask()
        except OSError:
            self._lines.pop(key).close()
            raise
        if pid is not None:
            self._heard[key] = now
        return pid

    def _silent(self, key: str) -> Tuple[Optional[Tuple[str, str]], float]:
        """((its node, why), for how long) when the node of ``key``, alive as far as is known, has not
        answered for :attr:`unanswered` seconds; (None, 0) otherwise."""
        since = self._heard.get(key)  # set once its node was asked
        if since is None or time.monotonic() - since < self.unanswered:
            return None, 0.0
        known = self._known.get(key)
        node = known[0] if known is not None else self.resolve(key)
        if node is None:
            return None, 0.0
        silent = time.monotonic() - since
        return (node, "node %s has not answered for %.0fs (its machine cannot be reached, or its process is "
                "stopped)" % (node, silent)), silent

    def _lost(self, key: str) -> Optional[Tuple[str, str]]:
        """(its node, why) when the node of ``key`` is lost, or None while it lives (or cannot be told)."""
        known = self._known.get(key)
        if known is None:
            node = self.resolve(key)
            if node is None:
                return None  # not found (yet): the call's timeout stays the bound
            try:
                uri = self.lookup(node)
            except OSError:
                return None
            if not uri:  # for a caller: perhaps a restarted master it has not registered with again yet
                return (node, "node %s is not registered with the master" % node) if self.unregistered_lost else None
            gone = self._gone.get(key) if key != BLACKBOARD else None
            if gone is not None and gone[0] == uri and self.registered(node):   # not started again (yet)
                waited = self._oldest_wait(key, gone[1])
                if waited < self.restart_grace:
                    return None
                return node, "node %s stopped (its process is gone) and was not started again within %gs" % (
                    node, self.restart_grace)
            self._gone.pop(key, None)
            try:
                pid = self._ask(key, uri)
            except OSError:
                self._gone[key] = (uri, time.monotonic())
                return node, "node %s stopped (its process is gone)" % node
            if pid is not None:
                self._known[key] = (node, uri, pid)
            return None
        node, uri, pid = known
        line = self._lines.get(key)
        if line is not None and line.kept and not self.unanswered:
            return None  # its connection stays open: its process lives
        try:
            now = self._ask(key, uri)
        except OSError:
            now = -1
        if now is None or now == pid:
            return None
        try:
            new_uri = self.lookup(node)
        except OSError:
            new_uri = None
        if now == -1 and new_uri and new_uri != uri:
            return node, "node %s was restarted (it cannot know the calls sent to its previous process)" % node
        if now == -1:
            if new_uri == uri:
                self._gone[key] = (uri, time.monotonic())
            return node, "node %s stopped (its process is gone)" % node
        return node, "node %s was restarted (pid %d, was %d)" % (node, now, pid)

    def _oldest_wait(self, key: str, found: float) -> float:
        """How long the oldest call owed by ``key`` has waited since its process was found gone (0: none)."""
        with self._lock:
            sent = [when for m, when in self._calls.values() if m == key]
        return time.monotonic() - max(min(sent), found) if sent else 0.0


class NodeWatch:
    """Watches one node's process, found by ``resolve``, as the :class:`Watchdog` does (its
    ``getPid`` over one kept connection, waited on, never polled while it stays open).

    ``on_gone(node, reason)`` once when its process is gone (the port refuses, the connection
    breaks, or it answers with another pid: restarted; ``reason`` says which, without the node's
    name); then, while it is gone, ``resolve`` and
    ``lookup`` are asked every ``period`` seconds, and ``on_back(node)`` is called once a node
    (the same name restarted, or another) answers again. A node that is merely slow to answer
    (busy, stopped with SIGSTOP), or a master that does not answer, is not taken for gone.
    A node not found at the start is waited for silently (``on_back`` only follows ``on_gone``);
    one found registered but dead is gone at once with ``dead_is_gone``, else waited for too.

    Args:
        resolve: the node's name now, or None (may raise OSError while the master is away).
        lookup: a node's XML-RPC URI, or None when it is not registered (may raise OSError).
        recheck: seconds after which a quiet kept connection is asked again anyway.
    """

    def __init__(self, resolve: Callable[[], Optional[str]], lookup: Callable[[str], Optional[str]],
                 on_gone: Callable[[str, str], None], on_back: Optional[Callable[[str], None]] = None,
                 period: float = 0.5, ping_timeout: float = 0.5, recheck: float = 60.0,
                 line: Callable[[str, float, str], Any] = PidLine, caller: str = "/bmtree_liveness",
                 dead_is_gone: bool = False):
        self.resolve = resolve
        self.dead_is_gone = dead_is_gone
        self.lookup = lookup
        self.on_gone = on_gone
        self.on_back = on_back
        self.period = period
        self.ping_timeout = ping_timeout
        self.recheck = recheck
        self.caller = caller
        self._line_of = line
        self.node: Optional[str] = None
        self.gone = False
        self._uri = ""
        self._pid: Optional[int] = None
        self._line: Any = None
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._thread: Optional[threading.Thread] = None

    def start(self) -> NodeWatch:
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="bmtree-nodewatch", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        try:
            self._wake_w.send(b"x")
        except OSError:  # stopped twice
            pass

    def _loop(self) -> None:
        try:
            while not self._stop.is_set():
                try:
                    self.check()
                except Exception as exc:  # the master may be away: try again later
                    log.debug("watching node %s: %s", self.node, exc)
                line = self._line
                if line is not None and line.fileno() >= 0:
                    woke, closed = wait_closed({"node": line}, self.recheck, self._wake_r)
                    if woke:
                        return
                elif self._stop.wait(self.period):
                    return
        finally:
            if self._line is not None:
                self._line.close()
            self._wake_r.close()
            self._wake_w.close()

    def _drop(self) -> None:
        if self._line is not None:
            self._line.close()
        self._line, self._pid, self._uri = None, None, ""

    def check(self) -> None:
        """One look (the watching thread's; callable directly in tests)."""
        if self._pid is not None:  # watching a live process
            try:
                pid = self._line.ask()
            except OSError:
                pid = -1
            if pid is None or pid == self._pid:
                return
            node = self.node or "?"
            reason = "its process ended" if pid == -1 else "it was restarted: pid %d, was %d" % (pid, self._pid)
            self._drop()
            self.gone = True
            self.on_gone(node, reason)
            if pid == -1:
                return
        node = self.resolve()
        if node is None:
            return
        uri = self.lookup(node)
        if not uri:
            return
        line = self._line_of(uri, self.ping_timeout, self.caller)
        try:
            pid = line.ask()
        except OSError:  # a dead node still registered (killed outright): gone, or still gone
            line.close()
            if self.dead_is_gone and not self.gone:
                self.node, self.gone = node, True
                self.on_gone(node, "its process ended")
            return
        if pid is None:
            line.close()
            return
        self.node, self._uri, self._pid, self._line = node, uri, pid, line
        if self.gone:
            self.gone = False
            if self.on_back is not None:
                self.on_back(node)
