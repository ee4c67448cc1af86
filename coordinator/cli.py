"""The ``bmtree`` command (DESIGN §5). Exit codes: 0 success, 1 task failed, 2 invalid input, 3 environment."""
from __future__ import annotations

import argparse
import os
import signal
import sys
from typing import Any, Dict, List, Optional

import yaml

from comm.errors import did_you_mean
from comm.nodeopts import fill_from_params, myargv, node_params, private_namespace
from coordinator import __version__
from coordinator.errors import EnvironmentProblem, InvalidInput, TreeErrors, UsageError
from modules.definition import DefinitionError, ModuleDefinition, load_definitions
from modules.search import default_definitions

__all__ = ["main", "make_parser", "EXIT_OK", "EXIT_FAILED", "EXIT_INVALID", "EXIT_ENV"]

EXIT_OK, EXIT_FAILED, EXIT_INVALID, EXIT_ENV = 0, 1, 2, 3
PROJECT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMO_TREE = os.path.join(PROJECT, "trees", "find_apple.yaml")


class _Plain(UsageError):
    """An exit-2 error already written as ``file:line:column: message``."""


def _err(text: str) -> None:
    sys.stderr.write(text.rstrip("\n") + "\n")


def _definitions(paths: Optional[List[str]]) -> Dict[str, ModuleDefinition]:
    """The default definitions plus ``paths`` (``--modules`` adds; a later one replaces a module by name)."""
    return default_definitions(paths or ())


def _given(pairs: Optional[List[str]]) -> Dict[str, Any]:
    out = {}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        if not sep or not key.isidentifier():
            raise UsageError("--set takes KEY=VALUE, got %r" % pair)
        try:
            out[key] = yaml.safe_load(value) if value else ""
        except (yaml.YAMLError, RecursionError) as exc:
            raise UsageError("--set %s: not a plain YAML value: %s" % (key, str(exc).splitlines()[0]))
    return out


def _legacy(pairs: Optional[List[str]], defs: Dict[str, ModuleDefinition]) -> Dict[str, str]:
    """``--legacy MODULE=/node``: the node of an original module not named ``/<module>``."""
    out = {}
    for pair in pairs or []:
        module, sep, node = pair.partition("=")
        if not sep or not module or not node:
            raise UsageError("--legacy takes MODULE=/node, got %r" % pair)
        if module not in defs:
            raise UsageError("--legacy names module %r, which has no definition (give it with --modules)" % module)
        out[module] = node if node.startswith("/") else "/" + node
    return out


# check / render --------------------------------------------------------------------------
def cmd_check(args: argparse.Namespace) -> int:
    from coordinator.language import load_tree

    defs = _definitions(args.modules)
    problems = warned = 0
    for path in args.trees:
        try:
            tree = load_tree(path, defs)
        except TreeErrors as exc:
            problems += len(exc.errors)
            _err(str(exc))
            continue
        for w in tree.warnings:
            _err(str(w))
        warned += len(tree.warnings)
        print("%s: ok%s" % (path, " (%d warning%s)" % (len(tree.warnings), "s" if len(tree.warnings) > 1 else "")
                                  if tree.warnings else ""))
    return EXIT_INVALID if problems or (args.strict and warned) else EXIT_OK


def cmd_schema(args: argparse.Namespace) -> int:
    import json

    from coordinator.schema import json_schema, markdown_tables, replace_tables

    if args.write and not args.markdown:
        raise UsageError("--write goes with --markdown")
    if not args.markdown:
        print(json.dumps(json_schema(), indent=2, ensure_ascii=False))
    elif args.write:
        with open(args.write, encoding="utf-8") as fh:
            text = fh.read()
        new = replace_tables(text)
        if new != text:
            with open(args.write, "w", encoding="utf-8") as fh:
                fh.write(new)
        print("%s: %s" % (args.write, "updated" if new != text else "up to date"))
    else:
        sys.stdout.write(markdown_tables())
    return EXIT_OK


def offline_tree(path: str, defs: Dict[str, ModuleDefinition]) -> Any:
    """Validate and build with no ROS at all (for render and tests)."""
    from coordinator.builder import build
    from coordinator.clock import RealClock
    from coordinator.context import RunContext
    from coordinator.language import load_tree
    from coordinator.transport import NullTransport

    tree = load_tree(path, defs)
    return tree, build(tree.root, RunContext(NullTransport(), RealClock(), defs))


