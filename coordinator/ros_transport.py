"""The transport over real ROS topics (DESIGN §2). The only coordinator part that talks to ROS
(with the modules it names below).

Calls and cancels go to a module's own call topic when its announcement names one (a
cancel there, marked ``"cancel": true``, can never overtake its call), else to the shared
``/master/output`` and ``/master/cancel`` (README, "Addressed calls").
Sending never blocks the ticking thread: a module's own topic is written by a
:class:`coordinator.sender.TopicSender` (a tick's messages to one module in one write that
cannot block; what a socket does not take, to that topic's own thread), the shared topics by
rospy's queued publishers (a queue and writer thread per subscriber connection), so a
subscriber that stops reading (a stopped process) fills only its own queue (then loses its
oldest messages). The preflight is :mod:`coordinator.preflight`; the start-up guard
:mod:`coordinator.startguard`; the run stream's topics :mod:`coordinator.rosstream`; the
liveness watchdogs' questions to the master :mod:`coordinator.rosliveness`.

A call is never delivered after it ended, nor held for ever: one kept for a module's node to
connect (restarting) is given up as ``module_lost`` after :data:`HOLD_LIMIT` seconds, or sooner
when the watchdog finds the module's node gone; one to a module reached on ``/master/output``
whose node is not connected there (ROS would drop it) ends ``module_lost`` at once. The
watchdog also watches the modules whose events a ``wait_event`` waits for
(:meth:`RosTransport.watch_module`).
"""
from __future__ import annotations

import contextlib
import json
import logging
import threading
import typing
from collections import OrderedDict
from typing import Any, Callable, Dict, Iterable, Iterator, List, Mapping, Optional, Set, Tuple

from comm import (
    TOPIC_BB_ANSWER,
    TOPIC_BB_REQUEST,
    TOPIC_CALL,
    TOPIC_CANCEL,
    TOPIC_EVENT,
    TOPIC_RESULT,
)
from comm.address import own_address_problem
from comm.addressing import PING_FUNCTION, cancel_on_call_topic
from comm.errors import ProtocolError
from comm.limits import check_depth
from comm.liveness import BLACKBOARD, DEFAULT_PERIOD, ModuleLost, NodeWatch, Watchdog
from comm.messages import (
    DEFAULT_MAX_BYTES,
    BlackboardAnswer,
    BlackboardRequest,
    CallStatus,
    CancelRequest,
    Event,
    FunctionCall,
    FunctionResult,
    new_id,
)
from comm.nodelife import registering
from coordinator.preflight import diff_definitions, wait_ready
from coordinator.rosliveness import GONE, Whereabouts, node_of, uri_of
from coordinator.rosstream import RosStreamSink
from coordinator.runevents import Notice
from coordinator.sender import TopicSender, peer_gone, topic_senders, widen_accept_queue
from coordinator.startguard import MasterGone, StartupGuard
from coordinator.transport import Screen, Transport
from modules.definition import ModuleDefinition
from modules.discovery import LiveModule, live_modules

__all__ = ["RosTransport", "RosStreamSink", "StartupGuard", "MasterGone", "diff_definitions", "address_problem",
           "SEND_QUEUE", "HOLD_LIMIT", "WATCH_PREFIX"]

log = logging.getLogger("bmtree.coordinator")

SEND_QUEUE = 10000  # messages queued per subscriber connection before the oldest is dropped
HOLD_LIMIT = 10.0  # s a call may wait for its module's node to connect (restarting) before it is given up
WATCH_PREFIX = "watch/"  # the watchdog's key of a module watched for a wait_event (never a call id)


def address_problem() -> str:
    """Why nodes may be unable to connect back to this process (empty when nothing is wrong): this
    process's advertised address does not resolve, is loopback while the master's is not, or is not
    an address of this machine (:func:`comm.address.own_address_problem`)."""
    return str(own_address_problem() or "")


