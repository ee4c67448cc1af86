"""The transport over real ROS topics (DESIGN §2). The only coordinator part that talks to ROS."""
from __future__ import annotations

import logging
import time
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional

from comm import (
    TOPIC_BB_ANSWER,
    TOPIC_BB_REQUEST,
    TOPIC_CALL,
    TOPIC_CANCEL,
    TOPIC_EVENT,
    TOPIC_RESULT,
    sync_publisher,
)
from comm.errors import ProtocolError
from comm.messages import (
    DEFAULT_MAX_BYTES,
    BlackboardAnswer,
    BlackboardRequest,
    CancelRequest,
    Event,
    FunctionCall,
    FunctionResult,
)
from coordinator.transport import Transport
from modules.definition import ModuleDefinition
from modules.discovery import LiveModule, live_modules

__all__ = ["RosTransport", "diff_definitions"]

log = logging.getLogger("bmtree.coordinator")


def diff_definitions(local: ModuleDefinition, live: ModuleDefinition) -> List[str]:
    """What differs between the definition a tree was checked against and the running module's."""
    out = []
    for name, fn in local.functions.items():
        other = live.functions.get(name)
        if other is None:
            out.append("function %r is not served by the running module" % name)
            continue
        for kind, a, b in (("input", fn.inputs, other.inputs), ("output", fn.outputs, other.outputs)):
            if [(p.name, p.rostype) for p in a] != [(p.name, p.rostype) for p in b]:
                out.append("%s %ss differ: here %s, running %s" % (name, kind, ", ".join(
                    "%s:%s" % (p.name, p.rostype) for p in a), ", ".join("%s:%s" % (p.name, p.rostype) for p in b)))
    for name, ev in local.events.items():
        other_ev = live.events.get(name)
        if other_ev is None or [(p.name, p.rostype) for p in ev.params] != [(p.name, p.rostype) for p in other_ev.params]:
            out.append("event %r differs or is missing in the running module" % name)
    return out


class RosTransport(Transport):
    """Publishes calls/cancels/requests; decodes results/events/answers in rospy's threads."""

    def __init__(self, node_name: str = "bmtree", max_bytes: int = DEFAULT_MAX_BYTES):
        self.node_name = node_name
        self.max_bytes = max_bytes
        self._deliver: Callable[[Any], None] = lambda item: None
        self._pubs: Dict[str, Any] = {}
        self._subs: List[Any] = []
        self._String: Any = None

    def open(self) -> None:
        """Init the rospy node (once per process) and the topics."""
        if self._pubs:
            return
        import rospy
        from std_msgs.msg import String

        self._String = String
        if not rospy.core.is_initialized():
            rospy.init_node(self.node_name, anonymous=True, disable_signals=True)
        self._pubs = {  # synchronous: lowest latency, and calls are small and few
            "call": sync_publisher(TOPIC_CALL, String),
            "cancel": sync_publisher(TOPIC_CANCEL, String),
            "request": sync_publisher(TOPIC_BB_REQUEST, String),
        }
        self._subs = [
            rospy.Subscriber(TOPIC_RESULT, String, self._on(FunctionResult), queue_size=1000, tcp_nodelay=True),
            rospy.Subscriber(TOPIC_EVENT, String, self._on(Event), queue_size=1000, tcp_nodelay=True),
            rospy.Subscriber(TOPIC_BB_ANSWER, String, self._on(BlackboardAnswer), queue_size=100, tcp_nodelay=True),
        ]

    def _on(self, cls: Any) -> Callable[[Any], None]:
        def callback(msg: Any) -> None:
            try:
                item = cls.decode(msg.data, self.max_bytes)
            except ProtocolError as exc:
                log.warning("ignored a malformed %s: %s", cls.__name__, exc)
                return
            self._deliver(item)
        return callback

    def connect(self, deliver: Callable[[Any], None]) -> None:
        self.open()
        self._deliver = deliver

    def _publish(self, which: str, text: str) -> None:
        self._pubs[which].publish(self._String(text))

    def send_call(self, call: FunctionCall) -> None:
        self._publish("call", call.encode())

    def send_cancel(self, cancel: CancelRequest) -> None:
        self._publish("cancel", cancel.encode())

    def send_request(self, request: BlackboardRequest) -> None:
        self._publish("request", request.encode())

    def live(self, timeout: float = 1.0) -> Dict[str, LiveModule]:
        return live_modules(timeout=timeout)

    def wait_ready(self, modules: Iterable[str], timeout: float,
                   definitions: Optional[Mapping[str, ModuleDefinition]] = None, blackboard: bool = False) -> None:
        """Wait (bounded) until every module runs with a matching definition and is connected.

        Raises:
            EnvironmentError: what is missing or different, after ``timeout`` seconds.
        """
        import rosgraph

        self.open()
        wanted = sorted(set(modules))
        end = time.monotonic() + timeout
        problems: List[str] = []
        master = rosgraph.Master("/bmtree_ready")
        while True:
            problems = []
            live = self.live()
            nodes = []
            legacy = self._legacy_nodes(master, [n for n in wanted if n not in live])
            for name in wanted:
                if name not in live:
                    if name in legacy:
                        nodes.append(legacy[name])
                    else:
                        problems.append("module %r is not running (no bmtree module announced it and no node "
                                        "named /%s listens on %s)" % (name, name, TOPIC_CALL))
                    continue
                nodes.append(live[name].node)
                if definitions and name in definitions:
                    diff = diff_definitions(definitions[name], live[name].definition)
                    if diff:
                        problems.append("module %r runs with another definition: %s" % (name, "; ".join(diff)))
            if not problems:
                problems = self._unconnected(master, nodes, blackboard)
            if not problems:
                return
            if time.monotonic() >= end:
                raise OSError("; ".join(problems))
            time.sleep(0.1)

    @staticmethod
    def _legacy_nodes(master: Any, names: List[str]) -> Dict[str, str]:
        """Original modules do not announce themselves; they are found by node name.

        A node called ``/<module>`` (in any namespace) that subscribes to
        ``/master/output`` is taken as that module, the convention of the original
        template modules.
        """
        if not names:
            return {}
        _, subs, _ = master.getSystemState()
        listeners = next((n for t, n in subs if t == TOPIC_CALL), [])
        found = {}
        for name in names:
            for node in listeners:
                if node.rsplit("/", 1)[-1] == name:
                    found[name] = node
        return found

    def _unconnected(self, master: Any, nodes: List[str], blackboard: bool) -> List[str]:
        """Nodes whose topics are not yet connected to ours (a first message would be lost)."""
        pubs, subs, _ = master.getSystemState()
        subs_of = {t: set(n) for t, n in subs}
        pubs_of = {t: set(n) for t, n in pubs}
        out = []
        need_call = len([n for n in nodes if n in subs_of.get(TOPIC_CALL, set())])
        if need_call < len(nodes) or self._pubs["call"].get_num_connections() < need_call:
            out.append("waiting for modules to connect to %s" % TOPIC_CALL)
        result_pubs = [n for n in nodes if n in pubs_of.get(TOPIC_RESULT, set())]
        if len(result_pubs) < len(nodes) or self._subs[0].get_num_connections() < len(result_pubs):
            out.append("waiting for %s connections" % TOPIC_RESULT)
        if blackboard and (self._pubs["request"].get_num_connections() < 1 or self._subs[2].get_num_connections() < 1):
            out.append("the Blackboard node is not running or not connected")
        return out

    def close(self) -> None:
        for s in self._subs:
            s.unregister()
        for p in self._pubs.values():
            p.unregister()
        self._subs, self._pubs = [], {}
