"""One actionlib goal as the body of a module function: connect, send, wait, cancel, answer.

Most skills of a ROS 1 robot (move_base, MoveIt, manipulation) are actionlib action servers; a
basic module wraps each in a function. Written by hand, that wrapper tends to leave the goal
running when the tree halts the call, or to hang on a server that answers at once:
``SimpleActionClient.send_goal`` records the goal handle only after publishing the goal, so a
result that comes back first is dropped and the goal never ends. :class:`Action` does it once::

    self._move_base = Action(self, "move_base", MoveBaseAction)          # in setup()
    return self._move_base.run(goal, outputs=lambda result: {"success": True})

``run`` returns the outputs of a SUCCEEDED goal and raises :class:`ActionFailed` (a
:class:`~modules.basicmodule.Failure`: the call answers ``failed``) otherwise. When the call is
cancelled (tree halt, timeout, Ctrl-C on ``bmtree run``) it cancels the goal, waits a bounded
time for the server to end it, and raises, so the runtime answers ``cancelled``. When the module's
node stops (Ctrl-C, ``rosnode kill``) it cancels its running goals the same way, and their calls
answer ``failed: /move_base: the module's node stops: goal cancelled`` (the coordinator did not
cancel them; the runtime answers what the function raised, as for any call in flight when its
node stops). A server that does not end a cancelled goal in time is said in the call's answer
(``bmtree run`` lists the call under "may still be running"). A server whose process is gone
(its status connection closed) loses the goal at once.

A module killed outright (``kill -9``) cannot cancel its goals. When its node starts again (a
``respawn``), the first status it sees from the server still lists them, under ids that begin
with the node's name: it cancels those (its earlier process's, so nobody waits for them) before
it sends a goal, and logs each.
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable, Dict, Optional, Set

from modules.basicmodule import BasicModule, Failure

__all__ = ["Action", "ActionFailed", "GOAL_STATES", "state_name"]

log = logging.getLogger("bmtree.module")

#: actionlib_msgs/GoalStatus codes by name (the terminal ones end a goal)
GOAL_STATES = {0: "PENDING", 1: "ACTIVE", 2: "PREEMPTED", 3: "SUCCEEDED", 4: "ABORTED", 5: "REJECTED",
               6: "PREEMPTING", 7: "RECALLING", 8: "RECALLED", 9: "LOST"}
SUCCEEDED = 3
LOST = 9
_UNENDED = (0, 1, 6, 7)  # PENDING, ACTIVE, PREEMPTING, RECALLING: a goal the server still runs or holds
_SENT: Set[str] = set()  # ids of the goals this process sent (every Action): not an earlier process's
_SENT_LOCK = threading.Lock()  # also held while a goal is sent: a sweep never sees one of ours unrecorded
_DONE = 7  # actionlib.CommState.DONE: the client's state machine has the goal's result (or lost it)
_POLL = 0.5  # seconds between checks that the server still publishes its status
_CONNECT_POLL = 0.01  # as actionlib's wait_for_server


def state_name(state: Optional[int]) -> str:
    """``ABORTED`` for 4: the words of actionlib_msgs/GoalStatus, which servers' users know."""
    if state is None:
        return "unknown"
    return GOAL_STATES.get(state, "status %d" % state)


class ActionFailed(Failure):
    """The goal did not succeed: the call answers ``failed`` with this text (or ``cancelled``, when
    the call was cancelled). ``state`` is the goal's terminal GoalStatus code (None: it never ended,
    or was never sent), ``text`` the server's status text."""

    def __init__(self, message: str, namespace: str, state: Optional[int] = None, text: str = "",
                 not_stopped: str = ""):
        super().__init__(message, not_stopped=not_stopped)
        self.namespace = namespace
        self.state = state
        self.text = text


