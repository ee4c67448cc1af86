"""A synchronous Blackboard client for scripts: ``BlackboardClient().get(["apple"])``."""
from __future__ import annotations

import http.client
import threading
import time
from typing import Any, Dict, List, Optional, Tuple

from comm import TOPIC_BB_ANSWER, TOPIC_BB_REQUEST, TOPIC_CALL
from comm.errors import ProtocolError
from comm.messages import BlackboardAnswer, BlackboardRequest

__all__ = ["BlackboardClient", "BlackboardError", "blackboard_listeners", "blackboard_nodes", "silent_blackboards"]


def blackboard_listeners(caller: str = "/bmtree_ready", timeout: float = 0.5) -> List[str]:
    """The running Blackboard nodes on the master: those that take requests and listen to the
    calls (a node killed outright stays registered, so each is asked for its pid)."""
    return blackboard_nodes(caller, timeout)[0]


def blackboard_nodes(caller: str = "/bmtree_ready", timeout: float = 0.5
                     ) -> Tuple[List[str], Dict[str, Tuple[str, str]]]:
    """The Blackboard nodes registered on the master: those that answer here, and those that do
    not (node -> (its URI, why not: :func:`comm.address.reach`)). Each master question gives up
    after :data:`comm.rpc.MASTER_TIMEOUT` seconds (``socket.timeout``, an OSError)."""
    import rosgraph

    from comm.address import reach
    from comm.rpc import MASTER_TIMEOUT, master_api

    master = master_api(caller, MASTER_TIMEOUT)
    subs_of = {t: set(n) for t, n in master.getSystemState()[1]}
    live: List[str] = []
    silent: Dict[str, Tuple[str, str]] = {}
    for node in sorted(subs_of.get(TOPIC_BB_REQUEST, set()) & subs_of.get(TOPIC_CALL, set())):
        try:
            uri = master.lookupNode(node)
        except rosgraph.masterapi.MasterError:
            continue
        try:
            failure = reach(uri, timeout)
        except http.client.HTTPException:  # answered, not as a ROS node
            failure = "not a ROS node"
        if failure:
            silent[node] = (uri, failure)
        else:
            live.append(node)
    return live, silent


def silent_blackboards(silent: Dict[str, Tuple[str, str]], master_uri: Optional[str] = None) -> str:
    """What to say of the Blackboard nodes that are registered but do not answer here
    (:func:`blackboard_nodes`): "" when there are none. A refused connection: the process is gone
    (killed outright, its registration left behind); a timeout, no route: its address (a wrong
    ``ROS_IP`` on its machine, :func:`comm.address.node_address_problem`)."""
    from comm.address import REFUSED, node_address_problem

    out = []
    for node, (uri, failure) in sorted(silent.items()):
        why = node_address_problem(node, uri, failure, master_uri)
        if why:
            out.append("the Blackboard node %s is registered but cannot be reached: %s" % (node, why))
            continue
        if failure == REFUSED:
            why = ("nothing listens at %s, so its process is gone (killed outright, its registration left behind): "
                   "start it again (bmtree-blackboard, or roslaunch bmtree blackboard.launch)" % uri)
        else:
            why = "%s at %s (is its process stuck?)" % (failure, uri)
        out.append("the Blackboard node %s is registered but does not answer from here: %s" % (node, why))
    return "; ".join(out)


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
