"""``bmtree run`` and ``bmtree demo``: a tree against the live graph or the simulated robot."""
from __future__ import annotations

import argparse
import errno
import logging
import os
import time
from typing import Any, Dict, List, Optional, Set

from comm.errors import did_you_mean
from comm.nodelife import Interrupts, leave_graph, shut_rospy_down
from comm.nodeopts import _shown
from coordinator.cliutil import (
    EXIT_ENV,
    EXIT_FAILED,
    EXIT_INVALID,
    EXIT_OK,
    PlainError,
    check_local_address,
    count,
    definitions_from,
    err,
    from_env,
    legacy_option,
    ros_home_problem,
    set_values,
    wait_master,
)
from coordinator.errors import TreeError, TreeErrors, UsageError
from coordinator.preflight import call_limit_warnings, first_uses
from coordinator.runstop import RequestNotice, interrupted_line, shutdown_notice
from coordinator.usermodule import user_module

__all__ = ["DEMO_TREE", "cmd_demo", "cmd_run", "interrupted_line", "shutdown_notice"]

log = logging.getLogger("bmtree.coordinator")

PROJECT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMO_TREE = os.path.join(PROJECT, "trees", "find_apple.yaml")
ANNOUNCED_EVERY = 0.2  # s between looks for the announcement of a module not given with --modules
PREFLIGHT_AT_LEAST = 2.0  # s the preflight has even when the --wait before it is used up
#: s a shutdown request of the run's node holds rospy's shutdown beyond the cleanup's own limit:
#: root halted, the summary, the run's topics unregistered (each master question bounded, 2 s)
SHUTDOWN_MARGIN = 5.0
REQUEST_ANSWERED = 3.0  # s the leave waits for rospy to end the shutdown it held and answer the request


def _report(result: Any, tree_name: str, files: Any = None) -> None:
    from coordinator.runner import summary_lines

    recorded = files is not None and files.log_path is not None
    every = "bmtree replay lists them from the run log" if recorded else ""
    for line in summary_lines(result, tree_name, every):
        print(line)


def _warn_without_blackboard() -> None:
    """A tree that never recalls runs without a Blackboard node, but its results are then kept nowhere."""
    import rosgraph

    from blackboard.client import blackboard_nodes, silent_blackboards

    try:
        answering, silent = blackboard_nodes()
        if answering:
            return
    except (OSError, rosgraph.masterapi.Error) as exc:  # the master went away meanwhile: the run will say so
        log.debug("asking for the Blackboard node: %s", exc)
        return
    if silent:   # registered, but not reachable from here: saying "none is running" would be false
        from comm.address import REFUSED

        gone = any(failure == REFUSED for _uri, failure in silent.values())
        err("warning: %s: %s" % (silent_blackboards(silent), "the results of this run's calls are not stored" if gone
                                 else "it may still store the results of this run's calls (it connects to the "
                                      "modules itself), but a recall could not get its answers here"))
        return
    err("warning: no Blackboard node is running on this master: the results of this run's calls are not stored "
        "(start one: bmtree-blackboard, or roslaunch bmtree blackboard.launch)")


def _check_given(tree: Any, given: Dict[str, Any], path: str) -> None:
    """Print the tree's warnings; ``--set`` keys must be inputs the tree declares (a typo would
    silently use the default), every required input must be given, and each value must fit the call
    inputs the tree passes it to (else the call would refuse it mid-run, after the calls before it)."""
    for w in tree.warnings:
        err(str(w))
    for key in sorted(given):
        if key not in tree.inputs:
            raise UsageError("%s declares no input %s%s (its inputs: %s)" % (
                path, _shown(key), did_you_mean(key, tree.inputs), ", ".join(sorted(tree.inputs)) or "none"))
    missing = sorted(tree.required_inputs - set(given))
    if missing:
        raise UsageError("%s needs the input%s %s: give them with --set KEY=VALUE" % (
            path, "s" if len(missing) > 1 else "", ", ".join(missing)))
    from coordinator.inputvalues import set_value_errors

    misfits = set_value_errors(tree, given)
    if misfits:
        raise PlainError("\n".join("error: %s" % m for m in misfits))


def _needs_live_definitions(exc: TreeErrors) -> bool:
    """True if the tree may still be valid once the live modules' definitions are known."""
    return any(e.message.startswith("unknown module") for e in exc.errors)