class _RosClient:
    """An actionlib ActionClient and the three things :class:`Action` asks of it: is its server
    connected (why not), how old is the server's last status, send a goal. Unit tests give a
    stand-in with the same methods."""

    def __init__(self, namespace: str, action_type: Any, stale_after: Optional[float] = None,
                 sweep: bool = True):
        import actionlib
        import rospy

        owner = self

        class _Timed(actionlib.ActionClient):  # type: ignore[misc]
            """Notes when the server's status last came: a server that died sends none (5 Hz otherwise)."""

            status_at: Optional[float] = None

            def _status_cb(self, msg: Any) -> None:
                self.status_at = time.monotonic()
                super()._status_cb(msg)
                owner.sweep()

        self.where = rospy.resolve_name(namespace)
        self._rospy = rospy
        self.stale_after = stale_after  # seconds without a status after which a connected server is not taken
        self._swept: Optional[str] = None if sweep else ""  # the server whose goals were looked at ('': never look)
        self.client = _Timed(namespace, action_type)

    def _server(self) -> Optional[str]:
        """The node of the server's last status while this node is still connected to it (actionlib keeps
        the last status for ever: a server that died would be named still), else None."""
        c = self.client
        last = c.last_status_msg
        if last is None:
            return None
        server = last._connection_header.get("callerid", "?")
        if not any(x.callerid_pub == server and not getattr(x, "done", False) for x in c.status_sub.impl.connections):
            return None
        return server

    def server_left(self) -> str:
        """Why the server that sent the last status is gone ('' while it is connected, or none was seen): its
        process ended or it stopped serving (rospy closes the status link at once), which a goal need not
        wait ``stale_after`` seconds of silence to learn."""
        last = self.client.last_status_msg
        if last is None or self._server() is not None:
            return ""
        return "its server %s closed its connection to %s/status: it stopped or died" % (
            last._connection_header.get("callerid", "?"), self.where)

    def sweep(self) -> None:
        """Once per server, when connected both ways (a cancel published earlier could be lost): cancel the
        goals it still runs under this node's name that this process did not send, which an earlier
        process of this node left (killed outright: nobody waits for them, and the robot would go on)."""
        if getattr(self, "client", None) is None:  # a status before __init__ ended
            return
        if self._swept is not None and self._swept in ("", self._server()):
            return
        with _SENT_LOCK:
            server = self._server()
            if server is None or server == self._swept or self.missing():
                return
            self._swept = server
            prefix = self._rospy.get_name() + "-"  # actionlib's goal ids: NODE-COUNT-STAMP
            left = [s.goal_id.id for s in self.client.last_status_msg.status_list
                    if s.status in _UNENDED and s.goal_id.id.startswith(prefix) and s.goal_id.id not in _SENT]
            for goal_id in left:
                from actionlib_msgs.msg import GoalID

                self.client.pub_cancel.publish(GoalID(stamp=self._rospy.Time(), id=goal_id))
                log.warning("%s: cancelled goal %s, which an earlier process of this node left running on %s",
                            self.where, goal_id, server)

    def missing(self) -> str:
        """Empty once a server is connected both ways (actionlib's own ``wait_for_server`` test, without
        its ROS-time timeout: with ``use_sim_time`` and no clock that never ends), else what is not.

        The server is the node of the last status, while this node is still connected to its status
        topic (actionlib keeps that last message for ever: a server that died would be named still)
        and its status is not older than ``stale_after``."""
        c = self.client
        server = self._server()
        if server is None:  # none yet, or its server left (stopped or died): rospy closed the link
            return "nothing publishes %s/status" % self.where
        age = self.status_age()
        if self.stale_after is not None and age is not None and age > self.stale_after:
            return "its server %s has published nothing on %s/status for %.1fs" % (server, self.where, age)
        if not (c.pub_goal.impl.has_connection(server) and c.pub_cancel.impl.has_connection(server)):
            return "its server %s has not subscribed to %s/goal and /cancel" % (server, self.where)
        for sub, topic in ((c.result_sub, "result"), (c.feedback_sub, "feedback")):
            if not any(x.callerid_pub == server for x in sub.impl.connections):
                return "this node is not connected to %s/%s of its server %s" % (self.where, topic, server)
        return ""

    def status_age(self) -> Optional[float]:
        at = self.client.status_at
        return None if at is None else time.monotonic() - at

    def send(self, goal: Any, transition: Callable[[Any], None], feedback: Callable[[Any, Any], None]) -> Any:
        # ActionClient.send_goal tracks the goal before publishing it, and calls back with the handle:
        # a result that arrives before it returns is not lost (SimpleActionClient's is)
        self.sweep()  # an earlier process's goals are cancelled before this one starts
        with _SENT_LOCK:
            handle = self.client.send_goal(goal, transition, feedback)
            _SENT.add(handle.comm_state_machine.action_goal.goal_id.id)
        return handle

    def forget(self, handle: Any) -> None:
        """The call of a goal sent with :meth:`send` is over (its id need not be kept)."""
        with _SENT_LOCK:
            _SENT.discard(handle.comm_state_machine.action_goal.goal_id.id)

    def shutting_down(self) -> bool:
        return bool(self._rospy.is_shutdown())

    def on_shutdown(self, fn: Callable[[], None]) -> None:
        # rospy.on_shutdown hooks run before its pre-shutdown ones, the first of which closes the topics
        self._rospy.on_shutdown(fn)


