"""``bmtree-bridge``: serves a C++ basic module (manual §4.3) as a bmtree module.

One process per C++ module. Towards the coordinator and the Blackboard it is a module
node like any other (:class:`modules.node.ModuleNode` with the runtime's validation,
busy rule, cancel answers and announcement); its functions are executed by the C++ node
over the original protocol: the inputs on the data topics ``/<BM>/<type>``, then
``/<BM>/BM_input``; the C++ node publishes the outputs on the data topics, then
``/<BM>/BM_output``. See the README's "C++ modules" for what it adds to the original.

    bmtree-bridge --definition gripper.json            # or python -m modules.bridge
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import threading
import time
from typing import Any, Dict, List, Optional, Tuple

from comm import sync_publisher
from comm.errors import ProtocolError
from comm.messages import DEFAULT_MAX_BYTES, MIN_MAX_BYTES, load_payload, new_id
from comm.nodeopts import count, node_name
from comm.saylimit import SayLimit
from modules.bridgegraph import CppNodeGraph
from modules.bridgeoutput import CppCall as _Call
from modules.bridgeoutput import CppOutputs
from modules.cppinfo import data_topic, data_topics, event_topic, signature_problems
from modules.definition import DefinitionError, FunctionDefinition, ModuleDefinition, load_definition
from modules.runtime import BasicModule, BindingError, Failure, ModuleServer, Rejected

__all__ = ["BridgeError", "CppBridge", "data_topic", "data_topics", "make_bridge", "make_parser", "main"]

log = logging.getLogger("bmtree.bridge")

#: Gap between the last input and ``BM_input`` for C++ nodes that are not built with bmtree's
#: library (they read the last value of each topic as soon as ``BM_input`` arrives, and ROS
#: orders messages per connection only). Measured on loopback: see the README.
DEFAULT_INPUT_GAP = 0.01
_POLL = 0.2  # how often a running call checks that the C++ node is still there (s)
#: after --call-timeout, how long the bridge waits for a node that takes cancels to answer the
#: cancel, to say what happened (a function that honours it answers within milliseconds)
_CANCEL_ANSWER = 0.5


class BridgeError(EnvironmentError):
    """The C++ node is not there or not connected (the message names what is missing)."""


class CppBridge(CppNodeGraph, CppOutputs, BasicModule):
    """Execution over the C++ protocol; one method per function is added by :func:`make_bridge`.

    Args:
        call_timeout: seconds a call may wait for ``BM_output`` (0: no limit; a crashed node
            is still noticed within ``_POLL`` seconds).
        input_gap: seconds between the last input and ``BM_input``; None = none for nodes
            built with bmtree's C++ library, :data:`DEFAULT_INPUT_GAP` for others.
        output_wait: seconds to wait, after ``BM_output``, for output values still in flight.
        connect_timeout: seconds to wait at start-up for the C++ node's connections.

    Finding the C++ node and noticing its death: :class:`modules.bridgegraph.CppNodeGraph`; taking
    its answers: :class:`modules.bridgeoutput.CppOutputs`.
    """

    def __init__(self, call_timeout: float = 30.0, input_gap: Optional[float] = None, output_wait: float = 1.0,
                 connect_timeout: float = 30.0, max_bytes: int = DEFAULT_MAX_BYTES):
        super().__init__()
        self.call_timeout = call_timeout
        self.input_gap = input_gap
        self.output_wait = output_wait
        self.connect_timeout = connect_timeout
        self.max_bytes = max_bytes
        self.cpp_node = ""
        self.cpp_uri = ""
        self.library = False
        self.cancellable = False  # the C++ node takes cancels (bmtree's library subscribes /<BM>/BM_cancel)
        self.emits = False  # the C++ node sends events (bmtree's library, API 3, publishes /<BM>/BM_event)
        self._cond = threading.Condition()
        self._call: Optional[_Call] = None
        self._ready = False
        self._pubs: Dict[str, Any] = {}
        self._subs: List[Any] = []
        self._in_pub: Any = None
        self._cancel_pub: Any = None
        self._out_sub: Any = None
        self._info_sub: Any = None
        self._event_sub: Any = None
        self._event_warnings = SayLimit()  # a refused event's reason, said at most every 10 s
        self._infos: Dict[str, Dict[str, Any]] = {}  # the latest BM_info of each node that sent one
        self._String: Any = None
        self._self_name = ""
        #: a call that timed out while the C++ node still ran it: (function, the node's URI, when its
        #: late BM_output came or 0.0). Until it answers, the node is busy: a new call would be given
        #: that answer.
        self._owed: Optional[Tuple[str, str, float]] = None
        self._owed_id = ""  # the call_id of the owed call (a library node echoes it in BM_output)
        self._checked = ""  # the C++ node whose BM_info was compared with the definition
        self._gone_said = ""  # the URI of a C++ node whose death is in the log already
        self._deaths: Dict[str, Tuple[float, str]] = {}  # URI of a C++ node gone -> (when, how: "died (…)")
        self._served = ""  # the URI of the C++ node last connected: its death is said, and refuses calls at once
        self._misnamed = ""  # no node serves the module, but one named as it serves another: what is there
        self._live = False  # the C++ node found is running (its missing connections are worth a wait)
        self._absent = ""  # what the last look for the C++ node found missing ("" once connected)
        self._finding = threading.Lock()  # held by whoever looks for the C++ node (a call, or the watch)
        self._say_lock = threading.Lock()
        self._watch_stop = threading.Event()
        self._watcher: Optional[threading.Thread] = None
        self._module_node: Any = None  # the module node serving this bridge (modules.node.ModuleNode)
        self._announced_not_ready = ""  # the announcement's "not_ready" as last set
        self._ping_warnings = SayLimit()  # a ping left unanswered: why, at most every 10 s

    # -- set-up ----------------------------------------------------------------------
    def setup(self, node: Any) -> None:
        """Create the C++ protocol's topics and wait (bounded) until the C++ node is connected."""
        import rospy
        from std_msgs.msg import String

        from comm.rostypes import resolve_type

        self._String = String
        self._self_name = rospy.get_name()
        if isinstance(getattr(node, "max_bytes", None), int):  # --max-bytes, or ~max_bytes (_max_bytes:=N)
            self.max_bytes = node.max_bytes  # BM_output, BM_info and BM_event are held to it too
        name = self.definition.name
        ins, outs = data_topics(self.definition)
        for topic, rostype in ins.items():
            self._pubs[topic] = sync_publisher(topic, resolve_type(rostype))
        for topic, rostype in outs.items():
            self._subs.append(rospy.Subscriber(topic, resolve_type(rostype), self._on_data, callback_args=topic,
                                               queue_size=1000, tcp_nodelay=True))
        self._in_pub = sync_publisher("/%s/BM_input" % name, String)
        self._cancel_pub = sync_publisher("/%s/BM_cancel" % name, String)
        self._out_sub = rospy.Subscriber("/%s/BM_output" % name, String, self._on_output, queue_size=100,
                                         tcp_nodelay=True)
        self._info_sub = rospy.Subscriber("/%s/BM_info" % name, String, self._on_info, queue_size=1)
        self._event_sub = rospy.Subscriber(event_topic(name), String, self._on_event, queue_size=1000,
                                           tcp_nodelay=True)
        self._module_node = node
        with self._finding:
            missing = self._wait_connected(self.connect_timeout, check=True)
        if missing:
            raise BridgeError("the C++ node of module %r is not ready after %gs: %s (the bridge waits --wait seconds "
                              "for it)" % (name, self.connect_timeout, "; ".join(missing)))
        self._check_signatures()
        self._check_events()
        self._watcher = threading.Thread(target=self._watch, name="bridge-watch", daemon=True)
        self._watcher.start()
        rospy.loginfo("bridge for %r: C++ node %s connected (%s)", name, self.cpp_node,
                      ("bmtree library, no input gap, %s%s" % ("takes cancels" if self.cancellable else "no cancels",
                                                               ", sends events" if self.emits else ""))
                      if self.library else "input gap %gs, no cancels" % self._gap())

    def not_ready(self, caller: Optional[str] = None) -> str:
        """A ping (``bmtree run``'s start-up check) is answered only while the C++ node can take a call. The
        module node answers pings itself, and the ping never reaches the C++ node: answered for a dead one,
        the run started, and its first call was refused. Unanswered, the run waits (``--wait``) as for a
        module not started yet; why is in the bridge's log (at most every 10 s for one reason) and in its
        announcement (``not_ready``, :meth:`_announce_readiness`). Never raises."""
        try:
            reason = self._not_ready()
        except Exception:  # a bug here must not keep a run from starting: the ping goes its usual way
            log.exception("could not tell whether the C++ node of module %r is ready", self.definition.name)
            return ""
        if reason:
            more = self._ping_warnings.due(reason)
            if more is not None:
                log.warning("not answering the ping of %s (a run's start-up check): module %r cannot take a call "
                            "now: %s%s", caller or "a caller", self.definition.name, reason, more)
        return reason

    def _check_events(self) -> None:
        """At start: a definition with Events whose C++ node cannot send them is said in the log."""
        events = ", ".join(self.definition.events)
        if not events or self.emits:
            return
        if self.library:
            log.warning("%s lists events (%s), but the C++ node %s does not publish %s (built with a bmtree C++ "
                        "library older than BMTREE_CPP_API 3?): rebuild it, or its events never come",
                        self.definition.source or self.definition.name, events, self.cpp_node,
                        event_topic(self.definition.name))
        else:
            log.warning("%s lists events (%s), but the C++ node %s is not built with bmtree's C++ library, and the "
                        "original C++ protocol has no events: they never come", self.definition.source or
                        self.definition.name, events, self.cpp_node)

    def shutdown(self) -> None:
        self._watch_stop.set()
        for s in self._subs + [self._out_sub, self._info_sub, self._event_sub]:
            if s is not None:
                s.unregister()

    @property
    def call_limit(self) -> Optional[float]:
        """Announced: a coordinator warns of a call that would wait longer than the bridge does."""
        return self.call_timeout or None

    def _gap(self) -> float:
        if self.input_gap is not None:
            return self.input_gap
        return 0.0 if self.library else DEFAULT_INPUT_GAP

    # -- what the C++ node provides (BM_info of bmtree's library) ----------------------
    def _on_info(self, msg: Any) -> None:
        try:
            info = load_payload(msg.data, self.max_bytes)
        except ProtocolError as exc:
            log.warning("ignored a malformed BM_info from %s: %s", msg._connection_header.get("callerid"), exc)
            return
        with self._cond:
            self._infos[str(msg._connection_header.get("callerid"))] = info
            self._cond.notify_all()

    def _signature_problem(self, fn: FunctionDefinition, info: Dict[str, Any]) -> str:
        return "; ".join(signature_problems(fn, self.definition.name, info, self.cpp_node))

    def _check_signatures(self, wait: float = 2.0) -> None:
        """At start: the definition's functions must be the C++ node's, with the same inputs and
        outputs (BindingError naming every difference); skipped for nodes without bmtree's library."""
        if not self.library or self._checked == self.cpp_node:
            return
        end = time.monotonic() + wait
        with self._cond:
            while self.cpp_node not in self._infos and time.monotonic() < end:
                self._cond.wait(end - time.monotonic())
            info = self._infos.get(self.cpp_node)
        if info is None:
            log.warning("no BM_info from %s within %gs: its functions are not checked against %s", self.cpp_node,
                        wait, self.definition.source or self.definition.name)
            return
        problems = [p for fn in self.definition.functions.values()
                    for p in signature_problems(fn, self.definition.name, info, self.cpp_node)]
        if problems:
            raise BindingError("%s does not match the C++ node: %s" % (
                self.definition.source or self.definition.name, "; ".join(problems)))
        self._checked = self.cpp_node
        extra = sorted(set(f for f in info.get("functions") or [] if isinstance(f, str)) - set(self.definition.functions))
        if extra:
            log.warning("the C++ node %s also provides %s, which %s does not list (not callable through the bridge)",
                        self.cpp_node, ", ".join(extra), self.definition.source or self.definition.name)

    # -- a call ----------------------------------------------------------------------
    def _execute(self, name: str, inputs: Dict[str, Any]) -> Dict[str, Any]:
        fn = self.definition.function(name)
        if not self._ready or not self._out_sub.impl.has_connection(self.cpp_uri) or self._said_gone():
            # first call after a failure, or the C++ node died or was restarted (new URI): find it again. Only a
            # live node still connecting is waited for: a dead one refuses the call at once (no code runs)
            self._ready = False
            ctx = getattr(self._local, "ctx", None)
            with self._finding:
                missing = self._wait_connected(min(2.0, self.connect_timeout),
                                               cancelled=ctx.cancelled.is_set if ctx is not None else lambda: False)
            if missing:
                raise Rejected(self._misnamed or self._down() or "the C++ node of module %r is not connected: %s" % (
                    self.definition.name, "; ".join(missing)))
        self._settle_owed()
        with self._cond:
            info = self._infos.get(self.cpp_node) if self.library else None
        problem = self._signature_problem(fn, info) if info is not None else ""
        if problem:  # the C++ node was rebuilt and restarted since the bridge started
            raise Rejected(problem)
        module = self.definition.name
        in_topics = [data_topic(module, p.rostype) for p in fn.inputs]
        call = _Call(fn, sorted({data_topic(module, p.rostype) for p in fn.outputs}))
        call.call_id = self.context.call_id or new_id()
        with self._cond:
            self._call = call
        try:
            for p, topic in zip(fn.inputs, in_topics):
                self._pubs[topic].publish(inputs[p.name])
            gap = self._gap()
            if gap > 0:
                time.sleep(gap)
            sync: Dict[str, Any] = {"function": name, "inparam_topics": in_topics}
            if self.library:  # the original C++ utility knows no call ids; the library names late inputs
                sync["call_id"] = call.call_id
                sync["inparam_names"] = [p.name for p in fn.inputs]
            self._in_pub.publish(self._String(json.dumps(sync)))
            if self.cancellable:  # a halted tree stops the C++ function (it answers "cancelled")
                self.context.on_cancel(lambda: self._send_cancel(call))
            self._wait_output(call)
        finally:
            with self._cond:
                self._call = None
        return self._outputs(call)

    def _wait_output(self, call: _Call) -> None:
        start = pinged = time.monotonic()
        while True:
            with self._cond:
                now = time.monotonic()
                if call.output is not None:
                    lacking = self._lacking(call)
                    if not lacking:
                        return
                    if now - call.output_at >= self.output_wait:
                        raise Failure("BM_output of %s listed %s, but %s within %gs" % (
                            call.fn.qualified, ", ".join(call.output.get("outparam_topics") or []),
                            "; ".join(lacking), self.output_wait))
                    self._cond.wait(self.output_wait - (now - call.output_at))
                    continue
                timed_out = bool(self.call_timeout) and now - start >= self.call_timeout
                if not timed_out:
                    left = self.call_timeout - (now - start) if self.call_timeout else _POLL
                    self._cond.wait(min(_POLL, left))
                    if call.output is not None or time.monotonic() - pinged < _POLL:
                        continue
            if timed_out:
                raise Failure(self._give_up(call))
            pinged = time.monotonic()
            if self._gone():
                self._ready = False
                self._say_gone()
                death = self._deaths.get(self.cpp_uri)
                raise Failure("the C++ node %s exited during the call (no BM_output)%s" % (
                    self.cpp_node, ": %s; start it again" % self._death_note(death) if death else ""))

    def _give_up(self, call: _Call) -> str:
        """After ``--call-timeout``: cancel the call on the C++ node and say what happened (the
        node stopped, answered too late, did not answer the cancel, or cannot take cancels)."""
        self._ready = False
        said = "no BM_output from the C++ node %s within %gs (the bridge's --call-timeout): %s exceeded the call " \
               "timeout" % (self.cpp_node, self.call_timeout, call.fn.qualified)
        if not self.cancellable:
            self._owe(call)
            return ("%s; the C++ node takes no cancels (it is not built with bmtree's library), so it may still run "
                    "the call: the module is busy until its BM_output comes or the node is restarted" % said)
        self._send_cancel(call)
        cancelled_at = time.monotonic()
        end = cancelled_at + _CANCEL_ANSWER
        with self._cond:
            while call.output is None and time.monotonic() < end:
                self._cond.wait(end - time.monotonic())
            out = call.output
            if out is None:
                self._owe(call)
        if out is None:
            if self._gone():
                self._say_gone()
                return "%s and was cancelled; then the C++ node exited" % said
            return ("%s and was cancelled, but the C++ node did not answer within %gs of the cancel (its function "
                    "does not look at cancelled()?): the module is busy until it answers or the node is restarted"
                    % (said, _CANCEL_ANSWER))
        after = max(0.0, call.output_at - cancelled_at)
        with self._cond:
            if self._lacking(call):  # its output values are still on their way: the next call waits for them
                self._owed = (call.fn.qualified, self.cpp_uri, call.output_at)
                self._owed_id = call.call_id
        if out.get("status") == "cancelled":
            return "%s and was cancelled; the function stopped %.2fs after the cancel" % (said, after)
        return "%s and was cancelled; the C++ node answered %s %.2fs after the cancel, too late" % (
            said, out.get("status") or "succeeded", after)

    def _owe(self, call: _Call) -> None:
        """``call`` was given up on while the C++ node still runs it: the node is busy until it answers."""
        with self._cond:
            self._owed = (call.fn.qualified, self.cpp_uri, 0.0)
            self._owed_id = call.call_id
            self._call = None  # its late BM_output is the owed one, not a call's

    def _send_cancel(self, call: _Call) -> None:
        """Tell the C++ node to stop ``call`` (if it takes cancels; never raises)."""
        if not self.cancellable or call.cancel_sent:
            return
        call.cancel_sent = True
        try:
            self._cancel_pub.publish(self._String(json.dumps({"call_id": call.call_id, "function": call.fn.name})))
        except Exception as exc:  # shutting down, or the topic is gone
            log.warning("could not send the cancel of %s to %s: %s", call.fn.qualified, self.cpp_node, exc)

    def _settle_owed(self) -> None:
        """Before a call: refuse it while the C++ node still runs a call that timed out (its
        BM_output would be taken for this call's), unless that node is gone or was restarted; once
        the late BM_output came, wait ``output_wait`` for its output values, then forget them."""
        with self._cond:
            owed = self._owed
        if owed is None:
            return
        function, uri, answered = owed
        if uri != self.cpp_uri or self._gone():
            self._owed = None
            return
        if not answered:
            raise Rejected("busy: the C++ node %s still runs %s, which got no BM_output within %gs (the bridge's "
                           "--call-timeout); it takes calls again when it answers or is restarted" % (
                               self.cpp_node, function, self.call_timeout))
        left = answered + self.output_wait - time.monotonic()
        if left > 0:
            time.sleep(left)
        self._owed = None

