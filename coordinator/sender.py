"""Publishing a topic without ever making the ticking thread wait on a socket.

rospy's queued publishers also never block, but each ``publish`` ends with
``time.sleep(0)``, which hands the GIL to another thread: with 100 calls sent in one tick
that alone took half a millisecond per call on the CI machine, and a ``parallel`` of 100
calls went out one after another. A :class:`TopicSender` (one per module's own call topic,
which has one subscriber) writes each message's TCPROS frame itself: at once, in the
caller's thread, with a send that cannot block (``MSG_DONTWAIT``), when every
subscriber's socket takes the whole frame; otherwise (a subscriber that stopped reading
filled its socket) the rest of the frame and every later message go to the sender's own
thread, which writes them in order with blocking sends, and the caller only queues. So a
subscriber that stops reading blocks only its own topic's thread; past ``limit`` waiting
messages the oldest is dropped (and logged once), as rospy's queues do. ``publish(msg,
hold=True)`` keeps a message for :meth:`TopicSender.flush`: the transport keeps a tick's
calls so that each module gets them in one write, and wakes once (sent one by one, 50
modules woke twice as often and spent more CPU than the coordinator saved). Writing in the
caller's thread spares each call a wake-up of another thread.

A message published while the topic has no subscriber at all (the module's node is
restarting: its old connection is gone, the new one not made yet) would be lost, and a call
in it would wait out its whole timeout. Such messages are kept, with a key (the call id),
until a subscriber connects (:meth:`TopicSender.connected`), and a kept message can be taken
back (:meth:`TopicSender.discard`: a cancel of a call its module never got). The wait is
bounded (:meth:`TopicSender.give_up_after`): a call to a module that does not come back is
dropped and its caller told, never delivered to a node started much later. A connection whose
subscriber's process is gone is closed before each send, so a message does not go into a
dead node's socket (a node killed while it owed nothing, its replacement not connected yet).

:func:`topic_senders` makes many at once: rospy registers publishers with the master one
after another (a lock around each XML-RPC), which with 50 modules was most of ``bmtree
run``'s preflight; they are registered here concurrently instead.
"""
from __future__ import annotations

import collections
import io
import logging
import select
import socket
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Deque, List, Optional, Tuple

from comm import sync_publisher
from comm.rpc import proxy

__all__ = ["TopicSender", "peer_gone", "topic_senders", "widen_accept_queue"]

ACCEPT_QUEUE = 128  # pending TCP connections to this node's TCPROS port (rospy listens with 5)

log = logging.getLogger("bmtree.coordinator")

_Keyed = Tuple[Optional[str], bytes, float]  # a message's key (a call id, or None), frame, when published


def _close(conn: Any) -> None:
    """Close a broken connection; rospy removes it from its topic, as its own publish does."""
    try:
        conn.close()
    except Exception as exc:  # the topic was unregistered meanwhile (rospy then fails on its listeners)
        log.debug("closing a connection: %s", exc)


def _frame(msg: Any) -> bytes:
    """The message as rospy writes it on a TCPROS connection (length-prefixed)."""
    from rospy.msg import serialize_message

    buff = io.BytesIO()
    serialize_message(buff, 0, msg)
    return buff.getvalue()


def peer_gone(sock: socket.socket) -> bool:
    """Whether the peer of a subscriber connection went away (the socket is at its end or broken).
    A subscriber never writes after its handshake, so a readable end means gone."""
    try:
        # select first: with a timeout on the socket, recv would wait and then raise
        if not select.select([sock], [], [], 0)[0]:
            return False
        return sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
    except (BlockingIOError, InterruptedError):
        return False
    except (OSError, ValueError):
        return True