class RosTransport(Transport):
    """Publishes calls/cancels/requests; decodes results/events/answers in rospy's threads."""

    def __init__(self, node_name: str = "bmtree", max_bytes: int = DEFAULT_MAX_BYTES,
                 liveness: float = DEFAULT_PERIOD, hold_limit: float = HOLD_LIMIT):
        self.node_name = node_name
        self.max_bytes = max_bytes
        self.hold_limit = hold_limit
        self._early: List[Any] = []  # events and notices that came during the preflight, for the run
        self._other_runs: Set[str] = set()  # nodes of other runs on this master, each noticed once
        self._deliver: Callable[[Any], None] = self._hold
        self._watch: Any = None  # the process's comm.masterwatch.MasterWatch, once open
        self._bb_watch: Optional[NodeWatch] = None  # the Blackboard node's process, while the run goes on
        #: where each module's node is, or was last seen: a node that stopped cleanly leaves no trace on the master
        self.whereabouts = Whereabouts(self._run_node)
        self.watchdog = Watchdog(self._from_watchdog, self.whereabouts.node_of, self.whereabouts.uri_of,
                                 period=liveness, restart_grace=hold_limit, registered=self.whereabouts.registered)
        self._pubs: Dict[str, Any] = {}
        self._subs: List[Any] = []
        self._String: Any = None
        self._answered: typing.OrderedDict[str, str] = OrderedDict()  # call_id -> node that answered
        #: node -> module of every module the run uses (announced, found by name, or --legacy):
        #: a result without call_id belongs to the module whose node published it
        self.node_modules: Dict[str, str] = {}
        self._routes: Dict[str, TopicSender] = {}  # module -> its own call topic
        self._holding = 0  # depth of hold()
        self._held: Dict[str, TopicSender] = {}  # topics with messages kept by hold()
        self._pings: Dict[str, str] = {}  # ping call_id -> module
        self._ponged: Set[str] = set()  # modules that answered a ping
        #: module -> what its last ping's answer said beside "alive" (busy with a call cancelled long ago)
        self.ping_notes: Dict[str, str] = {}
        self._cond = threading.Condition()
        self.screen = Screen()  # what arrives, checked against the definitions of the run's modules

    def open(self) -> None:
        """Init the rospy node (once per process) and the topics."""
        if self._subs:
            return
        import rospy
        from std_msgs.msg import String

        self._String = String
        with registering():  # a Ctrl-C now would leave registrations on the master for ever
            if not rospy.core.is_initialized():
                rospy.init_node(self.node_name, anonymous=True, disable_signals=True)
            widen_accept_queue()  # every module connects to this node at once in the preflight
            from comm.masterwatch import watch_master

            self._watch = watch_master()  # a restarted master gets this node's topics again; the run goes on
            self._watch.on_down.append(self._master_down)  # and the run log says when and why
            self._watch.on_restart.append(self._master_back)
            # the shared call and cancel topics only when a module needs them (_shared): every module
            # listens there, so each publisher costs one connection per module
            self._pubs = {"request": self._publisher(TOPIC_BB_REQUEST)}
            self._subs = [
                rospy.Subscriber(TOPIC_RESULT, String, self._on(FunctionResult, self._take_ping), queue_size=1000,
                                 tcp_nodelay=True),
                rospy.Subscriber(TOPIC_EVENT, String, self._on(Event), queue_size=1000, tcp_nodelay=True),
                rospy.Subscriber(TOPIC_BB_ANSWER, String, self._on(BlackboardAnswer), queue_size=100,
                                 tcp_nodelay=True),
            ]

    def _publisher(self, topic: str) -> Any:
        """Queued (non-blocking, see the module docstring), Nagle off: calls are small."""
        import rospy

        return rospy.Publisher(topic, self._String, queue_size=SEND_QUEUE, tcp_nodelay=True)

    def _on(self, cls: Any, intercept: Optional[Callable[[Any], bool]] = None) -> Callable[[Any], None]:
        """A subscriber's callback: results and events go through the screen (a malformed answer to a call
        awaited fails it, an event breaking its definition is refused: :class:`~coordinator.transport.Screen`)."""
        def callback(msg: Any) -> None:
            header = getattr(msg, "_connection_header", None) or {}
            node = header.get("callerid") if isinstance(header, dict) else None
            if cls is FunctionResult:
                items = self.screen.result(msg.data, self.max_bytes, node)
            elif cls is Event:
                items = self.screen.event(msg.data, self.max_bytes, node)
            else:
                try:
                    items = [cls.decode(msg.data, self.max_bytes)]
                except Exception as exc:  # nothing a sender writes may stop a subscriber
                    log.warning("ignored a malformed %s (%s: %s)", cls.__name__, type(exc).__name__, exc)
                    return
            for item in items:
                if intercept is not None and isinstance(item, cls) and intercept(item):
                    continue
                if isinstance(item, FunctionResult):
                    if item.call_id is None and item.basic_mod is None:
                        item.basic_mod = self.node_modules.get(item.publisher or "")
                    self.watchdog.call_done(item.call_id)
                    self._check_twice(item, header)
                elif isinstance(item, BlackboardAnswer):
                    self.watchdog.request_done(item.request_id)
                self._deliver(item)
        return callback

    def _check_twice(self, result: FunctionResult, header: Mapping[str, str]) -> None:
        """Report a call answered by two nodes: two nodes serve one module, every call runs twice."""
        node = header.get("callerid", "")
        if result.call_id is None or not node:
            return
        first = self._answered.setdefault(result.call_id, node)
        if first != node:
            log.error("call %s of %s.%s was answered by two nodes, %s and %s: two nodes serve module %r and run "
                      "every call twice; stop one of them", result.call_id, result.basic_mod, result.function,
                      first, node, result.basic_mod)
        while len(self._answered) > 10000:
            self._answered.popitem(last=False)

    def _take_ping(self, result: FunctionResult) -> bool:
        """A ping's answer (``rejected`` from a module too old to know pings) is consumed here."""
        if result.function != PING_FUNCTION:
            return False
        with self._cond:
            module = self._pings.get(result.call_id or "")
            if module is not None and module == result.basic_mod:
                self._ponged.add(module)
                if result.status == CallStatus.SUCCEEDED:
                    self.ping_notes[module] = result.error
                self._cond.notify_all()
        return True

    def _hold(self, item: Any) -> None:
        """Before the run connects: keep events (a module may announce something while the
        preflight runs) and notices, drop the rest (nothing was called yet)."""
        with self._cond:
            if isinstance(item, (Event, Notice)) and len(self._early) < 1000:
                self._early.append(item)

    def connect(self, deliver: Callable[[Any], None]) -> None:
        self.open()
        with self._cond:
            early, self._early = self._early, []
            self._deliver = deliver
        for item in early:
            if isinstance(item, Notice) and item.what in ("master_down", "master_back"):
                # it happened before the first tick: the run's clock would date it at 0.0 s
                item = Notice(item.what, "during start-up, before the first tick: " + item.text)
            for taken in self.screen.take_event(item) if isinstance(item, Event) else [item]:
                deliver(taken)  # (an event that came before the definitions were known is checked now)
        self.watchdog.start()
        if self._bb_watch is None:
            self._bb_watch = NodeWatch(lambda: node_of(BLACKBOARD), uri_of, self._blackboard_gone,
                                       self._blackboard_back, period=1.0).start()

    def _blackboard_gone(self, node: str, reason: str) -> None:
        self._deliver(Notice("blackboard_down", "the Blackboard node %s is gone: results from now on are not stored "
                                                "(%s)" % (node, reason)))

    def _blackboard_back(self, node: str) -> None:
        self._deliver(Notice("blackboard_back", "the Blackboard node %s is back: results from now on are stored "
                                                "again (those of the calls that ended meanwhile are not)" % node))

    def _route(self, module: str) -> Any:
        route = self._routes.get(module)
        return route if route is not None else self._shared("call")

    def _shared(self, which: str) -> Any:
        pub = self._pubs.get(which)
        if pub is None:
            with registering():
                pub = self._pubs[which] = self._publisher(TOPIC_CALL if which == "call" else TOPIC_CANCEL)
        return pub

    def topics_of(self, module: str) -> Tuple[str, str]:
        """Where calls and cancels for ``module`` go now."""
        route = self._routes.get(module)
        if route is not None:
            return route.resolved_name, route.resolved_name
        return self._shared("call").resolved_name, self._shared("cancel").resolved_name

    @contextlib.contextmanager
    def hold(self) -> Iterator[None]:
        """Calls and cancels to modules' own topics made inside leave at its end, one write per
        module (from the ticking thread only, as every send)."""
        self._holding += 1
        try:
            yield
        finally:
            self._holding -= 1
            if not self._holding:
                held, self._held = self._held, {}
                for route in held.values():
                    route.flush()

    def _to_route(self, route: TopicSender, text: str, key: Optional[str] = None) -> None:
        if not self._holding:
            route.publish(self._String(text), key=key)
        elif route.publish(self._String(text), hold=True, key=key):
            self._held[route.resolved_name] = route

    def send_call(self, call: FunctionCall) -> None:
        route = self._routes.get(call.basic_mod)
        if route is None:
            shared = self._shared("call")
            node = self._unconnected_node(call.basic_mod, shared)
            if node is not None:  # ROS would drop it, and the call would wait for nothing
                self._lost_now(call, node, "node %s is not connected to %s (gone, or restarting): the call was "
                                           "not sent" % (node, shared.resolved_name))
                return
        if call.call_id:
            self.watchdog.call_sent(call.call_id, call.basic_mod)
        self.screen.sent(call)
        if route is not None:  # kept while the module's node is not connected (restarting), sent when it is
            self._to_route(route, call.encode(), key=call.call_id)
        else:
            shared.publish(self._String(call.encode()))

    def _unconnected_node(self, module: str, shared: Any) -> Optional[str]:
        """The node the run knows for ``module`` (reached on the shared call topic) when none of its
        nodes is connected there, alive; None when one is, or when the run knows no node of it."""
        nodes = [node for node, m in list(self.node_modules.items()) if m == module]
        if not nodes:
            return None
        for conn in list(shared.impl.connections):  # a dead node's connection stays until a write fails
            sock = getattr(conn, "socket", None)
            if getattr(conn, "endpoint_id", None) in nodes and sock is not None and not conn.done \
                    and not peer_gone(sock):
                return None
        return nodes[0]

    def _lost_now(self, call: FunctionCall, node: str, reason: str) -> None:
        """End ``call`` as ``module_lost`` without sending it (delivered to the run like the watchdog's)."""
        log.warning("module %s (node %s): %s", call.basic_mod, node, reason)
        if call.call_id:
            self._deliver(ModuleLost(module=call.basic_mod, node=node, reason=reason, call_ids=[call.call_id]))

    def watch_module(self, module: str) -> str:
        """Watch ``module``'s node as if it owed an answer (a ``wait_event`` waits for its event) until
        :meth:`unwatch_module`: when that node is gone, a ``ModuleLost`` names the key returned here."""
        key = WATCH_PREFIX + new_id()
        self.watchdog.call_sent(key, module)
        return key

    def unwatch_module(self, key: str) -> None:
        self.watchdog.call_done(key)

    def send_cancel(self, cancel: CancelRequest) -> None:
        self.screen.ended([cancel.call_id])
        route = self._routes.get(cancel.basic_mod)
        if route is not None and cancel.call_id and route.discard(cancel.call_id):
            return  # its module never got the call
        if route is not None:
            self._to_route(route, cancel_on_call_topic(cancel.call_id, cancel.basic_mod, cancel.function))
        else:
            self._shared("cancel").publish(self._String(cancel.encode()))

    def send_request(self, request: BlackboardRequest) -> None:
        if request.request_id:
            self.watchdog.request_sent(request.request_id)
        self._pubs["request"].publish(self._String(request.encode()))

    def live(self, timeout: float = 1.0) -> Dict[str, LiveModule]:
        return live_modules(timeout=timeout)

    def wait_ready(self, modules: Iterable[str], timeout: float,
                   definitions: Optional[Mapping[str, ModuleDefinition]] = None, blackboard: bool = False,
                   legacy: Optional[Mapping[str, str]] = None,
                   notify: Optional[Callable[[str], None]] = None, where: Optional[Mapping[str, str]] = None) -> None:
        """Wait (bounded) until a first call to every module would be taken and answered.

        All modules at once (:mod:`coordinator.preflight`): one master query for the
        announcements, the publishers of their own call topics registered concurrently, then
        each announced module is pinged where its calls will go, as soon as both its call
        topic and its results are connected; the answer on ``/function/output`` proves both
        directions. An original module (not announced: a node ``/<module>`` listening on
        ``/master/output``) must be connected both ways to this node.

        ``legacy`` names the node of an original module (``{"DEMO_BM": "/some/node"}``) whose
        node is not called ``/<module>``. Original modules found are announced on their behalf
        (marked legacy), so ``bmtree modules --live`` and the Blackboard know their node; such
        an announcement is treated as an original module's (no ping) by later runs.

        ``notify`` is told once what is still missing when the wait goes on past
        :data:`~coordinator.preflight.NOTIFY_AFTER` seconds (a run started before its modules).
        ``where`` (module -> ``file:line:column`` of its first use) prefixes its problems.

        Raises:
            EnvironmentProblem: what is missing or different, after ``timeout`` seconds.
        """
        modules = set(modules)
        self.screen.know({m: d for m, d in (definitions or {}).items() if m in modules})
        wait_ready(self, modules, timeout, definitions, blackboard, legacy, notify, where)

    def _set_routes(self, lives: List[LiveModule]) -> None:
        """Publishers for the modules' own topics (once; all new ones registered with the
        master at once), or none for a module that has none."""
        fresh = []
        for live in lives:
            route = self._routes.get(live.name)
            if route is not None and route.resolved_name != live.call_topic:
                del self._routes[live.name]
                route.unregister()
                route = None
            if route is None and live.call_topic is not None:
                fresh.append(live)
        for live in lives:
            self.whereabouts.seen(live.name, live.node, live.uri)
        self.screen.know({live.name: live.definition for live in lives}, replace=False)
        with registering():
            senders = topic_senders([live.call_topic or "" for live in fresh], self._String, SEND_QUEUE,
                                    on_connect=self._connected)
        for live, sender in zip(fresh, senders):
            sender.give_up_after(self.hold_limit, lambda keys, module=live.name: self._gave_up(module, keys))
            self._routes[live.name] = sender

    def _run_node(self, module: str) -> Optional[str]:
        """The node the run found for ``module`` before it started (None if none)."""
        return next((node for node, m in list(self.node_modules.items()) if m == module), None)

    def _gone_text(self, module: str, node: str) -> str:
        """``node %s stopped (its process is gone) 3.2 s ago`` when the watchdog found it so, else ''."""
        since = self.watchdog.gone_since(module)
        return "" if since is None else self.whereabouts.explain(node, "node %s stopped %s %.1f s ago" % (node, GONE, since))

    def unsent_note(self, call_id: str) -> str:
        for module, route in list(self._routes.items()):
            if route.unsent(call_id):
                node = self.whereabouts.known(module) or "?"
                gone = self._gone_text(module, node)
                return "never sent: %s" % (gone + " and was not started again" if gone else
                                           "no node of %s is connected to %s (node %s restarting, or unable to reach "
                                           "this process?)" % (module, self.topics_of(module)[0], node))
        return ""

    def _gave_up(self, module: str, keys: List[str]) -> None:
        """Calls that waited :data:`HOLD_LIMIT` seconds for ``module``'s node to connect end as
        ``module_lost``, never sent (its node runs but did not connect, or none was found)."""
        ids = [key for key in keys if self.watchdog.owes(key)]
        for key in ids:
            self.watchdog.call_done(key)
        self.screen.ended(ids)
        if ids:
            node = self.whereabouts.known(module) or "?"
            gone = self._gone_text(module, node)
            reason = ("%s and was not started again within %gs: the call was never sent" % (gone, self.hold_limit)
                      if gone else "no node of it connected to %s within %gs (node %s: restarting, or unable to reach "
                      "this process?): the call was never sent" % (self.topics_of(module)[0], self.hold_limit, node))
            log.warning("module %s: %s", module, reason)
            self._deliver(ModuleLost(module=module, node=node, reason=reason, call_ids=ids))

    def _from_watchdog(self, item: Any) -> None:
        """A lost module's dead connection is closed before the run hears of it: a retry then waits
        for the restarted node instead of going into the old socket."""
        if isinstance(item, ModuleLost):
            item.reason = self.whereabouts.explain(item.node, item.reason)  # why it ended, when known (--sim)
            self.screen.ended(item.call_ids)
            route = self._routes.get(item.module)
            if route is not None:
                for call_id in item.call_ids:  # kept for a connection that will not come: never sent
                    route.discard(call_id)
                if route.drop_closed():
                    log.info("closed the call connection of module %s's dead node %s", item.module, item.node)
        self._deliver(item)

    def _connected(self, topic: str) -> None:
        """A module connected to its call topic: the preflight may ping it now, and the calls sent
        while it was not connected (its node restarting) and still owed an answer go to it."""
        for route in list(self._routes.values()):
            if route.resolved_name == topic:
                sent = route.connected(self.watchdog.owes)
                if sent:
                    log.info("%s connected: sent the %d call%s that waited for it", topic, sent,
                             "" if sent == 1 else "s")
        with self._cond:
            self._cond.notify_all()

    def stream_sink(self, namespace: str = "/bmtree/run") -> Any:
        """A run-stream sink that publishes each channel on ``namespace/<channel>`` (README, "Run stream").

        It also listens there for the tree records of other runs: a run started on this master
        while this one runs gets a notice (both store under the same Blackboard names)."""
        import rospy

        self.open()
        sink = RosStreamSink(namespace, self._String)
        with registering():
            self._subs.append(rospy.Subscriber("%s/tree" % namespace.rstrip("/"), self._String, self._other_run,
                                               queue_size=10))
        return sink

    def _other_run(self, msg: Any) -> None:
        """Another run's (latched) tree record: the first one of each node becomes a notice."""
        import rospy

        node = (getattr(msg, "_connection_header", None) or {}).get("callerid", "")
        if not node or node == rospy.get_name() or node in self._other_runs:
            return
        self._other_runs.add(node)
        tree = ""
        try:
            if len(msg.data) <= self.max_bytes:
                check_depth(msg.data)
                record = json.loads(msg.data)
                if isinstance(record, dict):
                    tree = str(record.get("path") or record.get("name") or "")
        except (ValueError, ProtocolError, RecursionError):
            pass
        self._deliver(Notice("other_run", "another bmtree run is running on this master (node %s%s): both store "
                                          "results under the same Blackboard names, so a recall may read its "
                                          "values, and bmtree control commands reach both"
                             % (node, ", tree %s" % tree if tree else "")))

    def _master_down(self) -> None:
        self._deliver(Notice("master_down", "the ROS master at %s does not answer: calls on open connections go on, "
                                            "but no node can find another until it is back" % self._watch.master_uri))

    def _master_back(self) -> None:
        self._deliver(Notice("master_back", "the ROS master at %s answers again; this run's topics are registered "
                                            "with it again (plain rospy/roscpp nodes, such as original modules and "
                                            "C++ modules not built with bmtree's library, do not register again: "
                                            "they are unknown to it until restarted)" % self._watch.master_uri))

    def close(self) -> None:
        watch = self._watch
        if watch is not None:
            for hooks, hook in ((watch.on_down, self._master_down), (watch.on_restart, self._master_back)):
                if hook in hooks:
                    hooks.remove(hook)
        self.watchdog.stop()
        if self._bb_watch is not None:
            self._bb_watch.stop()
            self._bb_watch = None
        for s in self._subs:
            s.unregister()
        for p in list(self._pubs.values()) + list(self._routes.values()):
            p.unregister()
        self._subs, self._pubs, self._routes = [], {}, {}