def cmd_render(args: argparse.Namespace) -> int:
    import py_trees

    out = args.output
    fmt = os.path.splitext(out)[1].lstrip(".").lower()
    if fmt not in ("dot", "svg", "png"):
        raise UsageError("-o must end in .dot, .svg or .png, got %r" % out)
    tree, root = offline_tree(args.tree, _definitions(args.modules))
    graph = py_trees.display.dot_tree(root, collapse_decorators=False)
    graph.set_name(tree.name)
    if fmt == "dot":
        graph.write(out, format="raw")
    else:
        try:
            graph.write(out, format=fmt)
        except (OSError, FileNotFoundError) as exc:
            _err("cannot render %s: %s (is graphviz installed? 'make setup' installs it)" % (fmt, exc))
            return EXIT_ENV
    print("wrote %s" % out)
    return EXIT_OK


# modules ---------------------------------------------------------------------------------
def _print_module(d: ModuleDefinition, where: str) -> None:
    print("%s  (%s)" % (d.name, where))
    if d.brief:
        print("    %s" % d.brief)
    for fn in d.functions.values():
        ins = ", ".join("%s: %s" % (p.name, p.rostype) for p in fn.inputs)
        outs = ", ".join("%s: %s" % (p.name, p.rostype) for p in fn.outputs)
        print("    %s(%s) -> %s%s" % (fn.name, ins, outs or "()", "   [concurrent]" if fn.concurrent else ""))
    for ev in d.events.values():
        print("    event %s(%s)" % (ev.name, ", ".join("%s: %s" % (p.name, p.rostype) for p in ev.params)))


def cmd_modules(args: argparse.Namespace) -> int:
    if args.live:
        from modules.discovery import live_modules

        if not _master_up(args.wait):
            _err("error: no ROS master at %s" % os.environ.get("ROS_MASTER_URI", "http://localhost:11311/"))
            return EXIT_ENV
        live = live_modules()
        if not live:
            print("no modules running on %s" % os.environ.get("ROS_MASTER_URI", "?"))
        for m in live.values():
            _print_module(m.definition, "node %s%s" % (m.node, ", original module" if m.legacy else ""))
        return EXIT_OK
    defs = load_definitions(args.paths) if args.paths else _definitions(None)
    for d in defs.values():
        _print_module(d, os.path.relpath(d.source) if d.source else "?")
    return EXIT_OK


# run / demo ------------------------------------------------------------------------------
def _master_up(timeout: float) -> bool:
    import time

    import rosgraph

    end = time.monotonic() + timeout
    while True:
        if rosgraph.is_master_online():
            return True
        if time.monotonic() >= end:
            return False
        time.sleep(0.2)


def _report(result: Any, tree_name: str) -> None:
    print()
    print("%s: %s in %.2f s (%d ticks)" % (tree_name, result.status.value, result.duration, result.ticks))
    if result.reason and not result.succeeded:
        print("reason: %s" % result.reason)
    print("calls:")
    start = result.calls[0].started if result.calls else 0.0
    for c in result.calls:
        dur = "%.3fs" % c.duration if c.duration is not None else "-"
        print("  +%7.3fs  %-26s %-10s %8s  %s" % (c.started - start, c.target, c.status, dur, c.error))


def _check_given(tree: Any, given: Dict[str, Any], path: str) -> None:
    """Print the tree's warnings; ``--set`` keys must be inputs the tree declares (a typo would
    silently use the default) and every required input must be given."""
    for w in tree.warnings:
        _err(str(w))
    for key in sorted(given):
        if key not in tree.inputs:
            raise UsageError("%s declares no input %r%s (its inputs: %s)" % (
                path, key, did_you_mean(key, tree.inputs), ", ".join(sorted(tree.inputs)) or "none"))
    missing = sorted(tree.required_inputs - set(given))
    if missing:
        raise UsageError("%s needs the input%s %s: give them with --set KEY=VALUE" % (
            path, "s" if len(missing) > 1 else "", ", ".join(missing)))


def _needs_live_definitions(exc: TreeErrors) -> bool:
    """True if the tree may still be valid once the live modules' definitions are known."""
    return any(e.message.startswith("unknown module") for e in exc.errors)


