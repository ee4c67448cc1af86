"""``bmtree watch``: attach to the tree running on $ROS_MASTER_URI through its run stream.

The watcher subscribes to ``/bmtree/run/*``: the latched ``tree`` and the ``snapshot``
records catch it up mid-run, the other channels keep it current. On a terminal it
shows :func:`coordinator.watchview.render` redrawn in place (``rich.live``,
:mod:`coordinator.watchterm`); otherwise one line per change. ``--web`` serves the same state as
a page (:mod:`coordinator.webview`). It shows one run: the first one seen, or the one ``--run``
names; another run on the same master gets a notice saying how to watch it.
"""
from __future__ import annotations

import argparse
import contextlib
import logging
import os
import sys
import threading
import time
from typing import Any, Callable, Dict, Iterator, List, Optional, TextIO, Tuple, cast

from comm.nodelife import StopSignals, leave_graph
from comm.nodeopts import PORT
from coordinator.cliutil import bind_address, seconds
from coordinator.runevents import terminal_text
from coordinator.runrecords import parse_record
from coordinator.runstream import to_json
from coordinator.watchlive import END_TICKS_GRACE, RunLiveness
from coordinator.watchsinks import SnapshotSink
from coordinator.watchstate import WatchState
from coordinator.watchterm import Keys, LiveView, key_reader, keys_help
from coordinator.watchview import LinePrinter, TimeOrderedLines

__all__ = ["RosWatcher", "LiveView", "cmd_watch", "run_view", "STREAM_NS", "WATCH_CHANNELS"]

STREAM_NS = "/bmtree/run"
WATCH_CHANNELS = ("tree", "snapshot", "status", "calls", "events", "blackboard", "control", "end")
#: after the run's end, ``watch --web`` serves until a page got the end (and one second more, for
#: the other pages polling), and at most this long (s); the page keeps showing the last state
END_GRACE = 5.0


class RosWatcher:
    """Subscribes to the run stream and applies every record to ``state`` (and to ``on_record``)."""

    def __init__(self, state: WatchState, namespace: str = STREAM_NS,
                 on_record: Optional[Callable[[dict], None]] = None):
        self.state = state
        self.namespace = namespace.rstrip("/")
        self.on_record = on_record
        self._subs: List[Any] = []
        self.nodes: Dict[str, str] = {}  # run id -> the node that published its tree (the run's own)

    def start(self) -> None:
        import rospy
        from std_msgs.msg import String

        for c in WATCH_CHANNELS:
            self._subs.append(rospy.Subscriber("%s/%s" % (self.namespace, c), String, self._got, queue_size=1000))

    def _got(self, msg: Any) -> None:
        data = getattr(msg, "data", None)
        rec, _why = parse_record(data) if isinstance(data, str) else (None, "")
        if not isinstance(rec, dict):
            return
        if rec.get("type") in ("tree", "snapshot"):
            node = (getattr(msg, "_connection_header", None) or {}).get("callerid")
            if node and rec.get("run"):
                self.nodes[str(rec["run"])] = node
        self.apply(rec)

    def apply(self, rec: Dict[str, Any]) -> None:
        """A record, as if it came from the stream (the watch's own ``end`` of a run that is gone)."""
        with self.state.lock:
            self.state.apply(rec)
            if self.on_record is not None:
                try:
                    self.on_record(rec)
                except Exception:  # a printing problem must not stop the subscriber
                    pass

    def show_next(self) -> bool:
        """Once the run shown has ended (``--follow``): show another one going on the master,
        which started meanwhile (True), if any."""
        with self.state.lock:
            nxt = self.state.others.next_live() if self.state.end is not None else None
            if nxt is not None:
                self.apply(nxt)
            return nxt is not None

    def node(self) -> Optional[str]:
        """The ROS node of the run shown (its commands name it: another run leaves them alone)."""
        with self.state.lock:
            return self.nodes.get(self.state.run) if self.state.nodes else None

    def close(self) -> None:
        for s in self._subs:
            s.unregister()
        self._subs = []


def run_view(transport: Any, quiet: bool, namespace: str = STREAM_NS) -> Tuple[Optional[LiveView], List[Any]]:
    """For ``bmtree run``: the snapshot publisher (latched ``namespace/snapshot``, so watchers that
    attach mid-run catch up) and, on a terminal, the live view drawn from the same state."""
    import rospy

    transport.open()
    string = transport._String
    sink = SnapshotSink(lambda text: pub.publish(string(text)))

    class CatchUp(rospy.SubscribeListener):
        """A new watcher gets the state of *now*, to itself alone, on connecting. Not a latched
        topic: the latch would hold the last periodic snapshot, up to an interval old, and a
        watcher attaching in between would load a past state."""

        def peer_subscribe(self, topic_name: str, topic_publish: Any, peer_publish: Any) -> None:
            peer_publish(string(to_json(sink.snapshot())))

    pub = rospy.Publisher("%s/snapshot" % namespace.rstrip("/"), string, queue_size=10, subscriber_listener=CatchUp())
    view = None
    if not quiet and sys.stdout.isatty():
        view = LiveView(sink.state, footer="Ctrl-C stops the run", title="bmtree run").start()
    return view, [sink]


