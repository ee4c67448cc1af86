"""Steering over ROS: the topics a running ``bmtree run --control`` takes commands on and answers on
(:func:`ros_controller`), and the client that sends them (``bmtree control``, the watch's keys, the
page's buttons). What a command does is :class:`coordinator.control.Controller`'s."""
from __future__ import annotations

import itertools
import json
import threading
import time
from typing import Any, Dict, List

from comm import settle_new_connection
from comm.nodelife import registering
from coordinator.control import MAX_REQUEST, REPLY, REQUEST, Controller, Unreadable, read_request

__all__ = ["ControlClient", "ros_controller"]

MASTER_QUESTION = 3.0  # s the master may take to say which runs there are


class ControlClient:
    """Sends commands to the run on this master and waits for each reply (watch keys, web buttons, CLI)."""

    _ids = itertools.count(1)

    def __init__(self, request: str = REQUEST, reply: str = REPLY):
        import rospy
        from std_msgs.msg import String

        self._String = String
        self._replies: Dict[Any, Dict[str, Any]] = {}
        self._cond = threading.Condition()
        self._sub = rospy.Subscriber(reply, String, self._got, queue_size=100)
        self._pub = rospy.Publisher(request, String, queue_size=100)
        self._request = rospy.resolve_name(request)
        self._prefix = "%s-%d" % (rospy.get_name(), int(time.time() * 1000) % 100000)

    def _got(self, msg: Any) -> None:
        try:
            rep = json.loads(msg.data)
            key = rep.get("id")
        except (ValueError, AttributeError):
            return
        with self._cond:
            self._replies[key] = rep
            self._cond.notify_all()

    def runs(self) -> List[str]:
        """The nodes of the runs on this master now (every run takes requests, refusing them without
        ``--control``): one master query. Raises OSError when the master does not answer."""
        import rospy

        from comm.rpc import master_api

        _, subs, _ = master_api(rospy.get_name(), MASTER_QUESTION).getSystemState()
        return sorted(n for topic, nodes in subs if topic == self._request for n in nodes if n != rospy.get_name())

    def send(self, command: Dict[str, Any], timeout: float = 10.0) -> Dict[str, Any]:
        """The run's reply, or ``{"ok": False, "answer": ...}`` if no run answers within ``timeout``.

        A command is for a run that runs now, never for one that starts later: it goes to the run
        named by ``to``, or to the one run on the master; none (or several, without ``to``) is said at
        once. It names that run (``to``), so no other run takes it."""
        to = str(command.get("to") or "")
        import rosgraph

        try:
            runs = self.runs()
        except (OSError, rosgraph.masterapi.Error) as exc:
            return {"ok": False, "answer": "no run answered: the ROS master does not answer (%s)" % exc}
        if to and to not in runs:
            return {"ok": False, "answer": "no run of node %s takes commands on this master%s" % (
                to, " (the runs on it: %s)" % ", ".join(runs) if runs else " (it has ended)")}
        if not to and not runs:
            return {"ok": False, "answer": "no run takes commands on this master now (a command is for a run that "
                                           "is running, not kept for the next one)"}
        if not to and len(runs) > 1:
            return {"ok": False, "answer": "%d runs take commands on this master (%s): say which one with --node" % (
                len(runs), ", ".join(runs))}
        to = to or runs[0]
        end = time.monotonic() + timeout
        waited = False
        while not (self._pub.impl.has_connection(to) and any(
                c.callerid_pub == to and not getattr(c, "done", False) for c in self._sub.impl.connections)) and \
                time.monotonic() < end:
            waited = True
            time.sleep(0.05)  # a message sent before the connection is up is lost
        if waited:
            settle_new_connection()  # the run's reply publisher, which this side counted first
        command = dict(command, to=to)
        cid = "%s-%d" % (self._prefix, next(self._ids))
        self._pub.publish(self._String(json.dumps(dict(command, id=cid))))
        with self._cond:
            while cid not in self._replies:
                left = end - time.monotonic()
                if left <= 0:
                    return {"ok": False, "answer": "no run answered on %s within %gs" % (REQUEST, timeout)}
                self._cond.wait(left)
            return self._replies.pop(cid)

    def close(self) -> None:
        self._sub.unregister()
        self._pub.unregister()


def ros_controller(enabled: bool, max_bytes: int = MAX_REQUEST) -> Controller:
    """A Controller fed by the request topic and answering on the reply topic (also when not
    enabled: then it refuses, so a user is told why nothing happens)."""
    import rospy
    from std_msgs.msg import String

    with registering():
        pub = rospy.Publisher(REPLY, String, queue_size=100)
    ctl = Controller(enabled, reply=lambda r: pub.publish(String(json.dumps(r, default=str))))

    def got(msg: Any) -> None:
        header = getattr(msg, "_connection_header", None) or {}
        by = str(header.get("callerid", "?"))
        cmd = read_request(msg.data, max_bytes, by)
        if isinstance(cmd, Unreadable) and cmd.args[3] not in (None, "", rospy.get_name()):
            return  # for another run, as far as its text says
        if isinstance(cmd, dict):
            if cmd.get("to") not in (None, "", rospy.get_name()):
                return  # for another run on this master (bmtree watch names the run it shows)
            cmd["by"] = by
        ctl.submit(cmd)  # (one that cannot be read is refused as every malformed command is)

    with registering():
        ctl.subscription = rospy.Subscriber(REQUEST, String, got, queue_size=100)
    return ctl