def _wait_master(timeout: float) -> bool:
    """Wait for the master, saying at once that it is not there yet and for how long bmtree waits."""
    if _master_up(0.0):
        return True
    _err("no ROS master at %s yet; waiting up to %g s (--wait) ..." % (
        os.environ.get("ROS_MASTER_URI", "http://localhost:11311/"), timeout))
    return _master_up(timeout)


def cmd_run(args: argparse.Namespace) -> int:
    from coordinator.builder import build_tree
    from coordinator.clock import RealClock
    from coordinator.context import RunContext
    from coordinator.language import load_tree, used_modules
    from coordinator.runlog import plan_run_files
    from coordinator.runner import Display, TreeRunner

    given = _given(args.set)
    defs = _definitions(args.modules)
    user_modules = [_user_module(spec) for spec in (getattr(args, "module", None) or [])]
    if user_modules and not args.sim:
        raise UsageError("--module starts your module beside the simulated robot: it needs --sim "
                         "(without --sim, start it with bmtree-module and run against the live graph)")
    for um in user_modules:
        defs[um.definition.name] = um.definition
    tree = None
    try:  # validate before anything waits: a typo is exit 2 at once, not after --wait seconds
        tree = load_tree(args.tree, defs, given=set(given))
    except TreeErrors as exc:
        if args.sim or not _needs_live_definitions(exc):
            raise
    if tree is not None:
        _check_given(tree, given, args.tree)
    files = plan_run_files(args.tree, args.record, args.no_record, args.keep_runs)
    graph = None
    transport = None
    previous = signal.getsignal(signal.SIGTERM)

    def on_term(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)
    try:
        if not args.sim:
            if not _wait_master(args.wait):
                _err("error: no ROS master at %s after %g s (start one, or use --sim)" % (os.environ.get(
                    "ROS_MASTER_URI", "http://localhost:11311/"), args.wait))
                return EXIT_ENV
            if tree is None:  # modules known only to the live graph
                from modules.discovery import announced_modules

                for name, live in announced_modules().items():  # liveness: the preflight pings them
                    defs.setdefault(name, live.definition)
                tree = load_tree(args.tree, defs, given=set(given))
                _check_given(tree, given, args.tree)
        assert tree is not None
        legacy = _legacy(getattr(args, "legacy", None), defs)
        mods, recall = used_modules(tree)
        if args.sim:
            from coordinator.simgraph import SIM_MODULES, ModuleStartError, start_sim

            mine = {um.definition.name for um in user_modules}
            sim = [m for m in SIM_MODULES if m not in mine]
            absent = sorted(set(mods) - set(sim) - mine)
            if absent:
                raise UsageError("%s uses %s, which --sim does not start (it starts %s): add --module %s.json=FILE.py:CLASS"
                                 % (args.tree, ", ".join(absent), ", ".join(SIM_MODULES), absent[0]))
            print("starting the simulated robot (private rosmaster, Blackboard, %s)..." % ", ".join(
                sim + ["%s (yours)" % m for m in sorted(mine)]))
            sys.stdout.flush()
            print("its Blackboard store and module logs go to %s" % files.sim_dir)
            try:
                graph = start_sim(world=args.world, ros_home=files.sim_dir, modules=sim, user_modules=user_modules,
                                  address=args.ros_ip)
            except ModuleStartError as exc:
                _err("error: %s" % exc)
                return EXIT_INVALID if exc.code == EXIT_INVALID else EXIT_ENV
            graph.adopt()  # loopback: the private graph works whatever the hostname
            print("simulated robot up, master at %s" % graph.uri)
        from coordinator.ros_transport import RosTransport, address_problem

        hint = address_problem()
        if hint:
            _err("warning: %s" % hint)
        transport = RosTransport(max_bytes=args.max_bytes, liveness=args.liveness)
        stream_sink = transport.stream_sink()
        try:
            transport.wait_ready(mods, args.wait, defs, blackboard=recall, legacy=legacy)
        except OSError as exc:
            _err("error: %s" % exc)
            return EXIT_ENV
        stream_sink.settle()
        ctx = RunContext(transport, RealClock(), defs, default_timeout=args.call_timeout)
        root = build_tree(tree, ctx, given)
        from coordinator.watch import run_view

        view, sinks = run_view(transport, args.quiet)
        display = None if args.quiet or view is not None else Display()
        print("running %s" % tree.name)
        recorder = files.recorder([stream_sink] + sinks, given, args.max_duration, args.world if args.sim else None)
        from coordinator.control import ros_controller

        steer = ros_controller(getattr(args, "control", False))
        try:
            result = TreeRunner(root, ctx, period=args.period, display=display, observers=[recorder, steer],
                                tree=tree, gate=steer).run(args.max_duration)
        finally:
            if view is not None:
                view.stop()
        _report(result, tree.name)
        files.report(print)
        return EXIT_OK if result.succeeded else EXIT_FAILED
    except KeyboardInterrupt:
        _err("interrupted: running calls were cancelled")
        return EXIT_ENV
    finally:
        signal.signal(signal.SIGTERM, previous)
        if transport is not None:
            transport.close()
            try:
                import rospy

                rospy.signal_shutdown("bmtree run finished")
            except Exception:
                pass
        if graph is not None:
            graph.close()


