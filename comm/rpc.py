"""XML-RPC to ROS nodes and the master with a timeout: a hung peer must not hang the caller."""
from __future__ import annotations

import errno
import http.client
import selectors
import socket
import threading
import urllib.parse
import xmlrpc.client
from typing import Any, Mapping, Optional, Set, Tuple

__all__ = ["master_absence", "proxy", "node_alive", "PidLine", "wait_closed", "MASTER_TIMEOUT", "master_api", "master_answers",
           "MasterProxy"]

#: seconds a question to the master may take: a master whose machine dropped off the network, or
#: whose process is stopped, answers nothing, and rosgraph's own proxy waits for ever
MASTER_TIMEOUT = 3.0


class _TimeoutTransport(xmlrpc.client.Transport):
    def __init__(self, timeout: float):
        super().__init__()
        self._timeout = timeout

    def make_connection(self, host):  # type: ignore[no-untyped-def]
        conn = super().make_connection(host)
        conn.timeout = self._timeout
        return conn


def proxy(uri: str, timeout: float) -> Any:
    """An ``xmlrpc.client.ServerProxy`` whose every request gives up after ``timeout`` seconds."""
    return xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(timeout))


def node_alive(uri: str, timeout: float = 1.0) -> bool:
    """True if the node at ``uri`` answers ``getPid`` (a node killed outright stays registered)."""
    try:
        code, _, _ = proxy(uri, timeout).getPid("/bmtree")
        return code == 1
    except (OSError, socket.timeout, xmlrpc.client.Error, http.client.HTTPException):
        return False


def master_api(caller_id: str, timeout: float = MASTER_TIMEOUT, master_uri: Optional[str] = None) -> Any:
    """A ``rosgraph.Master`` whose every query gives up after ``timeout`` seconds (``socket.timeout``,
    an OSError, as a refused connection is)."""
    import rosgraph

    master = rosgraph.Master(caller_id, master_uri=master_uri)
    master.handle = proxy(master.master_uri, timeout)
    return master


def master_answers(timeout: float, master_uri: Optional[str] = None) -> bool:
    """True if the master answers ``getPid`` within ``timeout`` seconds. ``rosgraph.is_master_online``
    has no timeout (a master that is unreachable or stopped holds it for minutes, or for ever) and
    swallows KeyboardInterrupt; a Ctrl-C here is raised."""
    import rosgraph

    try:
        code, _, _ = proxy(master_uri or rosgraph.get_master_uri(), timeout).getPid("/bmtree")
        return code == 1
    except (OSError, http.client.HTTPException, xmlrpc.client.Error):
        return False


def master_absence(master_uri: str, timeout: float = 2.0) -> str:
    """Why nothing answered at ``master_uri``, for an operator: nothing listens on its port, its
    host does not answer (the network, or a wrong address), its name does not resolve; '' when a
    connection can be made (something listens there, but it did not answer as a master)."""
    import socket
    import urllib.parse

    parsed = urllib.parse.urlparse(master_uri)
    host, port = parsed.hostname or "localhost", parsed.port or 11311
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return ""
    except socket.gaierror:
        return "%s is no host name this machine can resolve (check ROS_MASTER_URI)" % host
    except ConnectionRefusedError:
        return "nothing listens on port %d of %s: no master runs there (start one: roscore), or ROS_MASTER_URI " \
               "names the wrong port" % (port, host)
    except OSError as exc:   # a timeout, no route to the host, the network down
        return "%s does not answer (%s): is the robot's network up, and is ROS_MASTER_URI its address?" % (
            host, "timed out" if isinstance(exc, socket.timeout) else exc.strerror or exc)


class MasterProxy(xmlrpc.client.ServerProxy):
    """A proxy of the master for rospy's cache (``rospy.core._xmlrpc_cache``, which every master
    question of rospy goes through; rospy's own has no timeout): a question gives up after
    ``timeout`` seconds, raising an OSError (rospy retries a registration then, for as long as it
    is not shut down). With ``sticky`` (a process leaving the graph), once one went unanswered
    (or at once with ``dead``: the master is known not to answer) every later one fails at once,
    so unregistering N topics from a master that does not answer costs ``timeout`` seconds, not
    N times rospy's none. Serialized by a lock, as rospy's own."""

    def __init__(self, uri: str, timeout: float, sticky: bool = False, dead: bool = False):
        super().__init__(uri, transport=_TimeoutTransport(timeout))
        self._lock = threading.Lock()
        self.sticky = sticky
        self.failed = dead  # a question went unanswered (with ``sticky``: every later one fails)

    def _ServerProxy__request(self, methodname: str, params: Any) -> Any:
        with self._lock:
            if self.failed and self.sticky:  # (errno, text): rospy's unregistering unpacks a socket error so
                raise OSError(errno.ETIMEDOUT, "the ROS master did not answer an earlier question")
            try:
                return xmlrpc.client.ServerProxy._ServerProxy__request(  # type: ignore[attr-defined]
                    self, methodname, params)
            except (OSError, http.client.HTTPException) as exc:
                self.failed = True
                raise OSError(getattr(exc, "errno", None) or errno.ETIMEDOUT, "the ROS master did not answer (%s)"
                              % (exc or type(exc).__name__)) from exc