class Action:
    """An actionlib action server, run one goal per call from a module's functions.

    Args:
        module: the module whose functions call :meth:`run` (its running call is cancelled
            through it).
        namespace: the action's namespace (``move_base``: its topics are ``move_base/goal`` …),
            resolved and remapped as any ROS name of the node.
        action_type: the generated ``…Action`` class (``move_base_msgs.msg.MoveBaseAction``).
        connect_timeout: seconds a call waits for the server to be connected before it fails.
        cancel_timeout: seconds a cancelled call waits for the server to end the goal; default
            0.8 of the runtime's cancel grace (0.8 s), so the module is free when the grace ends.
        silence_timeout: seconds without a status from the server (5 a second normally) after
            which the goal is taken as LOST (the server died), and a connected server as no server
            (the call is not sent); None never.
        cancel_left_goals: cancel, once connected, the goals the server still runs for an earlier
            process of this node (killed outright, then restarted); False leaves them.
        client: a stand-in for the ROS client (tests); default made on first use, after
            ``rospy.init_node``.
    """

    def __init__(self, module: BasicModule, namespace: str, action_type: Any, connect_timeout: float = 5.0,
                 cancel_timeout: Optional[float] = None, silence_timeout: Optional[float] = 5.0,
                 client: Any = None, cancel_left_goals: bool = True):
        self.module = module
        self.namespace = namespace
        self.action_type = action_type
        self.connect_timeout = connect_timeout
        self.cancel_timeout = cancel_timeout
        self.silence_timeout = silence_timeout
        self.cancel_left_goals = cancel_left_goals
        self._client = client
        self._lock = threading.Lock()
        self._active: Dict[Any, threading.Event] = {}  # running goals' handles and ends, cancelled if the node stops
        self._stopping = False  # the node stops: set by its shutdown hook, before rospy.is_shutdown()
        self._stop_cancelled: Set[Any] = set()  # the goals that hook cancelled

    @property
    def where(self) -> str:
        """The namespace as resolved (``/move_base``), for messages."""
        return getattr(self._client, "where", self.namespace) if self._client is not None else self.namespace

    def connect(self, timeout: float = 0.0) -> bool:
        """Make the client (its connections to the server start now) and wait up to ``timeout``
        seconds for the server; True if it is connected. Call it in ``setup()`` so that the first
        call does not wait for the connections."""
        client = self._get_client()
        end = time.monotonic() + timeout
        while client.missing():
            if time.monotonic() >= end:
                return False
            time.sleep(_CONNECT_POLL)
        return True

    def run(self, goal: Any, outputs: Optional[Callable[[Any], Dict[str, Any]]] = None,
            feedback: Optional[Callable[[Any], None]] = None) -> Dict[str, Any]:
        """Run ``goal`` as the body of the calling function; the outputs of a SUCCEEDED goal
        (``outputs(result)``, ``{}`` without it). Raises :class:`ActionFailed` for any other end,
        and after the call was cancelled (the goal cancelled first). ``feedback(msg)`` is called
        with each feedback message, in rospy's thread (``self.emit`` an event there, sparingly)."""
        ctx = self.module.context
        wake = threading.Event()
        ctx.on_cancel(wake.set)  # runs at once if the call was cancelled already
        client = self._connected(ctx, wake)
        done = threading.Event()

        def transition(handle: Any) -> None:
            if handle.get_comm_state() == _DONE:
                done.set()
                wake.set()

        def on_feedback(handle: Any, msg: Any) -> None:
            if feedback is not None:
                try:
                    feedback(msg)
                except Exception:
                    log.exception("the feedback callback of %s raised", self.where)

        handle = client.send(goal, transition, on_feedback)  # kept: actionlib tracks a goal while its handle lives
        with self._lock:
            self._active[handle] = done
        try:
            lost = self._wait(ctx, client, handle, done, wake)
        finally:
            with self._lock:
                self._active.pop(handle, None)
                self._stop_cancelled.discard(handle)
            if done.is_set() and hasattr(client, "forget"):
                client.forget(handle)
        state = handle.get_goal_status() if done.is_set() else None
        text = handle.get_goal_status_text() if done.is_set() else ""
        if ctx.cancelled.is_set():
            going = ""
            if state is None:
                going = "%s did not end the goal within %gs of its cancel" % (self.where, self._cancel_timeout())
                log.warning("%s: it may still run it", going)
            raise ActionFailed("%s: call cancelled, goal %s" % (self.where, state_name(state) if state is not None
                                                                 else "still running"), self.where, state, text,
                               not_stopped=going)
        if state != SUCCEEDED and self._stops(client):
            # cancelled by the node's stop, not by the coordinator: a server that honours the cancel
            # ends it PREEMPTED "cancelled by the client", which would read as a navigation failure
            if state is None:
                log.warning("%s did not end the goal within %gs of its cancel as the node stops: it may still run it",
                            self.where, self._cancel_timeout())
            raise ActionFailed("%s: the module's node stops: goal cancelled" % self.where, self.where, state, text)
        if lost:
            raise ActionFailed("%s: goal LOST: %s" % (self.where, lost), self.where, LOST, lost)
        if state == SUCCEEDED:
            return outputs(handle.get_result()) if outputs is not None else {}
        raise ActionFailed("%s: goal %s%s" % (self.where, state_name(state), ": " + text if text else
                                              " (the server gave no status text)"), self.where, state, text)

    # -- helpers -------------------------------------------------------------------------
    def _get_client(self) -> Any:
        with self._lock:
            if self._client is None:
                self._client = _RosClient(self.namespace, self.action_type, stale_after=self.silence_timeout,
                                          sweep=self.cancel_left_goals)
                self._client.on_shutdown(self._cancel_all)
            return self._client

    def _cancel_all(self) -> None:
        """The node stops: the goals it started must not drive the robot on without it. Waits (at most
        the cancel timeout) for the server to end them: rospy closes its publishers right after this
        hook, and a cancel still in the publisher's queue would be lost."""
        server = getattr(self.module, "_server", None)
        calls = server.in_flight() if server is not None else []
        with self._lock:
            self._stopping = True
            running = dict(self._active)
            self._stop_cancelled.update(running)
        for h in running:
            _cancel(h)
        end = time.monotonic() + self._cancel_timeout()
        for done in running.values():
            done.wait(max(0.0, end - time.monotonic()))
        if running and server is not None:   # the calls those goals served answer before the topics close
            server.answers_sent(calls, max(0.1, end - time.monotonic()))

    def _stops(self, client: Any) -> bool:
        """The module's node stops (rospy's ``is_shutdown()`` is true only after its shutdown hooks)."""
        return self._stopping or client.shutting_down()

    def _cancel_timeout(self) -> float:
        if self.cancel_timeout is not None:
            return self.cancel_timeout
        server = getattr(self.module, "_server", None)
        return 0.8 * float(getattr(server, "cancel_grace", 1.0))

    def _connected(self, ctx: Any, wake: threading.Event) -> Any:
        """The client, its server connected; ActionFailed if not within ``connect_timeout`` or if
        the call is cancelled meanwhile (no goal sent)."""
        client = self._get_client()
        end = time.monotonic() + self.connect_timeout
        while True:
            why = client.missing()
            if not why:
                return client
            if ctx.cancelled.is_set():
                raise ActionFailed("%s: call cancelled before the goal was sent" % self.where, self.where)
            if self._stops(client):
                raise ActionFailed("%s: the module's node stops: no goal sent" % self.where, self.where)
            if time.monotonic() >= end:
                raise ActionFailed("no action server on %s within %gs: %s" % (self.where, self.connect_timeout, why),
                                   self.where)
            wake.wait(_CONNECT_POLL)

    def _wait(self, ctx: Any, client: Any, handle: Any, done: threading.Event, wake: threading.Event) -> str:
        """Wait for the goal to end, cancelling it when the call is cancelled (then at most the
        cancel timeout). Returns why the goal is taken as lost ("" when it is not)."""
        deadline: Optional[float] = None
        while not done.is_set():
            wake.clear()
            now = time.monotonic()
            if ctx.cancelled.is_set() or self._stops(client):
                if deadline is None:
                    with self._lock:
                        cancelled = handle in self._stop_cancelled
                    if not cancelled:  # not by the node's shutdown hook already
                        _cancel(handle)
                    deadline = now + self._cancel_timeout()
                    continue
                if now >= deadline:
                    return ""
            else:
                left = client.server_left() if hasattr(client, "server_left") else ""
                if left:
                    return left
                age = client.status_age()
                if self.silence_timeout is not None and age is not None and age > self.silence_timeout:
                    _cancel(handle)  # a server that comes back must not run it on
                    return "no status from the server for %.1fs: it stopped or died" % age
            if done.is_set():
                break
            wait = _POLL if deadline is None else min(_POLL, max(0.0, deadline - now))
            wake.wait(wait)
        return ""


def _cancel(handle: Any) -> None:
    """Ask the server to cancel a goal; a node that stops may no longer publish (nothing else to do)."""
    try:
        handle.cancel()
    except Exception as exc:
        log.warning("could not cancel an actionlib goal: %s", exc)