def _user_module(spec: str) -> Any:
    """``DEFINITION.json=FILE.py:CLASS`` (or ``=package.module:Class``) for ``run --sim --module``."""
    from coordinator.simgraph import UserModule
    from modules.definition import load_definition

    definition, sep, cls = spec.partition("=")
    if not sep or not definition or ":" not in cls:
        raise UsageError("--module takes DEFINITION.json=FILE.py:CLASS, got %r" % spec)
    where = cls.rsplit(":", 1)[0]
    if where.endswith(".py"):
        if not os.path.isfile(where):
            raise UsageError("--module %s: no such file %s" % (spec, where))
        with open(where, "rb") as fh:
            source = fh.read()
        try:  # compiled, never run here: a syntax error is one line before the graph starts
            compile(source, where, "exec", dont_inherit=True)
        except SyntaxError as exc:
            raise _Plain("%s:%s:%s: syntax error: %s" % (where, exc.lineno, exc.offset or 0, exc.msg))
        cls = os.path.abspath(where) + ":" + cls.rsplit(":", 1)[1]
    return UserModule(os.path.abspath(definition), cls, load_definition(definition))


def cmd_demo(args: argparse.Namespace) -> int:
    args.tree, args.sim = DEMO_TREE, True
    return cmd_run(args)


# blackboard ------------------------------------------------------------------------------
def cmd_blackboard(args: argparse.Namespace) -> int:
    import datetime
    import sqlite3

    from blackboard.store import Store, default_db_path

    path = args.db or default_db_path()
    if path != ":memory:" and not os.path.exists(path):
        _err("error: no Blackboard store at %s" % path)
        return EXIT_ENV
    try:
        store = Store(path)
    except sqlite3.DatabaseError as exc:
        raise UsageError("%s is not a Blackboard store (%s)" % (path, exc))
    try:
        if args.name:
            try:
                values = store.latest(args.name, args.history)
            except ValueError as exc:
                raise UsageError(str(exc))
            if not values:
                known = [n for n, _count, _stamp in store.names()]
                _err("error: the Blackboard store %s has no value named %r%s" % (path, args.name,
                                                                                did_you_mean(args.name, known)))
                return EXIT_FAILED
            print("%-26s %-10s %-20s %-22s %s" % ("time", "call_id", "module.function", "type", "value"))
            for v in values:
                t = datetime.datetime.fromtimestamp(v.stamp).isoformat(sep=" ", timespec="milliseconds")
                print("%-26s %-10s %-20s %-22s %s" % (t, (v.call_id or "-")[:10], "%s.%s" % (v.basic_mod, v.function),
                                                       v.rostype, v.msg))
            return EXIT_OK
        print("%-24s %6s  %-22s %s" % ("name", "count", "type", "latest value"))
        for name, count, _stamp in store.names():
            latest = store.latest(name)[0]
            print("%-24s %6d  %-22s %s" % (name, count, latest.rostype, latest.msg))
        return EXIT_OK
    finally:
        store.close()


def cmd_test(args: argparse.Namespace) -> int:
    from coordinator.testing.scenario import run_scenarios

    return run_scenarios(args.scenarios, modules=args.modules)


def cmd_runs(args: argparse.Namespace) -> int:
    from coordinator.replay import cmd_runs as runs

    return runs(args)


