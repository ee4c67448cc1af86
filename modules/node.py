"""A basic module as a ROS node: the runtime bound to the wire topics.

Run one from the command line::

    bmtree-module --definition my_module.json --class my_package.my_module:MyModule

or ``python -m modules.node ...``. ROS remappings and private parameters work as
usual (``_definition:=``, ``_class:=``, ``_max_bytes:=`` and roslaunch ``<param>`` stand for the
options); ``_basic_mod:=other_name`` renames the module as the original modules did (and its
node, ``bm_other_name``, unless ``--node-name`` or ``__name:=`` names it).
"""
from __future__ import annotations

import argparse
import logging
import os
import signal
import socket
import sys
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

from comm import TOPIC_CALL, TOPIC_CANCEL, TOPIC_EVENT, TOPIC_RESULT, sync_publisher
from comm.address import warn_own_address
from comm.addressing import PING_FUNCTION, RecentIds, call_topic, cancel_topic, surely_not_for
from comm.errors import ProtocolError
from comm.masterwatch import watch_master
from comm.messages import DEFAULT_MAX_BYTES, MIN_MAX_BYTES, FunctionResult, load_payload, new_id
from comm.nodelife import StopSignals
from comm.nodeopts import count, node_name, node_params, parse_node_args
from comm.replies import ReplyPublisher, caller_of
from comm.roslog import log_to_rosout
from comm.rpc import master_api
from comm.startup import patiently
from modules.callers import CallerWatch, unreachable_seconds
from modules.classfile import load_class, where_raised
from modules.definition import DefinitionError, ModuleDefinition, load_definition
from modules.discovery import PARAM_ROOT, announcement, node_alive
from modules.errortext import raised_text, said
from modules.nodestop import stop_with_node
from modules.runtime import BasicModule, BindingError, ModuleServer

__all__ = ["CallInbox", "ModuleNode", "DuplicateModule", "make_parser", "main", "renamed_by_argument",
           "run_module", "serving_line"]

log = logging.getLogger("bmtree.module")

