"""A synchronous Blackboard client for scripts: ``BlackboardClient().get(["apple"])``."""
from __future__ import annotations

import threading
import time
from typing import Any, Dict, List

from comm import TOPIC_BB_ANSWER, TOPIC_BB_REQUEST, TOPIC_CALL
from comm.errors import ProtocolError
from comm.messages import BlackboardAnswer, BlackboardRequest

__all__ = ["BlackboardClient", "BlackboardError", "blackboard_listeners"]


def blackboard_listeners(caller: str = "/bmtree_ready", timeout: float = 0.5) -> List[str]:
    """The running Blackboard nodes on the master: those that take requests and listen to the
    calls (a node killed outright stays registered, so each is asked for its pid)."""
    import rosgraph

    from comm.rpc import node_alive

    master = rosgraph.Master(caller)
    subs_of = {t: set(n) for t, n in master.getSystemState()[1]}
    out = []
    for node in sorted(subs_of.get(TOPIC_BB_REQUEST, set()) & subs_of.get(TOPIC_CALL, set())):
        try:
            if node_alive(master.lookupNode(node), timeout):
                out.append(node)
        except rosgraph.masterapi.MasterError:
            continue
    return out


class BlackboardError(Exception):
    """No answer in time, or the answer lists missing names or an error."""


class BlackboardClient:
    """Needs an initialised rospy node (``rospy.init_node``) in this process."""

    def __init__(self, connect_timeout: float = 5.0):
        import rospy
        from std_msgs.msg import String

        self._String = String
        self._pending: Dict[str, Any] = {}
        self._lock = threading.Lock()
        self._pub = rospy.Publisher(TOPIC_BB_REQUEST, String, queue_size=100)
        self._sub = rospy.Subscriber(TOPIC_BB_ANSWER, String, self._on_answer, queue_size=100)
        end = time.monotonic() + connect_timeout  # an answer sent before we listen is lost
        while (self._pub.get_num_connections() == 0 or self._sub.get_num_connections() == 0) \
                and time.monotonic() < end:
            time.sleep(0.01)

    def _on_answer(self, msg: Any) -> None:
        try:
            ans = BlackboardAnswer.decode(msg.data)
        except ProtocolError:
            return
        with self._lock:
            slot = self._pending.get(ans.request_id or "")
        if slot is not None:
            slot[1] = ans
            slot[0].set()

    def request(self, req: BlackboardRequest, timeout: float = 2.0) -> BlackboardAnswer:
        slot: List[Any] = [threading.Event(), None]
        with self._lock:
            self._pending[req.request_id or ""] = slot
        text = self._String(req.encode())
        end = time.monotonic() + timeout
        wait = 0.2
        try:
            # a request can be lost (a connection to a Blackboard node that has just been replaced
            # counts as connected until a write to it fails): reads are idempotent, so it is sent
            # again, same request_id, at growing intervals; the first answer is taken
            while True:
                self._pub.publish(text)
                left = end - time.monotonic()
                if slot[0].wait(max(0.0, min(wait, left))):
                    return slot[1]
                if left <= wait:
                    raise BlackboardError("no answer from the Blackboard node within %.1f s (is it running?)"
                                          % timeout)
                wait *= 2
        finally:
            with self._lock:
                self._pending.pop(req.request_id or "", None)

    def get(self, names: List[str], timeout: float = 2.0) -> Dict[str, Any]:
        """Latest value of each name (ROS messages); BlackboardError if any is missing."""
        ans = self.request(BlackboardRequest(var_names=list(names)), timeout)
        if ans.error or ans.missing:
            raise BlackboardError("; ".join(filter(None, [ans.error, "missing: %s" % ", ".join(ans.missing)
                                                           if ans.missing else ""])))
        return ans.values

    def history(self, name: str, n: int, timeout: float = 2.0) -> List[Any]:
        ans = self.request(BlackboardRequest(var_names=[name], history=n), timeout)
        if ans.error:
            raise BlackboardError(ans.error)
        return list(ans.msgs)

    def close(self) -> None:
        self._pub.unregister()
        self._sub.unregister()