class TopicSender:
    """A publisher whose ``publish`` never blocks (see the module docstring)."""

    def __init__(self, topic: str, data_class: type, limit: int = 10000, pub: Any = None):
        self.pub: Any = pub if pub is not None else sync_publisher(topic, data_class, tcp_nodelay=True)
        self.resolved_name: str = self.pub.resolved_name
        self.impl = self.pub.impl  # its connections; has_connection()
        self.limit = limit
        self.dropped = 0
        self._queue: Deque[bytes] = collections.deque()  # whole frames for the thread
        self._held: List[_Keyed] = []  # (key, frame, when published) kept for flush()
        self._unconnected: List[_Keyed] = []  # (key, frame, when published) sent while nobody listened
        self.hold_limit: Optional[float] = None  # s a message may wait for a subscriber (give_up_after)
        self._on_expired: Callable[[List[str]], None] = lambda keys: None
        self._timer: Optional[threading.Timer] = None  # gives up what waited hold_limit
        self._rest: List[Tuple[Any, memoryview]] = []  # (connection, the unsent end of a frame): first
        self._writing = False  # the thread holds frames it has not written yet
        self._cond = threading.Condition()
        self._closed = False
        self._stopped = False  # closed and given up on flushing: drop the rest silently
        self._thread: Optional[threading.Thread] = None  # started when first needed

    def publish(self, msg: Any, hold: bool = False, key: Optional[str] = None) -> bool:
        """Send ``msg``; with ``hold``, keep it for :meth:`flush` instead (True if it was kept).
        ``key`` names it for :meth:`discard` while it waits for a subscriber."""
        keyed = (key, _frame(msg), time.monotonic())
        with self._cond:
            if hold:
                self._held.append(keyed)
                return True
        self._send([keyed])
        return False

    def flush(self) -> None:
        """Send the messages kept by ``publish(..., hold=True)``, in one write where the socket takes it."""
        with self._cond:
            frames, self._held = self._held, []
        if frames:
            self._send(frames)

    def connected(self, wanted: Callable[[str], bool] = lambda key: True) -> int:
        """A subscriber connected: send what waited for one (keyed messages only if still ``wanted``);
        how many were sent."""
        with self._cond:  # re-entrant: nothing newer is sent before these
            waiting, self._unconnected = self._unconnected, []
            frames = [w for w in waiting if w[0] is None or wanted(w[0])]
            if frames:
                self._send(frames)
        return len(frames)

    def drop_closed(self) -> int:
        """Close the connections whose subscriber is gone (its process died: the socket is at its
        end), so that what is sent next waits for a new subscriber instead of going into them;
        how many. A subscriber never writes after its handshake, so a readable end means gone."""
        gone = [conn for conn in list(self.impl.connections)
                if conn.socket is not None and not conn.done and peer_gone(conn.socket)]
        for conn in gone:
            _close(conn)
        return len(gone)

    def discard(self, key: str) -> bool:
        """Take back a message that still waits for a subscriber, or for :meth:`flush` (True if it did)."""
        with self._cond:
            for kept in (self._unconnected, self._held):
                for i, waiting in enumerate(kept):
                    if waiting[0] == key:
                        del kept[i]
                        return True
        return False

    def unsent(self, key: str) -> bool:
        """True while the message ``key`` waits for a subscriber (it was never sent)."""
        with self._cond:
            return any(w[0] == key for w in self._unconnected)

    def give_up_after(self, limit: float, on_expired: Callable[[List[str]], None]) -> None:
        """Bound the wait for a subscriber: a message kept ``limit`` seconds is dropped, never sent, and
        ``on_expired`` gets the keys of those dropped (from a timer's thread)."""
        self.hold_limit, self._on_expired = limit, on_expired

    def waiting_since(self) -> Optional[float]:
        """When the oldest message still waiting for a subscriber was published (None: none waits)."""
        with self._cond:
            return min((w[2] for w in self._unconnected), default=None)

    def expire(self, before: float) -> List[str]:
        """Give up the messages waiting for a subscriber since before ``before`` (``time.monotonic()``):
        they are never sent; the keys of those that had one."""
        with self._cond:
            old = [w for w in self._unconnected if w[2] < before]
            self._unconnected = [w for w in self._unconnected if w[2] >= before]
        return [w[0] for w in old if w[0] is not None]

    def _arm(self) -> None:
        """Wake when the oldest waiting message has waited ``hold_limit`` (called with the lock held)."""
        if self._timer is not None or self.hold_limit is None or self._closed or not self._unconnected:
            return
        delay = max(0.0, min(w[2] for w in self._unconnected) + self.hold_limit - time.monotonic())
        self._timer = threading.Timer(delay, self._give_up)
        self._timer.daemon = True
        self._timer.start()

    def _give_up(self) -> None:
        with self._cond:
            self._timer = None
            keys = self.expire(time.monotonic() - (self.hold_limit or 0.0))
            self._arm()  # for those that came later
        if keys:
            self._on_expired(keys)

    def _send(self, keyed: List[_Keyed]) -> None:
        self.drop_closed()  # a dead subscriber's socket would take the message, and nobody would read it
        broken = []
        with self._cond:
            if self._unconnected or not any(c.socket is not None and not c.done for c in list(self.impl.connections)):
                if not self._unconnected:
                    log.info("%s has no subscriber (its module's node restarting?): messages wait for one%s",
                             self.resolved_name, " (at most %gs)" % self.hold_limit if self.hold_limit else "")
                self._unconnected.extend(keyed)
                del self._unconnected[:-self.limit]
                self._arm()
            else:
                broken = self._write_now([f for _k, f, _t in keyed])
        for conn in broken:
            _close(conn)

    def _write_now(self, frames: List[bytes]) -> List[Any]:
        """Write ``frames`` from the caller's thread where the sockets take them (the rest to the
        thread); the connections found broken. Called with the lock held."""
        broken: List[Any] = []
        if self._queue or self._rest or self._writing:  # behind what waits: keep the order
            for frame in frames:
                self._enqueue(frame)
            return broken
        data = frames[0] if len(frames) == 1 else b"".join(frames)
        for conn in list(self.impl.connections):
            sock = conn.socket
            if sock is None or conn.done:
                continue
            if sock.gettimeout() is not None:  # Python would wait for room first: the thread writes
                self._rest.append((conn, memoryview(data)))
            else:
                try:
                    sent = sock.send(data, socket.MSG_DONTWAIT)
                except BlockingIOError:
                    sent = 0
                except OSError:
                    broken.append(conn)
                    continue
                if sent < len(data):
                    self._rest.append((conn, memoryview(data)[sent:]))
            conn.stat_bytes += len(data)  # counted when handed over, as rospy's queue does
            conn.stat_num_msg += len(frames)
        if self._rest:
            self._wake()
        return broken

    def _enqueue(self, frame: bytes) -> None:
        if len(self._queue) >= self.limit:
            self._queue.popleft()
            self.dropped += 1
            if self.dropped == 1:
                log.warning("%s: its subscriber does not read; dropping the oldest waiting messages",
                            self.resolved_name)
        self._queue.append(frame)
        self._wake()

    def _wake(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="send %s" % self.resolved_name, daemon=True)
            self._thread.start()
        self._cond.notify()

    def get_num_connections(self) -> int:
        return self.pub.get_num_connections()

    def _run(self) -> None:
        while True:
            with self._cond:
                self._writing = False
                while not self._queue and not self._rest and not self._closed:
                    self._cond.wait()
                if not self._queue and not self._rest:
                    return  # closed, and everything written
                rest, batch = self._rest, list(self._queue)
                self._rest = []
                self._queue.clear()
                self._writing = True
            for conn, data in rest:
                self._write(conn, data)
            for frame in batch:
                for conn in list(self.impl.connections):
                    if self._stopped:
                        return
                    if self._write(conn, frame):
                        conn.stat_bytes += len(frame)
                        conn.stat_num_msg += 1

    def _write(self, conn: Any, data: Any) -> bool:
        sock = conn.socket
        if sock is None or conn.done:
            return False
        try:
            sock.sendall(data)
            return True
        except OSError as exc:  # a broken connection, a closed topic at shutdown
            log.warning("could not publish on %s: %s", self.resolved_name, exc)
            _close(conn)
            return False

    def unregister(self, flush: float = 1.0) -> None:
        """Write what waits (cancels sent as a run ends), for at most ``flush`` seconds, then stop."""
        self.flush()
        with self._cond:
            self._closed = True
            self._cond.notify()
            thread = self._thread
            if self._timer is not None:
                self._timer.cancel()
        if thread is not None:
            thread.join(flush)
        self._stopped = True
        self.pub.unregister()


