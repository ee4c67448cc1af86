"""The ``bmtree`` command (DESIGN §5). Exit codes: 0 success, 1 task failed, 2 invalid input, 3 environment."""
from __future__ import annotations

import argparse
import os
import signal
import sys
from typing import Any, Dict, List, Optional

import yaml

from coordinator.errors import TreeErrors
from modules.definition import DefinitionError, ModuleDefinition, default_module_paths, load_definitions

__all__ = ["main", "make_parser", "EXIT_OK", "EXIT_FAILED", "EXIT_INVALID", "EXIT_ENV"]

EXIT_OK, EXIT_FAILED, EXIT_INVALID, EXIT_ENV = 0, 1, 2, 3
PROJECT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMO_TREE = os.path.join(PROJECT, "trees", "find_apple.yaml")


class _Usage(Exception):
    pass


def _err(text: str) -> None:
    sys.stderr.write(text.rstrip("\n") + "\n")


def _definitions(paths: Optional[List[str]]) -> Dict[str, ModuleDefinition]:
    return load_definitions(paths or default_module_paths())


def _given(pairs: Optional[List[str]]) -> Dict[str, Any]:
    out = {}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        if not sep or not key.isidentifier():
            raise _Usage("--set takes KEY=VALUE, got %r" % pair)
        out[key] = yaml.safe_load(value) if value else ""
    return out


# check / render --------------------------------------------------------------------------
def cmd_check(args: argparse.Namespace) -> int:
    from coordinator.language import load_tree

    defs = _definitions(args.modules)
    problems = 0
    for path in args.trees:
        try:
            load_tree(path, defs)
            print("%s: ok" % path)
        except TreeErrors as exc:
            problems += len(exc.errors)
            _err(str(exc))
    return EXIT_INVALID if problems else EXIT_OK


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
        raise _Usage("-o must end in .dot, .svg or .png, got %r" % out)
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
            _print_module(m.definition, "node %s" % m.node)
        return EXIT_OK
    defs = _definitions(args.paths)
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


def cmd_run(args: argparse.Namespace) -> int:
    from coordinator.builder import build_tree
    from coordinator.clock import RealClock
    from coordinator.context import RunContext
    from coordinator.language import load_tree, used_modules
    from coordinator.runner import Display, TreeRunner

    given = _given(args.set)
    defs = _definitions(args.modules)
    graph = None
    transport = None
    previous = signal.getsignal(signal.SIGTERM)

    def on_term(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)
    try:
        if not args.sim:
            if not _master_up(args.wait):
                _err("error: no ROS master at %s (start one, or use --sim)" % os.environ.get(
                    "ROS_MASTER_URI", "http://localhost:11311/"))
                return EXIT_ENV
            from modules.discovery import live_modules

            for name, live in live_modules().items():
                defs.setdefault(name, live.definition)
        tree = load_tree(args.tree, defs, given=set(given))
        missing = sorted(tree.required_inputs - set(given))
        if missing:
            raise _Usage("%s needs the input%s %s: give them with --set KEY=VALUE" % (
                args.tree, "s" if len(missing) > 1 else "", ", ".join(missing)))
        mods, recall = used_modules(tree)
        if args.sim:
            from coordinator.simgraph import start_sim

            print("starting the simulated robot (private rosmaster, Blackboard, %s)..." % ", ".join(sorted(mods)))
            sys.stdout.flush()
            graph = start_sim(world=args.world)
            os.environ["ROS_MASTER_URI"] = graph.uri
            print("simulated robot up, master at %s" % graph.uri)
        from coordinator.ros_transport import RosTransport

        transport = RosTransport(max_bytes=args.max_bytes)
        try:
            transport.wait_ready(mods, args.wait, defs, blackboard=recall)
        except OSError as exc:
            _err("error: %s" % exc)
            return EXIT_ENV
        ctx = RunContext(transport, RealClock(), defs, default_timeout=args.call_timeout)
        root = build_tree(tree, ctx, given)
        display = None if args.quiet else Display()
        print("running %s" % tree.name)
        result = TreeRunner(root, ctx, period=args.period, display=display).run(args.max_duration)
        _report(result, tree.name)
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


def cmd_demo(args: argparse.Namespace) -> int:
    args.tree, args.sim = DEMO_TREE, True
    return cmd_run(args)


# blackboard ------------------------------------------------------------------------------
def cmd_blackboard(args: argparse.Namespace) -> int:
    import datetime

    from blackboard.store import Store, default_db_path

    path = args.db or default_db_path()
    if path != ":memory:" and not os.path.exists(path):
        _err("error: no Blackboard store at %s" % path)
        return EXIT_ENV
    store = Store(path)
    try:
        if args.name:
            try:
                values = store.latest(args.name, args.history)
            except ValueError as exc:
                raise _Usage(str(exc))
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


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bmtree", description="Behaviour-tree task coordinator for basic-module robots.")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    def with_modules(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--modules", action="append", metavar="PATH",
                        help="module definition file or directory (repeatable; default: the simulated robot's "
                             "and $BMTREE_MODULE_PATH)")

    def run_options(sp: argparse.ArgumentParser) -> None:
        with_modules(sp)
        sp.add_argument("--world", help="world file for --sim (default: the shipped house)")
        sp.add_argument("--set", action="append", metavar="KEY=VALUE", help="set a tree input (YAML value)")
        sp.add_argument("--call-timeout", type=float, default=30.0, help="default timeout of a call (s)")
        sp.add_argument("--period", type=float, default=0.25, help="longest time between ticks (s)")
        sp.add_argument("--max-duration", type=float, help="stop the task after this many seconds")
        sp.add_argument("--wait", type=float, default=10.0, help="how long to wait for the master and modules (s)")
        sp.add_argument("--max-bytes", type=int, default=1 << 20, help="largest payload accepted (bytes)")
        sp.add_argument("-q", "--quiet", action="store_true", help="no live tree display")

    d = sub.add_parser("demo", help="run find_apple on the simulated robot (private master)")
    run_options(d)
    d.set_defaults(func=cmd_demo)
    r = sub.add_parser("run", help="run a tree against the live modules (or --sim)")
    r.add_argument("tree")
    r.add_argument("--sim", action="store_true", help="bring up a private simulated robot for this run")
    run_options(r)
    r.set_defaults(func=cmd_run)
    c = sub.add_parser("check", help="validate trees without running them")
    c.add_argument("trees", nargs="+")
    with_modules(c)
    c.set_defaults(func=cmd_check)
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
    return p


def main(argv: Optional[List[str]] = None) -> int:
    parser = make_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return EXIT_INVALID if exc.code not in (0, None) else EXIT_OK
    try:
        return args.func(args)
    except DefinitionError as exc:
        _err(str(exc))
        return EXIT_INVALID
    except TreeErrors as exc:
        _err(str(exc))
        return EXIT_INVALID
    except _Usage as exc:
        _err("error: %s" % exc)
        return EXIT_INVALID
    except ValueError as exc:  # e.g. a required tree input not given
        _err("error: %s" % exc)
        return EXIT_INVALID
    except OSError as exc:
        _err("error: %s" % exc)
        return EXIT_ENV
    except KeyboardInterrupt:
        _err("interrupted")
        return EXIT_ENV