class CallInbox:
    """How any bmtree module node takes calls and cancels, before running them.

    It subscribes to the shared topics (``/master/output``, ``/master/cancel``: the
    original protocol, for coordinators that do not address calls) and to the module's
    own (``/bmtree/call/<module>``, ``/bmtree/cancel/<module>``), and hands ``on_call``
    and ``on_cancel`` the payload text of what is meant for this module: a call for
    another module is skipped without parsing (:func:`comm.addressing.surely_not_for`),
    a ``call_id`` that came already (on the other topic) is skipped, a cancel marked
    ``"cancel": true`` on a call topic goes to ``on_cancel``, and a preflight ping is
    answered here through ``publish_result``. :meth:`topics` gives the keys
    the announcement adds. The Python module node and the C++ bridge both use it.
    """

    def __init__(self, module: str, on_call: Callable[[str], None], on_cancel: Callable[[str], None],
                 publish_result: Callable[[str], None], max_bytes: int = DEFAULT_MAX_BYTES, remember: int = 4096,
                 on_parsed: Optional[Callable[[Dict[str, Any], Optional[str]], None]] = None,
                 heard: Optional[Callable[[Optional[str]], None]] = None,
                 ping_note: Optional[Callable[[], str]] = None,
                 not_ready: Optional[Callable[[Optional[str]], str]] = None):
        self.module = module
        self.heard = heard  # told the node each call came from (its answer waits for that node's connection)
        self.on_call = on_call
        self.on_parsed = on_parsed  # takes the parsed payload instead of on_call: parsed once, not twice
        self.on_cancel = on_cancel
        self.publish_result = publish_result
        self.ping_note = ping_note  # what a ping's answer tells beside "alive" (a stuck call holding the module)
        self.not_ready = not_ready  # why a ping is left unanswered now ('' answers it): the module's own hook
        self.max_bytes = max_bytes
        self.skipped = 0  # calls for other modules, refused without parsing
        self.duplicates = 0
        self._seen = RecentIds(remember)
        self._subs: List[Any] = []

    def handle_call(self, text: Any, caller: Optional[str] = None) -> None:
        """One payload from either call topic, sent by node ``caller``; never raises."""
        try:
            if surely_not_for(text, self.module):
                self.skipped += 1
                return
            try:
                head = load_payload(text, self.max_bytes)
            except ProtocolError:
                self.on_call(text)  # malformed: the runtime reports it
                return
            if head.get("basic_mod") != self.module:
                return
            if head.get("cancel") is True:  # a cancel sent on the call topic, after its call
                self.on_cancel(text)
                return
            call_id = head.get("call_id") if isinstance(head.get("call_id"), str) else None
            if head.get("function") == PING_FUNCTION:
                if call_id is not None and not (self.not_ready is not None and self.not_ready(caller)):
                    note = self.ping_note() if self.ping_note is not None else ""
                    self.publish_result(FunctionResult(call_id=call_id, basic_mod=self.module,
                                                       function=PING_FUNCTION, error=note).encode())
                return
            if not self._seen.first(call_id):
                self.duplicates += 1
                log.debug("call %s of %s came twice; ran once", call_id, self.module)
                return
            if self.on_parsed is not None:
                self.on_parsed(head, caller)
            else:
                self.on_call(text)
        except Exception:
            log.exception("unexpected error while taking a call")

    def handle_cancel(self, text: Any) -> None:
        """One payload from either cancel topic; never raises."""
        try:
            if surely_not_for(text, self.module):
                return
            self.on_cancel(text)
        except Exception:
            log.exception("unexpected error while taking a cancel")

    def subscribe(self) -> None:
        """Subscribe to the four topics (after ``rospy.init_node``)."""
        import rospy
        from std_msgs.msg import String

        def sub(topic: str, handler: Callable[[Any], None], size: int) -> Any:
            return rospy.Subscriber(topic, String, lambda m: handler(m.data), queue_size=size, tcp_nodelay=True)

        def take_call(msg: Any) -> None:
            caller = caller_of(msg)
            if self.heard is not None:
                self.heard(caller)
            self.handle_call(msg.data, caller)

        def sub_calls(topic: str) -> Any:
            return rospy.Subscriber(topic, String, take_call, queue_size=10000, tcp_nodelay=True)

        # rospy drops the oldest queued message past queue_size: a burst of calls for other
        # modules (or garbage) must not push out a good call, so the queues are deep
        self._subs = [sub_calls(TOPIC_CALL), sub_calls(call_topic(self.module)),
                      sub(TOPIC_CANCEL, self.handle_cancel, 10000),
                      sub(cancel_topic(self.module), self.handle_cancel, 10000)]

    def topics(self) -> Dict[str, str]:
        """The announcement's ``call_topic`` and ``cancel_topic`` (as resolved, remappings applied)."""
        import rospy

        return {"call_topic": rospy.resolve_name(call_topic(self.module)),
                "cancel_topic": rospy.resolve_name(cancel_topic(self.module))}

    def close(self) -> None:
        for s in self._subs:
            s.unregister()
        self._subs = []