def _sim_advice(exc: TreeErrors, defs: Dict[str, Any]) -> TreeErrors:
    """``exc`` with its unknown modules' advice for ``--sim``: a definition alone (``--modules``) does
    not start a module there, ``--module DEF.json=FILE.py:CLASS`` does."""
    from coordinator.language import TreeErrorsWithWarnings

    if not any(e.module for e in exc.errors):
        return exc
    errors = [TreeError(e.pos, "unknown module %r (known: %s; --sim starts your module beside the simulated robot "
                               "with --module DEF.json=FILE.py:CLASS)" % (e.module, ", ".join(sorted(defs))), e.module)
              if e.module else e for e in exc.errors]
    return TreeErrorsWithWarnings(errors, list(getattr(exc, "warnings", ())))


def _other_runs() -> List[str]:
    """The live nodes, other than this one, that publish a run stream's tree on this master."""
    import rosgraph
    import rospy

    from comm.rpc import master_api
    from coordinator.watch import STREAM_NS
    from modules.discovery import node_alive

    master = master_api(rospy.get_name())
    try:
        pubs, _, _ = master.getSystemState()
    except (OSError, rosgraph.masterapi.MasterException):
        return []
    nodes = sorted({n for t, ns in pubs if t == STREAM_NS + "/tree" for n in ns if n != rospy.get_name()})
    out = []
    for node in nodes:
        try:
            alive = node_alive(master.lookupNode(node), 1.0)
        except (OSError, rosgraph.masterapi.MasterException):
            alive = False
        if alive:  # not one killed outright, whose registration stays
            out.append(node)
    return out


def _load_announced(path: str, defs: Dict[str, Any], given: Set[str], deadline: float) -> Any:
    """The tree, with the definitions the live modules announce added to ``defs``.

    A module the tree uses that is neither given (``--modules``) nor announced yet may be one
    that is starting (a launch file starts it beside the run): wait for its announcement until
    ``deadline``, saying so. None (after printing why) when it never came: the environment's
    problem, exit 3. A name close to a known one is taken as a typo and any other error in the
    tree as the tree's: TreeErrors at once, exit 2.
    """
    from coordinator.language import load_tree
    from modules.discovery import announced_modules

    told = False
    while True:
        for name, live in announced_modules().items():  # liveness: the preflight pings them
            defs.setdefault(name, live.definition)
        try:
            return load_tree(path, defs, given=given)
        except TreeErrors as exc:
            missing = sorted({e.module for e in exc.errors if e.module})
            if not missing or any(not e.module for e in exc.errors):
                raise
            master = os.environ.get("ROS_MASTER_URI", "http://localhost:11311/")
            left = deadline - time.monotonic()
            if left <= 0:
                for e in exc.errors:
                    err("%s: module %r is not running: no bmtree module of that name announced itself on %s "
                        "(--wait), and its definition was not given (start it, or give its definition with "
                        "--modules FILE.json or a folder of them: an original module does not announce itself)"
                        % (e.pos, e.module, master))
                return None
            if not told:
                err("module%s %s not announced on %s yet, and no definition given with --modules; waiting up to "
                    "%.3g s (--wait) ..." % ("s" if len(missing) > 1 else "", ", ".join(map(repr, missing)), master,
                                             left))
                told = True
            time.sleep(min(ANNOUNCED_EVERY, left))