def cmd_replay(args: argparse.Namespace) -> int:
    from coordinator.replay import cmd_replay as replay

    if args.web:
        from coordinator.webview import cmd_replay_web

        return cmd_replay_web(args)
    return replay(args)


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bmtree", description="Behaviour-tree task coordinator for basic-module robots.")
    p.add_argument("--version", action="version", version="bmtree %s" % __version__)
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    def with_modules(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--modules", action="append", metavar="PATH",
                        help="more module definitions, file or directory (repeatable; added to the simulated "
                             "robot's, the ROS packages' on $ROS_PACKAGE_PATH and $BMTREE_MODULE_PATH)")

    def run_options(sp: argparse.ArgumentParser) -> None:
        with_modules(sp)
        sp.add_argument("--world", help="world file for --sim (default: the shipped house)")
        sp.add_argument("--ros-ip", default="", metavar="ADDR",
                        help="with --sim: the address the private graph listens on (default 127.0.0.1, loopback "
                             "only; give this machine's address to let other machines in: ROS 1 has no "
                             "authentication)")
        sp.add_argument("--set", action="append", metavar="KEY=VALUE", help="set a tree input (YAML value)")
        sp.add_argument("--call-timeout", type=float, default=30.0, help="default timeout of a call (s)")
        sp.add_argument("--period", type=float, default=0.25, help="longest time between ticks (s)")
        sp.add_argument("--max-duration", type=float, help="stop the task after this many seconds")
        sp.add_argument("--wait", type=float, default=10.0, help="how long to wait for the master and modules (s)")
        sp.add_argument("--max-bytes", type=int, default=1 << 20, help="largest payload accepted (bytes)")
        sp.add_argument("--liveness", type=float, default=0.25, metavar="SECONDS",
                        help="how often the nodes owing answers are checked; a dead module's calls fail as "
                             "module_lost about this long after it died (0: off, calls wait their timeout)")
        sp.add_argument("-q", "--quiet", action="store_true", help="no live tree display")
        sp.add_argument("--record", metavar="PATH", help="write the run log to PATH (default: a new file under "
                                                         "$ROS_HOME/bmtree/runs/)")
        sp.add_argument("--no-record", action="store_true", help="write no run log")
        sp.add_argument("--keep-runs", type=int, default=None, metavar="N",
                        help="keep the newest N runs under $ROS_HOME/bmtree/runs/ (default $BMTREE_KEEP_RUNS or 50)")

    d = sub.add_parser("demo", help="run find_apple on the simulated robot (private master)")
    run_options(d)
    d.set_defaults(func=cmd_demo, command_parser=d)
    r = sub.add_parser("run", help="run a tree against the live modules (or --sim)")
    r.add_argument("tree")
    r.add_argument("--sim", action="store_true", help="bring up a private simulated robot for this run")
    r.add_argument("--module", action="append", metavar="DEF.json=FILE.py:CLASS",
                   help="with --sim: start your module beside the simulated ones (repeatable; replaces a "
                        "simulated module of the same name)")
    r.add_argument("--legacy", action="append", metavar="MODULE=/NODE",
                   help="the node of an original module whose node is not named /MODULE (repeatable)")
    r.add_argument("--control", action="store_true", help="let 'bmtree watch' and 'bmtree control' steer this run "
                   "(pause, step, breakpoints, forced outcomes, blackboard writes; ROS 1 has no authentication)")
    run_options(r)
    r.set_defaults(func=cmd_run, command_parser=r)
    c = sub.add_parser("check", help="validate trees without running them")
    c.add_argument("trees", nargs="+")
    c.add_argument("--strict", action="store_true", help="warnings are errors (exit 2)")
    with_modules(c)
    c.set_defaults(func=cmd_check)
    sc = sub.add_parser("schema", help="the JSON Schema of tree files, or the language reference's kind tables")
    sc.add_argument("--markdown", action="store_true", help="the kind tables of trees/README.md instead")
    sc.add_argument("--write", metavar="README", help="with --markdown: replace the tables in this file")
    sc.set_defaults(func=cmd_schema)
    rd = sub.add_parser("render", help="draw a tree as dot, svg or png")
    rd.add_argument("tree")
    rd.add_argument("-o", "--output", required=True)
    with_modules(rd)
    rd.set_defaults(func=cmd_render)
    m = sub.add_parser("modules", help="list module definitions, or the modules running now (--live)")
    m.add_argument("paths", nargs="*")
    m.add_argument("--live", action="store_true", help="the modules running now on $ROS_MASTER_URI")
    m.add_argument("--wait", type=float, default=2.0, help="how long to wait for the master with --live (s)")
    m.set_defaults(func=cmd_modules)
    b = sub.add_parser("blackboard", help="inspect the Blackboard node's store offline")
    bsub = b.add_subparsers(dest="bb_command", metavar="ACTION")
    bsub.required = True
    dump = bsub.add_parser("dump", help="latest value of every name, or the history of one")
    dump.add_argument("--db", help="store file (default $ROS_HOME/bmtree/blackboard.sqlite)")
    dump.add_argument("--name", help="show the history of this name (or module/function/name)")
    dump.add_argument("--history", type=int, default=20, help="how many values of --name")
    dump.set_defaults(func=cmd_blackboard)
    t = sub.add_parser("test", help="run YAML test scenarios against mocked modules")
    t.add_argument("scenarios", nargs="+")
    with_modules(t)
    t.set_defaults(func=cmd_test)
    rs = sub.add_parser("runs", help="list recorded runs (newest first)")
    rs.add_argument("--dir", help="where the run logs are (default $ROS_HOME/bmtree/runs)")
    rs.add_argument("-n", "--limit", type=int, default=0, help="only the newest N")
    rs.set_defaults(func=cmd_runs)
    rp = sub.add_parser("replay", help="show a recorded run again, or turn it into a test scenario")
    rp.add_argument("run", help="a run log file, 'last', its number in 'bmtree runs', or the start of its name")
    rp.add_argument("--dir", help="where the run logs are (default $ROS_HOME/bmtree/runs)")
    how = rp.add_mutually_exclusive_group()
    how.add_argument("--at", type=float, metavar="SECONDS", help="the tree, blackboard and calls at that moment")
    how.add_argument("--step", action="store_true", help="tick by tick (Enter for the next one on a terminal)")
    how.add_argument("--failure", action="store_true", help="jump to the first failing leaf")
    how.add_argument("--scenario", metavar="OUT.yaml", help="write a 'bmtree test' scenario that replays this run")
    rp.add_argument("--speed", type=float, metavar="X", help="play at X times the recorded pace (on a terminal "
                                                             "redrawn in place, like the live display)")
    how.add_argument("--web", action="store_true", help="serve the run as a page with a timeline to scrub")
    rp.add_argument("--bind", default="127.0.0.1", help="address of the page with --web (default loopback)")
    rp.add_argument("--port", type=int, default=8765, help="port of the page with --web (0: any free one)")
    rp.set_defaults(func=cmd_replay)
    from coordinator.watch import add_control_parser, add_watch_parser

    add_watch_parser(sub)
    add_control_parser(sub)
    return p