def no_run_message(namespace: str, waited: float, only: str = "", others: Optional[List[Dict[str, Any]]] = None,
                   address: str = "") -> str:
    """Why ``bmtree watch`` found nothing to show, and where a run that already ended is.
    ``address``: why the watch's own address cannot be reached (:func:`comm.address.own_address_problem`),
    so that a run's stream never connects to it."""
    seen = ", ".join("%s (%s)" % (o.get("run"), o.get("name")) for o in others or [])
    return ("error: %s on %s/tree after %gs (is 'bmtree run' running on this master?%s)%s. A run that has already "
            "ended is recorded on the machine that ran it: 'bmtree runs' lists them, 'bmtree replay last' (or RUN) "
            "shows one" % ("no run %s" % only if only else "no run", namespace, waited,
                           " If it is, it cannot reach this watch: %s" % address if address else "",
                           "; the runs seen: %s" % seen if seen else ""))


@contextlib.contextmanager
def joining(limit: float, tool: str) -> Iterator[Any]:
    """The start-up of ``bmtree watch`` or ``control`` (``rospy.init_node`` and their topics), bounded.

    The master answered the check before it (``master_up``); should it stop answering now (its
    process stopped, its machine cut off), rospy would retry its registrations for ever and hold
    Ctrl-C. Here, as in ``bmtree run``'s start-up, rospy's questions are bounded and the master
    gets ``limit`` seconds (``--wait``) to answer again, said on stderr
    (:class:`coordinator.ros_transport.StartupGuard`); then rospy's retries end and
    :class:`coordinator.ros_transport.MasterGone` is raised (exit 3). A stop signal is held until
    the block ends, then raised as KeyboardInterrupt, at once while the master does not answer; a
    second one exits at once (:class:`comm.nodelife.Interrupts`). Yields those Interrupts
    (``last_signal``: when a stop came)."""
    from comm.nodelife import Interrupts, bound_master_questions, registering
    from comm.rpc import MASTER_TIMEOUT
    from coordinator.cliutil import EXIT_ENV, err
    from coordinator.ros_transport import MasterGone, StartupGuard

    bound_master_questions(MASTER_TIMEOUT)
    interrupts = Interrupts(EXIT_ENV)
    guard = None
    try:
        guard = StartupGuard(limit, err, interrupts).start()
        with registering():
            yield interrupts
    except Exception:
        if guard is None or not guard.expired:
            raise
    finally:
        if guard is not None:
            guard.stop()
        interrupts.restore()
    if guard is not None and guard.expired:
        raise MasterGone("the ROS master at %s stopped answering while bmtree %s registered with it and did not answer "
                         "again within %g s (--wait): start it again, then bmtree %s" % (guard.master_uri, tool, limit,
                                                                                       tool))