class ModuleNode:
    """Wires a :class:`ModuleServer` to ROS; call :meth:`start` after ``rospy.init_node``."""

    def __init__(self, definition: ModuleDefinition, impl: BasicModule, max_bytes: Optional[int] = None,
                 unreachable_caller: Optional[float] = None):
        self.definition = definition
        self.impl = impl
        self.max_bytes = max_bytes  # None: the private parameter ~max_bytes, else 1 MiB
        #: seconds after which the calls of a caller that does not answer are cancelled (0: never); None:
        #: the private parameter ~unreachable_caller, else 0
        self.unreachable_caller = unreachable_caller
        self.server: Optional[ModuleServer] = None
        self.inbox: Optional[CallInbox] = None
        self.callers: Optional[CallerWatch] = None
        #: what the class's ``setup()`` may raise to say a start-up problem itself (run_module's exit codes);
        #: anything else it raises is the author's bug, said as a BindingError
        self.start_failures: Tuple[type, ...] = (BindingError, DuplicateModule)
        self.event_publisher: Any = None
        self._param = ""
        self.instance = "%s:%d:%s" % (socket.gethostname(), os.getpid(), new_id()[:8])
        self.kicked_out = ""  # why the master stopped this node (another node took its name)

    def _taken_by(self) -> str:
        """The other live node that already serves this module, if any (asked again while the
        master does not answer)."""
        import rosgraph
        import rospy

        entry = patiently(lambda: rospy.get_param(self._param, None))
        if not isinstance(entry, dict) or not isinstance(entry.get("node"), str) or entry["node"] == rospy.get_name():
            return ""
        try:
            uri = patiently(lambda: master_api(rospy.get_name()).lookupNode(entry["node"]))
        except rosgraph.masterapi.Error:  # its node is not registered
            return ""
        return entry["node"] if node_alive(uri, 1.0) else ""

    def _on_shutdown(self, reason: str) -> None:
        import rospy

        if "new node registered with same name" in reason:
            self.kicked_out = reason
            sys.stderr.write("error: another node registered with this node's name %s, so the master stopped "
                             "this one, which served module %r (give each module node its own name: "
                             "--node-name or __name:=)\n" % (rospy.get_name(), self.definition.name))

    def start(self) -> None:
        import rospy
        from std_msgs.msg import String

        name = patiently(lambda: rospy.get_param("~basic_mod", self.definition.name))
        if self.max_bytes is None:
            value = patiently(lambda: rospy.get_param("~max_bytes", DEFAULT_MAX_BYTES))
            if isinstance(value, bool) or not isinstance(value, int) or value < MIN_MAX_BYTES:
                raise BindingError("parameter ~max_bytes must be a whole number of at least %d, got %.80r" % (
                    MIN_MAX_BYTES, value))
            self.max_bytes = value
        if self.unreachable_caller is None:
            value = patiently(lambda: rospy.get_param("~unreachable_caller", 0))
            try:
                self.unreachable_caller = unreachable_seconds(value)
            except argparse.ArgumentTypeError as exc:
                raise BindingError("parameter ~unreachable_caller: %s" % exc)
        if name != self.definition.name:
            try:
                self.definition = self.definition.renamed(name)
            except (DefinitionError, TypeError) as exc:
                raise BindingError("parameter ~basic_mod must be a module name, got %r (%s)" % (name, exc))
        self._param = "%s/%s" % (PARAM_ROOT, self.definition.name)
        other = self._taken_by()
        if other:
            raise DuplicateModule("module %r is already served by the running node %s: two nodes answering one "
                                  "module would run every call twice (stop it, or rename this one with "
                                  "_basic_mod:=NAME)" % (self.definition.name, other))
        rospy.core.add_preshutdown_hook(self._on_shutdown)
        # from the call's worker thread; an answer waits for its caller's connection (a node restarted
        # mid-run gets its first call before the coordinator has connected to its results)
        res_pub = ReplyPublisher(sync_publisher(TOPIC_RESULT, String))
        ev_pub = rospy.Publisher(TOPIC_EVENT, String, queue_size=1000)
        self.event_publisher = ev_pub  # for setup(): who listens to this module's events
        faults = _faults(self.definition, patiently(lambda: rospy.get_param("~faults", None)))
        self.server = ModuleServer(self.definition, self.impl,
                                   publish_result=lambda text: res_pub.publish(String(text)),
                                   publish_event=lambda text: ev_pub.publish(String(text)),
                                   max_bytes=self.max_bytes)
        self.server.faults = faults
        self.server.on_death = _die
        stop_with_node(self.server)  # a stop cancels and answers its calls in flight, before the topics close
        self.inbox = CallInbox(self.definition.name, self.server.handle_call, self.server.handle_cancel,
                               lambda text: res_pub.publish(String(text)), self.max_bytes,
                               on_parsed=self.server.handle_parsed, heard=res_pub.heard,
                               ping_note=self.server.stuck_note, not_ready=self.impl.not_ready)
        self.callers = CallerWatch(self.server, self.definition.name, self.unreachable_caller).start()
        self.inbox.subscribe()
        try:
            self.impl.setup(self)
        except self.start_failures:   # said as they are (the bridge's C++ node missing: exit 3)
            raise
        except BaseException as exc:  # noqa: B036 - SystemExit too: one line, exit 2, not a traceback
            raise BindingError("%s.setup raised %s" % (type(self.impl).__name__, raised_text(exc)))
        ann = announcement(rospy.get_name(), self.definition, self.instance, self.inbox.topics(),
                           rospy.get_node_uri(), getattr(self.impl, "call_limit", None))
        patiently(lambda: rospy.set_param(self._param, ann))
        watch_master().keep_param(self._param, lambda: None if self.kicked_out else ann)
        rospy.loginfo("basic module %r %s%s", self.definition.name, serving_line(self.definition),
                      "; cancels the calls of a caller that has not answered for %g s (unreachable_caller)"
                      % self.unreachable_caller if self.unreachable_caller else "")
        injected = _injected(self.definition.name, self.impl, faults)
        if injected:
            log.info("%s", injected)

    def stop(self) -> None:
        self.unregister()
        _shut_down(self.impl)

    def unregister(self) -> None:
        """Leave the graph: the topics and this node's announcement (asks the master)."""
        import rospy

        if self.callers is not None:
            self.callers.stop()
        if self.inbox is not None:
            self.inbox.close()
        try:
            entry = rospy.get_param(self._param, {}) if self._param and not self.kicked_out else {}
            if isinstance(entry, dict) and entry.get("instance") == self.instance:
                rospy.delete_param(self._param)
        except Exception:  # the master may be gone already
            pass