def cmd_run(args: argparse.Namespace) -> int:
    for attr in ("tree", "world", "record"):  # a launch file passes ~/ as written
        if getattr(args, attr, None):
            setattr(args, attr, os.path.expanduser(getattr(args, attr)))
    args.modules = [os.path.expanduser(m) for m in args.modules] if args.modules else args.modules
    if not args.max_duration:   # 0: no limit (run.launch sets it always)
        args.max_duration = None
    from coordinator.builder import build_tree
    from coordinator.clock import RealClock
    from coordinator.context import RunContext
    from coordinator.language import load_tree, used_modules
    from coordinator.runlog import plan_run_files
    from coordinator.runner import Display, NoticeLines, TreeRunner

    given = set_values(args.set)
    legacy_option(getattr(args, "legacy", None), None)  # its form before anything waits (its module: below)
    if args.keep_runs is None:
        args.keep_runs = from_env("BMTREE_KEEP_RUNS", count())
    if args.record and not args.no_record:
        _check_record(args.record)
    defs = definitions_from(args.modules)
    user_modules = [user_module(spec) for spec in (getattr(args, "module", None) or [])]
    if user_modules and not args.sim:
        raise UsageError("--module starts your module beside the simulated robot: it needs --sim "
                         "(without --sim, start it with bmtree-module, or a C++ module's node with its bmtree-bridge, and "
                         "run against the live graph)")
    for option, value, what in (("--world", getattr(args, "world", None), "chooses the simulated robot's world"),
                                ("--ros-ip", getattr(args, "ros_ip", None), "is the simulated robot's address"),
                                ("--port", getattr(args, "port", None), "is the simulated robot's master's port")):
        if value and not args.sim:
            raise UsageError("%s %s: it needs --sim (without --sim the tree runs on the live graph, whose modules "
                             "are the robot's)" % (option, what))
    for um in user_modules:
        defs[um.definition.name] = um.definition
    tree = None
    try:  # validate before anything waits: a typo is exit 2 at once, not after --wait seconds
        tree = load_tree(args.tree, defs, given=set(given))
    except TreeErrors as exc:
        if args.sim:
            raise _sim_advice(exc, defs)
        if not _needs_live_definitions(exc):
            raise
    if tree is not None:
        _check_given(tree, given, args.tree)
    if args.sim:  # before anything starts: a wrong --world or --ros-ip is the user's, exit 2
        from modules.sim.world import DEFAULT_WORLD, World, WorldError

        if args.ros_ip:
            check_local_address("--ros-ip", args.ros_ip)

        try:
            World.load(args.world or DEFAULT_WORLD, others=[fn.qualified for um in user_modules
                                                           for fn in um.definition.functions.values()])
        except WorldError as exc:
            raise PlainError("error: --world %s" % exc)
    files = plan_run_files(args.tree, args.record, args.no_record, args.keep_runs)
    for folder in ([os.path.dirname(files.sim_dir)] if args.sim else []) + (
            [os.path.dirname(files.log_path)] if files.log_path and not args.record else []):
        problem = ros_home_problem(folder)
        if problem is not None:
            raise problem
    graph = None
    transport = None
    runner = None
    recorder: Any = None
    interrupts = Interrupts(EXIT_ENV)  # Ctrl-C and SIGTERM stop the tree (KeyboardInterrupt), never a registration
    guard = None
    stopped_at = None  # when a stop signal stopped the run: a second one leaves the graph at once
    try:
        deadline = time.monotonic() + args.wait  # for the master, the modules' announcements, the preflight
        if not args.sim:
            if not wait_master(args.wait):
                from comm.rpc import master_absence

                uri = os.environ.get("ROS_MASTER_URI", "http://localhost:11311/")
                err("error: no ROS master at %s after %g s: %s. Without a robot, bmtree run --sim brings up a "
                    "simulated one" % (
                    uri, args.wait, master_absence(uri) or "something listens there, but it does not answer as a "
                                                           "ROS master"))
                return EXIT_ENV
            guard = _start_guard(args.wait, interrupts)
            if tree is None:  # modules known only to the live graph
                with guard.watching():
                    tree = _load_announced(args.tree, defs, set(given), deadline)
                if tree is None:
                    return EXIT_ENV
                _check_given(tree, given, args.tree)
        assert tree is not None
        legacy = legacy_option(getattr(args, "legacy", None), defs)
        mods, recall = used_modules(tree)
        if args.sim:
            from coordinator.simgraph import SIM_MODULES, ModuleStartError, process_ends, start_sim

            mine = {um.definition.name for um in user_modules}
            sim = [m for m in SIM_MODULES if m not in mine]
            absent = sorted(set(mods) - set(sim) - mine)
            if absent:
                raise UsageError("%s uses %s, which --sim does not start (it starts %s): add --module %s.json=FILE.py:CLASS "
                                 "(or =EXECUTABLE for a C++ module, =SCRIPT.yaml for a scripted stand-in)" % (args.tree, ", ".join(absent),
                                                                        ", ".join(SIM_MODULES), absent[0]))
            # progress goes to stderr: stdout holds the run's outcome, for scripts (and with -q, only that)
            err("starting the simulated robot (private rosmaster, Blackboard, %s)..." % ", ".join(
                sim + ["%s (yours)" % m for m in sorted(mine)]))
            err("its Blackboard store and module logs go to %s" % files.sim_dir)
            try:
                graph = start_sim(world=args.world, ros_home=files.sim_dir, modules=sim, user_modules=user_modules,
                                  address=args.ros_ip, timeout=args.wait, port=args.port or 0)
            except ModuleStartError as exc:
                err("error: %s" % exc)
                return EXIT_INVALID if exc.code == EXIT_INVALID else EXIT_ENV
            graph.adopt()  # loopback: the private graph works whatever the hostname
            err("simulated robot up, master at %s" % graph.uri)
            err("  (to watch it from another terminal: ROS_MASTER_URI=%s bmtree watch)" % graph.uri)
            guard = _start_guard(args.wait, interrupts)
        assert guard is not None
        with guard.watching():  # a master that stops answering now: a bounded wait, then exit 3
            from coordinator.ros_transport import RosTransport, address_problem

            hint = address_problem()
            if hint:
                err("warning: %s" % hint)
            transport = RosTransport(max_bytes=args.max_bytes, liveness=args.liveness)
            transport.whereabouts.ended = process_ends(graph) if graph is not None else None  # --sim: why one ended
            stream_sink = transport.stream_sink()
            # rospy initialized: a shutdown request of its node (rosnode kill) stops the run as Ctrl-C does, ROS up
            request_notice = RequestNotice()
            interrupts.stop_on_shutdown_request(lambda: SHUTDOWN_MARGIN + (
                tree.cleanup_timeout if tree is not None and tree.cleanup is not None else 0.0), request_notice)
            from coordinator.watch import STREAM_NS

            for other in [] if args.sim else _other_runs():  # a private graph has no other run
                err("warning: another bmtree run is running on this master (node %s): both store results under the "
                    "same Blackboard names (a recall may read its values), both publish the run stream on %s (bmtree "
                    "watch shows the first it sees; watch --run ID picks one), and bmtree control needs --node NODE to say "
                    "which run it steers" % (other, STREAM_NS))
            try:
                left = args.wait if args.sim else max(deadline - time.monotonic(), min(args.wait, PREFLIGHT_AT_LEAST))
                transport.wait_ready(mods, left, defs, blackboard=recall, legacy=legacy, notify=None if args.sim else err,
                                     where=first_uses(tree))
            except OSError as exc:
                if not guard.answers():
                    raise guard.error(exc) from None
                err("error: %s" % exc)
                return EXIT_ENV
            stream_sink.settle()
            for module, note in sorted(transport.ping_notes.items()):
                if note and module in mods:
                    err("warning: module %s: %s" % (module, note[:400]))
            import rosgraph

            from modules.discovery import announced_modules

            try:
                limits = {n: m.call_limit for n, m in announced_modules().items() if n in mods and m.call_limit}
            except (OSError, rosgraph.masterapi.Error):  # the master went away meanwhile: the run will say so
                limits = {}
            for line in call_limit_warnings(tree, limits, args.call_timeout):
                err(line)
            if not recall and not args.sim:
                _warn_without_blackboard()
            ctx = RunContext(transport, RealClock(), defs, default_timeout=args.call_timeout)
            root = build_tree(tree, ctx, given)
            from coordinator.watch import run_view

            view, sinks = run_view(transport, args.quiet)
            display = None if args.quiet or view is not None else Display()
            err("running %s" % tree.name)
            recorder = files.recorder([stream_sink] + sinks, given, args.max_duration, args.world if args.sim else None,
                                      control=bool(getattr(args, "control", False)),
                                      modules=list(args.modules or []) + [um.definition_path for um in user_modules])
            from coordinator.controlros import ros_controller

            steer = ros_controller(getattr(args, "control", False))
            quiet_notices = [NoticeLines()] if display is None and view is None else []
            runner = TreeRunner(root, ctx, period=args.period, display=display,
                                observers=[recorder, steer] + quiet_notices, tree=tree, gate=steer)
            guard.wait_back()  # no first tick while the master is away (bounded)
        guard.stop()  # from the first tick on, the run's master watch tells (notices)
        request_notice.ctx = ctx
        try:
            result = runner.run(args.max_duration)
            interrupts.done()  # a shutdown request from now on only waits for the leave
            runner.confirm_cancels()   # the calls it stopped: ended on their module, or said to go on
            recorder.close()   # after the answers to its cancels, which the log keeps too
        finally:
            if view is not None:
                view.stop()
        _report(result, tree.name, files)
        files.report(print)
        return EXIT_OK if result.succeeded else EXIT_FAILED
    except KeyboardInterrupt:
        stopped_at = interrupts.last_signal
        running: List[Any] = []
        if runner is not None and runner.result is not None:
            try:   # (a second Ctrl-C meanwhile: said without waiting)
                running = runner.confirm_cancels()
            except KeyboardInterrupt:
                running = [c for c in runner.ctx.calls if c.maybe_running]
        if recorder is not None:
            recorder.close()
        err(interrupted_line(runner.result if runner is not None else None, runner is not None,
                             interrupts.shutdown_request, running))
        if runner is not None and runner.result is not None and tree is not None:
            with interrupts.held(again_exits=False):  # what it did and where its log is, before a second Ctrl-C
                _report(runner.result, tree.name, files)
                files.report(print)
        return EXIT_ENV
    finally:
        if recorder is not None:
            recorder.close()   # (done already, unless the run ended by an error)
        if guard is not None:
            guard.stop()
        try:
            with interrupts.held(again_exits=False):  # until the leave takes the signals (bounded)
                _leave_graph(transport, master_gone=guard is not None and (guard.expired or guard.down),
                             stopped_at=stopped_at, interrupts=interrupts)
        except KeyboardInterrupt:
            pass
        interrupts.restore()
        if graph is not None:
            graph.close()