def cmd_watch(args: argparse.Namespace) -> int:
    """Attach, show, and return when the run ends (or at once if it already ended), unless --follow."""
    import rospy

    from coordinator.cliutil import EXIT_ENV, EXIT_INVALID, EXIT_OK, err, master_up

    if not master_up(args.wait):
        err("error: no ROS master at %s" % os.environ.get("ROS_MASTER_URI", "http://localhost:11311/"))
        return EXIT_ENV
    from comm.address import warn_own_address

    own = warn_own_address()  # "warning: ROS_IP=127.0.0.1 is a loopback address ..."
    state = WatchState(only=getattr(args, "run", None) or "")
    tty = sys.stdout.isatty() and not args.plain
    # records come on several topics: their lines go out in run-time order, a moment late
    lines_out = None if tty or args.web else TimeOrderedLines(sys.stdout)
    printer = None if lines_out is None else LinePrinter(cast(TextIO, lines_out))
    # Ctrl-C, kill, timeout or a closed terminal only raise a flag that the waits poll, and the
    # watch ends through the finally that unregisters it: an exception thrown into rospy while it
    # registers a subscriber would leave that subscriber on the master, which each later run waits for
    signals = StopSignals()
    watcher = None
    liveness = None
    server = None
    view = None
    client = None
    stop = threading.Event()
    held = None  # the start-up's signals (a stop then is raised as KeyboardInterrupt)

    def wait(predicate: Callable[[WatchState], bool], timeout: float) -> bool:
        """``state.wait`` that a stop signal or the q key also ends (False)."""
        end = time.monotonic() + timeout
        while not (signals.requested or stop.is_set()):
            if state.wait(predicate, min(0.3, max(0.0, end - time.monotonic()))):
                return True
            if time.monotonic() >= end:
                return False
        return False

    try:
        from coordinator.controlros import ControlClient

        try:
            with joining(args.wait, "watch") as held:  # bounded: a master that stops answering now
                rospy.init_node("bmtree_watch", anonymous=True, disable_signals=True)
                watcher = RosWatcher(state, args.namespace,
                                     on_record=(lambda r: printer.record(r, state)) if printer else None)
                watcher.start()
                client = ControlClient()
        except KeyboardInterrupt:  # a stop signal while registering ends the watch as one later does
            return EXIT_OK
        liveness = RunLiveness(watcher, on_change=(lambda: printer.notes(state)) if printer else None).start()
        to = watcher.node

        def steer(cmd: Dict[str, Any]) -> Dict[str, Any]:
            """A command of the page, to the run shown only."""
            node = to()
            return client.send(dict(cmd, to=node) if node else cmd, 10.0)

        if args.web:
            from coordinator.webview import serve

            server = serve(state, args.bind, args.port, control=steer)
            print("watching %s/* of the master %s; page at %s" % (
                args.namespace, os.environ.get("ROS_MASTER_URI", ""), server.where()))
            sys.stdout.flush()
        elif tty:
            view = LiveView(state, footer=keys_help, summary=True).start()
            key_reader(Keys(view, client, stop, to).press, stop)
        if not wait(lambda s: bool(s.nodes or s.refused), args.wait if not args.follow else 1e9) or state.refused:
            if signals.requested or stop.is_set():
                return EXIT_OK
            if state.refused:  # a newer bmtree's run: what this one would show of it could be wrong
                if view is not None:
                    view.stop(final=False)
                    view = None
                err("error: %s" % state.refused)
                return EXIT_INVALID
            if view is not None:
                view.stop(final=False)
                view = None
            err(no_run_message(args.namespace, args.wait, state.only, state.others.summary(), str(own or "")))
            return EXIT_ENV
        while wait(lambda s: s.end is not None, 1e9):  # (False: a stop)
            # the latched end can overtake the last ticks (another topic): the lines, the terminal's
            # last screen and the page wait for them a moment
            wait(lambda s: s.end is None or s.tick >= int(s.end.get("ticks") or 0), END_TICKS_GRACE)
            if printer is not None:
                with state.lock:
                    printer.finish()
                if lines_out is not None and not args.follow:
                    lines_out.close()   # the lines of the run, all of them, before anything else is said
            if not args.follow:
                break
            run = state.run
            watcher.show_next()  # a run going on already; else the next run's tree is shown when it comes
            wait(lambda s, shown=run: s.run != shown or s.end is None, 1e9)
        if server is not None and state.end is not None and not (signals.requested or stop.is_set()):
            print(terminal_text("the run ended: %s; the page keeps showing it (--follow serves it for the next run "
                                "too)" % state.end.get("status")))
            sys.stdout.flush()
            if wait(lambda s: server.end_served.is_set(), END_GRACE):
                wait(lambda s: False, 1.0)
        if state.end is not None and state.end.get("gone"):
            if server is not None and not (signals.requested or stop.is_set()):
                # (the terminal view prints it once its alternate screen is gone, the lines have their end)
                err("the run did not finish: %s" % state.end.get("reason"))
            return EXIT_ENV
        return EXIT_OK
    finally:
        stop.set()
        if lines_out is not None:
            lines_out.close()
        if liveness is not None:
            liveness.stop()
        if view is not None:
            view.stop()
        if server is not None:
            server.close()
        def steps() -> None:
            if client is not None:
                client.close()
            if watcher is not None:
                watcher.close()
            rospy.signal_shutdown("bmtree watch finished")

        say, gone = leaving(state, err)
        with quiet_unregistering():  # bounded: a master that does not answer is left without unregistering
            leave_graph(steps, say, master_down=gone,
                        stopped_at=signals.signalled_at or (held.last_signal if held else None))


#: a ``--sim`` run's master answers this long at most when the watch leaves (s)
OWNER_GONE_QUESTION = 0.5