def _shut_down(impl: BasicModule) -> None:
    """The author's ``shutdown()`` hook; what it raises is one line in the log, not a traceback that
    hides the node's own last lines (nor another exit code)."""
    try:
        impl.shutdown()
    except BaseException as exc:  # noqa: B036
        log.error("%s.shutdown raised %s", type(impl).__name__, raised_text(exc))


#: seconds a stopped module node waits for the threads its code started and did not make daemons
THREADS_GRACE = 2.0


def _leave_without_threads(code: int, grace: float = THREADS_GRACE) -> None:
    """Exit with ``code`` once the module's own non-daemon threads have ended, or after ``grace`` seconds
    without them: a thread that loops for ever (emitting events, polling a driver) held a stopped node
    alive, and Ctrl-C, ``rosnode kill`` and roslaunch waited on it until they killed it."""
    end = time.monotonic() + grace
    left = []
    for t in threading.enumerate():
        if t is threading.current_thread() or t.daemon:
            continue
        t.join(max(0.0, end - time.monotonic()))
        if t.is_alive():
            left.append(t.name)
    if not left:
        return
    sys.stderr.write("warning: the module's thread%s %s still ran %gs after the node stopped; left without %s "
                     "(start %s with daemon=True, or end %s in shutdown())\n" % (
                         "s" if len(left) > 1 else "", ", ".join(repr(n) for n in left), grace,
                         "them" if len(left) > 1 else "it", "them" if len(left) > 1 else "it",
                         "them" if len(left) > 1 else "it"))
    sys.stderr.flush()
    sys.stdout.flush()
    logging.shutdown()
    os._exit(code)


def _die(call_ids: List[str], reason: str) -> None:
    """A ``die`` fault: the process ends as a crash does (SIGKILL: no clean unregistering), so the run
    meets a module that died mid-call as on the robot."""
    log.error("the node dies (an injected fault) with %d call(s) in flight: %s", len(call_ids), reason)
    logging.shutdown()
    os.kill(os.getpid(), signal.SIGKILL)


