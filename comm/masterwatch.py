"""Survive a restarted ROS master: notice it and register this node again.

rospy registers a node's topics once, when they are created; a master that is killed and
started again knows nothing, so new nodes never find the old ones (``bmtree modules --live``
is empty, ``bmtree run`` finds no module). Connections between running nodes survive a
master restart (they are plain TCP), so re-registering is enough to be whole again.

:class:`MasterWatch` asks the master for its pid over one kept-alive HTTP connection and
then waits, without polling, for the master to close that connection: a master that dies
(killed, crashed, stopped) closes it at once, and TCP keepalive probes (every few seconds,
sent by the kernel) notice a master machine that went away or a connection that broke. While
the master does not answer it asks every ``period`` seconds. When the master answers again
after being unreachable, or with another pid, it registers every publisher,
subscriber and service of this process again through the master API with the node's own
XML-RPC URI (what ``rospy.impl.registration.RegManager`` does at start-up), tells the
node's subscribers the current publishers (its own ``publisherUpdate``), sets the
parameters the node asked to keep, and calls ``on_restart`` hooks (``on_down`` hooks when
the master stops answering: a run records both). A master that does not keep connections
open (HTTP/1.0) is asked every ``period`` seconds instead.

An idle node costs nothing: asking twice a second cost 50 idle module nodes 6% of a core,
and the master 3% more, for nothing.

What ROS cannot get back: parameters set by others (launch files, ``rosparam``, private
``_name:=value`` arguments of nodes that do not use this watch), nodes that do not
re-register (plain rospy/roscpp nodes), and anything the master held only in memory
(parameter subscriptions). Messages published while a subscriber was not connected are
not replayed.
"""
from __future__ import annotations

import logging
import socket
import threading
from typing import Any, Callable, Dict, List, Optional

from comm.rpc import PidLine, proxy, wait_closed

__all__ = ["MasterWatch", "watch_master", "current_watch"]

log = logging.getLogger("bmtree.master")


class MasterWatch:
    """One per process, after ``rospy.init_node``; :func:`watch_master` makes and starts it.

    Args:
        period: seconds between questions while the master does not answer (or does not keep
            connections open).
        timeout: seconds a question may take.
        recheck: seconds after which a quiet, kept connection is asked again anyway.
    """

    def __init__(self, period: float = 0.5, timeout: float = 2.0, recheck: float = 60.0):
        self.period = period
        self.timeout = timeout
        self.recheck = recheck
        import rosgraph

        # the node's own master (rosgraph reads __master:= remappings and ROS_MASTER_URI)
        self.master_uri = rosgraph.get_master_uri()
        self.params: Dict[str, Callable[[], Any]] = {}
        self.on_restart: List[Callable[[], None]] = []  # after registering again
        self.on_down: List[Callable[[], None]] = []     # when the master stops answering
        self.restarts = 0
        self.down = False  # the master does not answer now (as far as this watch knows)
        self._pid: Optional[int] = None
        self._line = PidLine(self.master_uri, timeout, "/bmtree_masterwatch")
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._thread: Optional[threading.Thread] = None
        self.registered = threading.Event()  # set after each successful re-registration

    def keep_param(self, key: str, value: Callable[[], Any]) -> None:
        """Set ``key`` again (to ``value()``; skipped when it returns None) after a master restart."""
        self.params[key] = value

    def start(self) -> None:
        import rospy

        if self._thread is None:
            self._pid = self._master_pid()
            self._thread = threading.Thread(target=self._loop, name="bmtree-masterwatch", daemon=True)
            self._thread.start()
            rospy.on_shutdown(self.stop)

    def stop(self) -> None:
        self._stop.set()
        try:
            self._wake_w.send(b"x")
        except OSError:  # stopped twice: the buffer is full or closed
            pass

    def _master(self) -> Any:
        return proxy(self.master_uri, self.timeout)

    def _master_pid(self) -> Optional[int]:
        return self._line.pid()

    def _loop(self) -> None:
        down = False
        while not self._stop.is_set():
            if down or not self._line.kept:
                if self._stop.wait(self.period):
                    return
            elif wait_closed({"master": self._line}, self.recheck, self._wake_r)[0]:
                return
            pid = self._master_pid()
            if pid is None:
                if not down:
                    log.warning("the ROS master at %s does not answer; waiting for it to come back", self.master_uri)
                    self._call(self.on_down)
                down = self.down = True
                continue
            if down or pid != self._pid:
                try:
                    self.register_again(restarted=pid != self._pid)
                except Exception as exc:  # the master went away again: retry next period
                    log.warning("could not register again with the ROS master: %s", exc)
                    down = self.down = True
                    continue
                self._pid = pid
                self.restarts += 1
            down = self.down = False

    @staticmethod
    def _call(hooks: List[Callable[[], None]]) -> None:
        for hook in list(hooks):
            try:
                hook()
            except Exception:  # a hook must not stop the watch
                log.exception("master watch hook %r failed", hook)

    def register_again(self, restarted: bool = True) -> None:
        """Register every topic, service and kept parameter of this node with the master (``restarted``: it
        answers with another pid; else it was only unreachable, and may have dropped this node meanwhile)."""
        import rospy
        from rospy.impl.registration import get_service_manager, get_topic_manager

        caller_id = rospy.get_caller_id()
        api = rospy.core.get_node_uri()
        master = self._master()
        tm = get_topic_manager()
        for topic, type_ in tm.get_publications():
            master.registerPublisher(caller_id, topic, type_, api)
        node = proxy(api, self.timeout)
        for topic, type_ in tm.get_subscriptions():
            code, _, publishers = master.registerSubscriber(caller_id, topic, type_, api)
            if code == 1:
                node.publisherUpdate("/master", topic, publishers)
        for service, uri in get_service_manager().get_services():
            master.registerService(caller_id, service, uri, api)
        for key, value in list(self.params.items()):
            v = value()
            if v is not None:
                master.setParam(caller_id, key, v)
        self._call(self.on_restart)
        if restarted:
            rospy.logwarn("registered again with the restarted ROS master at %s", self.master_uri)
        else:
            rospy.logwarn("the ROS master at %s answers again (it was unreachable, not restarted): registered again",
                          self.master_uri)
        self.registered.set()


_WATCH: Optional[MasterWatch] = None


def current_watch() -> Optional[MasterWatch]:
    """The process's MasterWatch, if :func:`watch_master` made one."""
    return _WATCH


def watch_master(period: float = 0.5) -> MasterWatch:
    """The process's MasterWatch, started (once per process, after ``rospy.init_node``)."""
    global _WATCH
    if _WATCH is None:
        _WATCH = MasterWatch(period)
        _WATCH.start()
    return _WATCH