def leaving(state: WatchState, say: Callable[[str], None],
            answers: Optional[Callable[[float], bool]] = None) -> Tuple[Callable[[str], None], bool]:
    """How the watch leaves the master: what it says, and whether that master is known to be gone.

    A ``bmtree run --sim`` brings up a master of its own (its ``tree`` record has ``sim``) and takes it
    down when it ends: once the run shown was such a run and has ended, a master that does not answer
    is gone with it, and there is nothing to leave. The watch then says nothing of it (not rospy's
    "does not answer: leaving without unregistering … rosnode cleanup", which is about a master that is
    still there); ``answers(timeout)`` asks the master (:func:`comm.rpc.master_answers`)."""
    with state.lock:
        owned = state.end is not None and isinstance(state.tree.get("sim"), dict)
    if not owned:
        return say, False

    def quiet(text: str) -> None:
        if not (text.startswith("the ROS master at ") and "does not answer" in text):
            say(text)

    if answers is None:
        from comm.rpc import master_answers as answers
    try:
        up = answers(OWNER_GONE_QUESTION)
    except Exception:  # (a Ctrl-C is the leaving's own to handle)
        up = False
    return quiet, not up


class _OutOfSync(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return "registrations are now out of sync" not in str(record.msg)


@contextlib.contextmanager
def quiet_unregistering() -> Iterator[None]:
    """Our own shutdown leaves the master: when it is gone (the ``--sim`` run that brought it up
    has ended), rospy warns once per topic that it could not unregister. Nothing is left to
    unregister from a master that is gone, so those warnings are dropped, only meanwhile."""
    rosout = logging.getLogger("rosout")
    quiet = _OutOfSync()
    rosout.addFilter(quiet)
    try:
        yield
    finally:
        rosout.removeFilter(quiet)


def add_watch_parser(sub: Any) -> None:
    w = sub.add_parser("watch", help="show the tree running on $ROS_MASTER_URI, live (terminal or --web)")
    w.add_argument("--plain", action="store_true", help="one line per change even on a terminal")
    w.add_argument("--follow", action="store_true", help="keep watching after the run ends (the next run too)")
    w.add_argument("--run", metavar="ID", help="show this run (its id, as in the run stream and its log's name, or "
                                               "the id's last part); default: the first run seen")
    w.add_argument("--namespace", default=STREAM_NS, help="the run stream's topics (default %(default)s)")
    w.add_argument("--wait", type=seconds("do not wait"), default=10.0, help="how long to wait for the master and a run (s)")
    w.add_argument("--web", action="store_true", help="serve a live page instead of the terminal view")
    w.add_argument("--bind", type=bind_address, default="127.0.0.1",
                   help="address of the page with --web (default loopback)")
    w.add_argument("--port", type=PORT, default=8765, help="port of the page with --web (0: any free one)")
    w.set_defaults(func=cmd_watch)


def cmd_control(args: argparse.Namespace) -> int:
    """``bmtree control COMMAND ...``: one command to the run on $ROS_MASTER_URI, its answer printed."""
    import rospy

    from coordinator.cliutil import EXIT_ENV, EXIT_INVALID, EXIT_OK, err, master_up
    from coordinator.control import parse_command
    from coordinator.controlros import ControlClient

    try:
        cmd = parse_command(args.words)
    except ValueError as exc:
        err("error: %s" % exc)
        return EXIT_INVALID
    if not master_up(args.wait):
        err("error: no ROS master at %s" % os.environ.get("ROS_MASTER_URI", "http://localhost:11311/"))
        return EXIT_ENV
    client = None
    held = None
    try:
        with joining(args.wait, "control") as held:  # bounded: a master that stops answering now
            rospy.init_node("bmtree_control", anonymous=True, disable_signals=True)
            client = ControlClient()
        reply = client.send(dict(cmd, to=args.node) if args.node else cmd, args.wait)
    finally:
        def steps() -> None:
            if client is not None:
                client.close()
            rospy.signal_shutdown("bmtree control finished")

        with quiet_unregistering():  # bounded: a master that does not answer is left without unregistering
            leave_graph(steps, err, stopped_at=held.last_signal if held else None)
    if reply.get("ok"):
        print(terminal_text(str(reply.get("answer"))))
        return EXIT_OK
    err("refused: %s" % reply.get("answer"))
    return EXIT_ENV if str(reply.get("answer", "")).startswith("no run ") else EXIT_INVALID  # none there, or no answer


def add_control_parser(sub: Any) -> None:
    c = sub.add_parser("control", help="steer the run on $ROS_MASTER_URI (started with 'bmtree run --control')")
    c.add_argument("words", nargs="+", metavar="COMMAND",
                   help="pause | resume | step | stop | break NODE | clear NODE | force NODE SUCCESS|FAILURE | "
                        "set KEY VALUE (NODE: a name, or NAME@ID when several nodes share it)")
    c.add_argument("--wait", type=seconds(), default=10.0, help="how long to wait for the run's answer (s)")
    c.add_argument("--node", default="", metavar="NODE",
                   help="only the run of this ROS node (e.g. /bmtree_14239_1795636146106, as 'bmtree run' names "
                        "another run on the master), when several runs share one master")
    c.set_defaults(func=cmd_control)