def _faults(definition: ModuleDefinition, raw: Any) -> Dict[str, Any]:
    """Injected faults by function (``~faults``: ``{function: {fail: reason, times: n}, …}``, as a
    world writes them), checked like a world's."""
    if raw is None or raw == "":
        return {}
    from coordinator.errors import TreeErrors
    from coordinator.yamlsrc import load_value
    from modules.sim.world import Fault, WorldError

    if isinstance(raw, str):  # a launch file's <param value="..."/>: bounded as a world file is
        try:
            raw = load_value(raw, "~faults")
        except TreeErrors as exc:
            raise BindingError("parameter ~faults is not valid YAML: %s" % exc.errors[0])
    if not isinstance(raw, dict):
        raise BindingError("parameter ~faults must be a mapping of function -> fault, got %.80r" % (raw,))
    out = {}
    for fn, spec in raw.items():
        if not isinstance(fn, str) or fn not in definition.functions:
            raise BindingError("parameter ~faults: module %r has no function %r" % (definition.name, fn))
        try:
            out[fn] = Fault.parse("%s.%s" % (definition.name, fn), spec)
        except WorldError as exc:
            raise BindingError("parameter ~faults: %s" % exc)
    return out


def _injected(module: str, impl: BasicModule, faults: Dict[str, Any]) -> str:
    """The start-up line naming the faults this node injects: its ``~faults`` and, for a simulated
    module, its world's (``faults injected: navigation.go_to: fail 'blocked' ×1``), "" for none."""
    from modules.sim.world import Fault, describe_faults

    own = getattr(impl, "faults", None)  # a simulated module's faults of its world (SimModule.before_call)
    every = {fn: f for fn, f in own.items() if isinstance(f, Fault)} if isinstance(own, dict) else {}
    every.update(faults)  # ~faults answer first
    return describe_faults(module, every)


class DuplicateModule(Exception):
    """Another live node already serves this module."""


def serving_line(definition: ModuleDefinition) -> str:
    """What a started node serves, for its start-up line: ``serving go_to, approach; events: arrived``.
    An events-only module (``"Functions": []``, a topic turned into events: SMACH's MonitorState) says
    ``serving no functions; events: heard``, not a bare ``serving`` that reads as if its functions
    were lost."""
    functions = ", ".join(definition.functions) or "no functions"
    events = ", ".join(definition.events)
    if events:
        return "serving %s; events: %s" % (functions, events)
    return "serving %s%s" % (functions, " and no events" if not definition.functions else "")


def renamed_by_argument(definition: ModuleDefinition, argv: Optional[List[str]] = None) -> ModuleDefinition:
    """The definition under the name a ``_basic_mod:=NAME`` argument gives (``sys.argv`` by default),
    known before the node starts so that the node is named after it; DefinitionError if NAME is not
    a module name."""
    name = node_params(sys.argv[1:] if argv is None else argv, None).get("basic_mod")
    if name is None or name == definition.name:
        return definition
    try:
        return definition.renamed(name)
    except (DefinitionError, TypeError):
        raise DefinitionError(["_basic_mod:=%s: not a module name (letters, digits and '_', not starting with a "
                               "digit)" % (name,)])