def _method(name: str) -> Any:
    def call(self: CppBridge, **inputs: Any) -> Dict[str, Any]:
        return self._execute(name, inputs)

    call.__name__ = name
    call.__doc__ = "Run %s on the C++ node." % name
    return call


def make_bridge(definition: ModuleDefinition, **options: Any) -> CppBridge:
    """A bridge object with one method per function of ``definition`` (what the runtime binds)."""
    data_topics(definition)
    concurrent = sorted(f.name for f in definition.functions.values() if f.concurrent)
    if concurrent:  # one BM_input/BM_output pair: the node answers one call after another
        raise BindingError("%s: a C++ module runs one function at a time (the C++ protocol has one BM_input and "
                           "one BM_output), so its functions cannot be Concurrent: remove \"Concurrent\": true from "
                           "%s" % (definition.source or definition.name, ", ".join(concurrent)))
    cls = type("CppBridge_%s" % definition.name, (CppBridge,), {n: _method(n) for n in definition.functions})
    return cls(**options)


def make_parser() -> argparse.ArgumentParser:
    from coordinator.cliutil import path_arg, seconds  # the type= of every command's options
    from modules.callers import unreachable_seconds

    p = argparse.ArgumentParser(prog="bmtree-bridge", description="Serve a C++ basic module (manual §4.3) as a "
                                "bmtree module: wire protocol v2 outside, the original C++ protocol inside.")
    p.add_argument("--definition", required=True, type=path_arg("the C++ module's definition"),
                   help="the C++ module's definition JSON")
    p.add_argument("--node-name", type=node_name, help="ROS node name of the bridge (default <module>_bridge)")
    p.add_argument("--call-timeout", type=seconds("no limit"), default=30.0,
                   help="seconds a call may wait for the C++ node's BM_output, 0 = no limit (default 30)")
    p.add_argument("--input-gap", type=seconds("none"), default=None,
                   help="seconds between the last input and BM_input (default: 0 for nodes built with bmtree's "
                        "C++ library, %g for others)" % DEFAULT_INPUT_GAP)
    p.add_argument("--output-wait", type=seconds("do not wait"), default=1.0,
                   help="seconds to wait after BM_output for output values still in flight (default 1)")
    p.add_argument("--wait", type=seconds("do not wait"), default=30.0,
                   help="seconds to wait at start-up for the C++ node's connections (default 30)")
    p.add_argument("--max-bytes", type=count(MIN_MAX_BYTES, what="a ping's answer must fit"), default=None,
                   help="largest payload accepted, from the coordinator and from the C++ node (bytes; default %d, or "
                        "~max_bytes)" % DEFAULT_MAX_BYTES)
    p.add_argument("--unreachable-caller", type=unreachable_seconds, default=None, metavar="SECONDS",
                   help="cancel the calls of a caller that has not answered for this long (the C++ node gets the "
                        "cancel): its machine cannot be reached or its process is stopped (default 0: never; or "
                        "~unreachable_caller)")
    return p


def main(argv: Optional[List[str]] = None) -> int:
    import rospy

    from modules.node import run_module

    try:
        args = make_parser().parse_args(rospy.myargv(argv if argv is not None else sys.argv)[1:])
    except SystemExit as exc:  # argparse said what is wrong (or printed --help)
        return 2 if exc.code else 0
    try:
        definition = load_definition(args.definition)
        impl = make_bridge(definition, call_timeout=args.call_timeout, input_gap=args.input_gap,
                           output_wait=args.output_wait, connect_timeout=args.wait,
                           max_bytes=args.max_bytes or DEFAULT_MAX_BYTES)
        ModuleServer(definition, impl, lambda t: None, lambda t: None)
    except DefinitionError as exc:
        sys.stderr.write("%s\n" % exc)
        return 2
    except BindingError as exc:
        sys.stderr.write("error: %s\n" % exc)
        return 2
    return run_module(definition, impl, args.node_name, {BridgeError: 3}, name_format="%s_bridge",
                      max_bytes=args.max_bytes, unreachable_caller=args.unreachable_caller)


if __name__ == "__main__":
    sys.exit(main())