UNREACHABLE = frozenset((errno.ETIMEDOUT, errno.EHOSTUNREACH, errno.ENETUNREACH, errno.EHOSTDOWN, errno.ENETDOWN))
"""Errors that say nothing of the peer's process: its machine did not answer (a link down, a cable pulled,
keepalive probes unanswered). A process that ended on a machine that answers is refused (or reset)."""
KEEPALIVE = (("TCP_KEEPIDLE", 5), ("TCP_KEEPINTVL", 2), ("TCP_KEEPCNT", 3))  # a dead peer noticed in ~11 s


class PidLine:
    """A ROS node's (or the master's) ``getPid`` over one kept-alive HTTP connection that can be
    waited on.

    A new connection per question costs the peer a thread and this process a TCP handshake
    each time; one kept open also tells, by closing, that the peer's process went away.
    """

    def __init__(self, uri: str, timeout: float, caller: str = "/bmtree"):
        parts = urllib.parse.urlsplit(uri)
        self.host = parts.hostname or "localhost"
        self.port = parts.port or 11311
        self.path = parts.path or "/"
        self.timeout = timeout
        self.kept = False  # the peer kept the connection open after its last answer
        self._conn: Optional[http.client.HTTPConnection] = None
        self._body = xmlrpc.client.dumps((caller,), "getPid").encode()

    def pid(self) -> Optional[int]:
        """The pid; None when there is no answer (down, unreachable, busy, or not a ROS node)."""
        try:
            return self.ask()
        except OSError:
            return None

    def ask(self) -> Optional[int]:
        """The pid; None when no answer comes in time (alive but busy, or stopped), or its machine cannot
        be reached (:data:`UNREACHABLE`: a link that dropped is no process that ended).

        Raises:
            OSError: the connection was refused or broken by the peer's machine (the process is gone).
        """
        for fresh in (self._conn is None, True):  # a kept connection closed meanwhile: once more, afresh
            try:
                if self._conn is None:
                    self._conn = http.client.HTTPConnection(self.host, self.port, timeout=self.timeout)
                    self._conn.connect()
                    _keepalive(self._conn.sock)
                self._conn.request("POST", self.path, self._body, {"Content-Type": "text/xml"})
                resp = self._conn.getresponse()
                data = resp.read()
                self.kept = not resp.will_close
                if not self.kept:
                    self.close()
                (code, _, pid), = xmlrpc.client.loads(data)[0]
                return pid if code == 1 and isinstance(pid, int) else None
            except socket.timeout:
                self.close()
                return None
            except (OSError, http.client.HTTPException) as exc:
                self.close()
                if isinstance(exc, OSError) and exc.errno in UNREACHABLE:
                    return None   # no route, or no answer from its machine: the network, not the process
                if fresh:
                    raise exc if isinstance(exc, OSError) else OSError("bad answer: %s" % exc)
            except (xmlrpc.client.Error, ValueError, TypeError):  # answered, but not as a ROS node does
                self.close()
                return None
        return None

    def fileno(self) -> int:
        """The kept connection's socket (-1 when none is kept), to wait on with others."""
        sock = self._conn.sock if self._conn is not None and self.kept else None
        return sock.fileno() if sock is not None else -1

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        self.kept = False


def _keepalive(sock: Any) -> None:
    """Let the kernel probe an idle connection, so that a vanished machine is noticed."""
    if sock is None:
        return
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
    for name, value in KEEPALIVE:
        if hasattr(socket, name):
            sock.setsockopt(socket.IPPROTO_TCP, getattr(socket, name), value)


def wait_closed(lines: Mapping[Any, PidLine], limit: float, wake: Optional[socket.socket] = None
                ) -> Tuple[bool, Set[Any]]:
    """Wait on the kept connections of ``lines`` until one closes, ``wake`` is readable or ``limit``
    seconds pass: (woken by ``wake``, the keys whose connection closed, now closed here: ask afresh)."""
    with selectors.DefaultSelector() as sel:
        for key, line in lines.items():
            if line.fileno() >= 0:
                sel.register(line.fileno(), selectors.EVENT_READ, key)
        if wake is not None:
            sel.register(wake, selectors.EVENT_READ, wake)
        ready = [k.data for k, _ in sel.select(limit)] if sel.get_map() else []
    closed = {key for key in ready if key is not wake}
    for key in closed:  # closed by the peer (or something unasked for): a fresh connection next time
        lines[key].close()
    return wake is not None and wake in ready, closed