def run_module(definition: ModuleDefinition, impl: BasicModule, node_name: Optional[str] = None,
               failures: Optional[Dict[type, int]] = None, name_format: str = "bm_%s",
               max_bytes: Optional[int] = None, unreachable_caller: Optional[float] = None) -> int:
    """Init a ROS node, serve until SIGINT/SIGTERM or ROS shutdown, clean up. Exit code.

    The node is ``node_name``, else ``name_format`` of the module's name (after ``_basic_mod:=``).
    ``failures`` maps more start-up exceptions to exit codes (the bridge's C++ side missing is 3).
    A stop signal at any moment, start-up included, ends it with 0. A master that does not answer
    is waited for at start-up (said every few seconds) and left without unregistering at the end
    (:meth:`comm.nodelife.StopSignals.leave`)."""
    codes: Dict[type, int] = {BindingError: 2, DuplicateModule: 3}
    codes.update(failures or {})
    try:
        definition = renamed_by_argument(definition)
    except DefinitionError as exc:
        sys.stderr.write("error: %s\n" % exc)
        return 2
    stop = StopSignals()
    warn_own_address()  # an address the others cannot reach: rospy would start as if all were well
    if not stop.init_node(node_name or name_format % definition.name, anonymous=False):
        stop.leave()
        return 0
    log_to_rosout()
    node = ModuleNode(definition, impl, max_bytes, unreachable_caller)
    node.start_failures = tuple(codes)
    try:
        try:
            node.start()
        except tuple(codes) as exc:
            if stop.requested:  # a start-up wait given up because of the stop
                return 0
            sys.stderr.write("error: %s\n" % exc)
            return next(code for kind, code in codes.items() if isinstance(exc, kind))
        stop.started()
        stop.wait()
    finally:
        stop.leave(node.unregister)  # bounded: a master that does not answer is left as it is
        _shut_down(impl)
    return 3 if node.kicked_out else 0


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bmtree-module", description="Run a Python basic module as a ROS node.")
    p.add_argument("--definition", help="the module's definition JSON (or the private parameter ~definition)")
    p.add_argument("--class", dest="cls", help="MODULE:CLASS or FILE.py:CLASS implementing it (or ~class)")
    p.add_argument("--node-name", type=node_name, help="ROS node name (default bm_<module>)")
    p.add_argument("--max-bytes", type=count(MIN_MAX_BYTES, what="a ping's answer must fit"),
                   help="largest payload accepted (bytes; default %d, or ~max_bytes)" % DEFAULT_MAX_BYTES)
    p.add_argument("--unreachable-caller", type=unreachable_seconds, metavar="SECONDS",
                   help="cancel the calls of a caller that has not answered for this long: its machine cannot be "
                        "reached (a dropped link) or its process is stopped (default 0: never; or "
                        "~unreachable_caller)")
    return p


def main(argv: Optional[List[str]] = None) -> int:
    parser = make_parser()
    args = parse_node_args(parser, (argv if argv is not None else sys.argv)[1:], None)
    if not args.definition or not args.cls:
        parser.error("--definition and --class are required (or the private parameters ~definition, ~class)")

    try:
        definition = load_definition(os.path.expanduser(args.definition))  # a launch file passes ~/ as written
        factory = load_class(os.path.expanduser(args.cls))
        impl = factory()
    except DefinitionError as exc:
        sys.stderr.write("%s\n" % exc)
        return 2
    except SyntaxError as exc:  # one line, where the author looks: file:line
        sys.stderr.write("%s:%s:%s: syntax error: %s\n" % (exc.filename, exc.lineno, exc.offset or 0, exc.msg))
        return 2
    except ImportError as exc:  # in the class file (file:line where it imports), or its module is not found
        sys.stderr.write("error: %s: %s\n" % (where_raised(exc, args.cls), exc))
        return 2
    except (ValueError, OSError) as exc:
        sys.stderr.write("error: %s\n" % exc)
        return 2
    except KeyboardInterrupt:  # Ctrl-C while the class file loads or its __init__ runs (a driver that hangs)
        sys.stderr.write("stopped while loading %s\n" % args.cls)
        return 130
    except BaseException as exc:  # noqa: B036 - the class file raised while loading or in __init__ (sys.exit too)
        sys.stderr.write("error: %s: %s: %s\n" % (where_raised(exc, args.cls), type(exc).__name__, said(exc)))
        return 2
    try:
        ModuleServer(definition, impl, lambda t: None, lambda t: None)
    except BindingError as exc:
        sys.stderr.write("error: %s\n" % exc)
        return 2
    code = run_module(definition, impl, args.node_name, max_bytes=args.max_bytes,
                      unreachable_caller=args.unreachable_caller)
    _leave_without_threads(code)
    return code


if __name__ == "__main__":
    sys.exit(main())