class _Connected:
    """A rospy ``SubscribeListener``: calls ``fn`` when a subscriber connects."""

    def __init__(self, fn: Callable[[str], None]):
        self.fn = fn

    def peer_subscribe(self, topic_name: str, topic_publish: Any, peer_publish: Any) -> None:
        self.fn(topic_name)

    def peer_unsubscribe(self, topic_name: str, num_peers: int) -> None:
        pass


def topic_senders(topics: List[str], data_class: Any, limit: int = 10000,
                  on_connect: Optional[Callable[[str], None]] = None) -> List[TopicSender]:
    """A :class:`TopicSender` per topic, registered with the master concurrently.

    The publishers' topics are entered in rospy's topic manager first, so that creating
    them does not register them one by one (rospy's ``acquire_impl`` finds them there);
    then one ``registerPublisher`` per topic goes to the master from a thread pool, as
    rospy's own registration would (the master then tells the subscribers). Unregistering
    and re-registering after a master restart (``comm.masterwatch``) see them as any other.
    ``on_connect`` is called (from rospy's thread, with the topic) whenever a subscriber connects.
    """
    if not topics:
        return []
    import rosgraph
    import rospy
    from rospy.impl.registration import get_topic_manager
    from rospy.topics import _PublisherImpl

    names = [rospy.resolve_name(t) for t in topics]
    tm = get_topic_manager()
    fresh = []
    with tm.lock:
        for name in names:
            if name not in tm.pubs:
                tm.pubs[name] = _PublisherImpl(name, data_class)
                tm.topics.add(name)
                fresh.append(name)
    extra = {"subscriber_listener": _Connected(on_connect)} if on_connect is not None else {}
    out = [TopicSender(t, data_class, limit, pub=sync_publisher(t, data_class, tcp_nodelay=True, **extra))
           for t in topics]
    if fresh:
        uri, caller_id, api = rosgraph.get_master_uri(), rospy.get_caller_id(), rospy.core.get_node_uri()
        local = threading.local()  # a kept-alive connection per thread: the master starts a thread per connection

        def register(name: str) -> None:
            try:
                if getattr(local, "master", None) is None:
                    local.master = proxy(uri, 10.0)
                code, msg, _ = local.master.registerPublisher(caller_id, name, data_class._type, api)
                if code != 1:
                    log.error("the master refused publisher %s: %s", name, msg)
            except Exception as exc:  # no master: the preflight says what is not connected
                log.warning("could not register publisher %s with the master: %s", name, exc)

        with ThreadPoolExecutor(max_workers=min(8, len(fresh))) as pool:
            list(pool.map(register, fresh))
    return out


def widen_accept_queue(backlog: int = ACCEPT_QUEUE) -> None:
    """Let many nodes connect to this node's topics at once.

    rospy's TCPROS server listens with a backlog of 5 and reads each handshake in its
    accepting thread: when 50 modules connect to their call topics at once, the
    connections past the queue are dropped and retried by TCP a second later.
    """
    from rospy.impl import tcpros_base

    tcpros_base.start_tcpros_server()
    tcp = getattr(tcpros_base._tcpros_server, "tcp_ros_server", None)
    sock = getattr(tcp, "server_sock", None)
    if sock is not None:
        sock.listen(backlog)