def _start_guard(limit: float, interrupts: Interrupts) -> Any:
    """A master that stops answering during start-up gets ``limit`` s (``--wait``) to come back.

    rospy's questions to the master get a timeout first (before ``init_node``): one that a master
    stopped or cut off never answers would hold the start-up, and a stop signal, for ever."""
    from comm.nodelife import bound_master_questions
    from comm.rpc import MASTER_TIMEOUT
    from coordinator.ros_transport import StartupGuard

    bound_master_questions(MASTER_TIMEOUT)
    return StartupGuard(limit, err, interrupts).start()


def _leave_graph(transport: Any, master_gone: bool = False, stopped_at: Optional[float] = None,
                 interrupts: Optional[Interrupts] = None) -> None:
    """Unregister everything this process registered with the master (also when a stop signal
    came before the transport was made: ``init_node`` may have registered already), bounded
    (:func:`comm.nodelife.leave_graph`): a master that does not answer within a few seconds, or
    ``master_gone`` (it stopped answering during start-up), is left without unregistering, said in
    one line; a second stop signal (after the one at ``stopped_at``, if any) leaves at once. A
    shutdown request that ``interrupts`` hold goes on once the run's topics are unregistered, and is
    waited for (bounded): its thread unregisters the rest."""
    import rospy

    from coordinator.watch import quiet_unregistering

    if transport is None and not rospy.core.is_initialized():
        return  # nothing registered

    def steps() -> None:
        if transport is not None:
            transport.close()
        if interrupts is not None:
            interrupts.leaving()
        if rospy.core.is_initialized():
            shut_rospy_down("bmtree run finished")
        if interrupts is not None:
            interrupts.request_answered(REQUEST_ANSWERED)

    with quiet_unregistering():  # a master that is gone: one warning per topic, for nothing left to undo
        leave_graph(steps, err, master_down=master_gone, stopped_at=stopped_at)


def _check_record(record: str) -> None:
    """``--record PATH`` names a file in a folder that can be made and written in (else the run would go
    on, and only its end would say that nothing was recorded)."""
    folder = os.path.dirname(os.path.abspath(record))
    if os.path.isdir(record):
        raise UsageError("--record %s: a folder; give the name of a file (a run log) in it" % record)
    try:
        if os.path.lexists(folder) and not os.path.isdir(folder):
            raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR))
        os.makedirs(folder, exist_ok=True)  # as the run log's writer would
        why = "" if os.access(folder, os.W_OK | os.X_OK) else "Permission denied"
    except OSError as exc:
        why = exc.strerror or str(exc)
    if why:
        raise UsageError("--record %s: cannot write in %s (%s)" % (record, folder, why))


def cmd_demo(args: argparse.Namespace) -> int:
    args.tree, args.sim = DEMO_TREE, True
    return cmd_run(args)