_RUNS_A_TREE = ("run", "demo", "test")  # a closed output interrupted these: exit 3


def main(argv: Optional[List[str]] = None) -> int:
    # progress lines ("running …", the line-per-change view) must reach a pipe as they happen
    reconfigure = getattr(sys.stdout, "reconfigure", None)
    if reconfigure is not None:
        reconfigure(line_buffering=True)
    parser = make_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    plain = myargv(argv)  # under roslaunch: __name:=, __log:= and _param:= arguments
    try:
        args = parser.parse_args(plain)
        if len(plain) != len(argv) and getattr(args, "command_parser", None) is not None:
            params = node_params(argv, None)
            if private_namespace(argv, "") == "/bmtree/":  # a node named /bmtree: skip the module announcements
                params.pop("modules", None)
            fill_from_params(args.command_parser, args, plain[plain.index(args.command) + 1:], params)
    except SystemExit as exc:
        return EXIT_INVALID if exc.code not in (0, None) else EXIT_OK
    try:
        return args.func(args)
    except (TreeErrors, DefinitionError) as exc:  # each line already starts with where the problem is
        _err(str(exc))
        return EXIT_INVALID
    except _Plain as exc:
        _err(str(exc))
        return EXIT_INVALID
    except InvalidInput as exc:
        _err("error: %s" % exc)
        return EXIT_INVALID
    except BrokenPipeError:  # the reader went away (`bmtree replay last | head`): not bmtree's error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # nothing more to flush at exit
        if args.command in _RUNS_A_TREE:
            _err("stopped: the output was closed")
            return EXIT_ENV
        return EXIT_OK
    except (EnvironmentProblem, OSError) as exc:
        _err("error: %s" % exc)
        return EXIT_ENV
    except KeyboardInterrupt:
        _err("interrupted")
        return EXIT_ENV
