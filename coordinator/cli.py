"""The ``bmtree`` command (DESIGN §5). Exit codes: 0 success, 1 task failed, 2 invalid input, 3 environment."""
from __future__ import annotations

import argparse
import os
import sys
from typing import Any, Dict, List, Optional, Set

from comm.errors import did_you_mean
from comm.messages import MIN_MAX_BYTES
from comm.nodeopts import PORT, fill_from_params, myargv, node_params, private_namespace
from comm.textfile import read_text
from coordinator import __version__
from coordinator.checkcmd import cmd_check
from coordinator.cliutil import (
    EXIT_ENV,
    EXIT_FAILED,
    EXIT_INVALID,
    EXIT_OK,
    PlainError,
    bind_address,
    count,
    definitions_from,
    err,
    factor,
    master_up,
    path_arg,
    seconds,
    text,
)
from coordinator.errors import EnvironmentProblem, InvalidInput, TreeErrors, UsageError
from coordinator.runcmd import cmd_demo, cmd_run
from modules.definition import DefinitionError, ModuleDefinition, load_definitions

__all__ = ["main", "make_parser", "EXIT_OK", "EXIT_FAILED", "EXIT_INVALID", "EXIT_ENV"]


# check / render --------------------------------------------------------------------------
def cmd_schema(args: argparse.Namespace) -> int:
    import json

    from coordinator.schema import json_schema, markdown_tables, replace_tables

    if args.write and not args.markdown:
        raise UsageError("--write goes with --markdown")
    if not args.markdown:
        print(json.dumps(json_schema(), indent=2, ensure_ascii=False))
    elif args.write:
        reference = "it should be the language reference, trees/README.md"
        try:   # bounded, devices refused (/dev/full reads zeros for ever), a folder is EISDIR
            text = read_text(args.write)
        except OSError as exc:
            raise UsageError("--write %s: cannot read it: %s; %s" % (args.write, exc.strerror or exc, reference))
        except UnicodeDecodeError as exc:
            raise UsageError("--write %s: not UTF-8 text (byte %d); %s" % (args.write, exc.start, reference))
        new = replace_tables(text)
        if new != text:
            _replace_file(args.write, new)
        print("%s: %s" % (args.write, "updated" if new != text else "up to date"))
    else:
        sys.stdout.write(markdown_tables())
    return EXIT_OK


def _replace_file(path: str, text: str) -> None:
    """``path`` (through a symlink) made ``text`` whole or not at all: written beside it, then renamed over
    it (a full disk leaves the old file); an unwritable one is a bad argument, as ``render -o`` says."""
    import tempfile

    target = os.path.realpath(path)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=".%s." % os.path.basename(target), dir=os.path.dirname(target))
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.chmod(tmp, os.stat(target).st_mode & 0o7777)
        os.replace(tmp, target)
    except OSError as exc:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
        raise UsageError("--write %s: cannot write it: %s (the file is unchanged)" % (path, exc.strerror or exc))


def offline_tree(path: str, defs: Dict[str, ModuleDefinition]) -> Any:
    """Validate and build with no ROS at all (for render and tests)."""
    from coordinator.builder import build
    from coordinator.clock import RealClock
    from coordinator.context import RunContext
    from coordinator.language import load_tree
    from coordinator.transport import NullTransport
    from coordinator.treeast import top_of

    tree = load_tree(path, defs)
    return tree, build(top_of(tree), RunContext(NullTransport(), RealClock(), defs))


def _label_cases(root: Any) -> Set[str]:
    """Name each case of a switch after its value (``'yes' → answered yes``, ``default → …``): the
    rendering shows which child runs when; the names of the switches."""
    from coordinator.nodes.switch import Switch

    names = set()
    for b in root.iterate():
        if isinstance(b, Switch):
            names.add(b.name)
            labels = ["%r" % (lab,) for lab in b.spec.labels] + (["default"] if b.spec.has_default else [])
            for label, child in zip(labels, b.children):
                child.name = "%s → %s" % (label, child.name)  # not ':', graphviz's port separator
    return names


def cmd_render(args: argparse.Namespace) -> int:
    out = args.output
    fmt = os.path.splitext(out)[1].lstrip(".").lower()
    if fmt not in ("dot", "svg", "png"):
        raise UsageError("-o must end in .dot, .svg or .png, got %r" % out)
    tree, root = offline_tree(args.tree, definitions_from(args.modules))
    folder = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(folder):
        raise UsageError("-o %s: folder %s does not exist" % (out, folder))
    from coordinator.render import tree_graph

    graph = tree_graph(tree.name, root, _label_cases(root))
    if fmt == "dot":
        graph.write(out, format="raw")
    else:
        try:
            graph.write(out, format=fmt)
        except OSError as exc:
            if not os.access(folder, os.W_OK):
                raise UsageError("-o %s: cannot write in %s" % (out, folder))
            err("cannot render %s: %s (is graphviz installed? 'make setup' installs it)" % (fmt, exc))
            return EXIT_ENV
    print("wrote %s" % out)
    return EXIT_OK


# modules ---------------------------------------------------------------------------------
def _print_module(d: ModuleDefinition, where: str, at: str = "") -> None:
    print("%s  (%s)" % (d.name, where))
    if at:
        print("    at %s" % at)
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
        from comm.address import node_address_problem, warn_own_address
        from modules.discovery import listed_modules

        if not master_up(args.wait):
            err("error: no ROS master at %s" % os.environ.get("ROS_MASTER_URI", "http://localhost:11311/"))
            return EXIT_ENV
        warn_own_address()
        live, unreachable = listed_modules()
        if not live and not unreachable:
            print("no modules running on %s" % os.environ.get("ROS_MASTER_URI", "?"))
        for m in live.values():
            _print_module(m.definition, "node %s%s" % (m.node, ", original module" if m.legacy else ""), m.uri)
            why = node_address_problem(m.node, m.uri, "")  # answers here, but not the others (loopback)
            if why:
                print("    warning: %s" % why)
            if m.not_ready:
                print("    warning: not ready: %s" % m.not_ready)
        for name, (m, why) in unreachable.items():  # it runs, but its address cannot be reached from here
            print("%s  (node %s, unreachable)\n    %s" % (name, m.node, why))
        return EXIT_OK
    defs = load_definitions(args.paths) if args.paths else definitions_from(None)
    for d in defs.values():
        _print_module(d, _shown_path(d.source) if d.source else "?")
    return EXIT_OK


def _shown_path(path: str) -> str:
    """A path as short as it can be said: relative below the working directory, else absolute."""
    rel = os.path.relpath(path)
    return os.path.abspath(path) if rel.startswith(os.pardir) else rel


# blackboard ------------------------------------------------------------------------------
def cmd_blackboard(args: argparse.Namespace) -> int:
    import datetime
    import sqlite3

    from blackboard.store import Store, default_db_path, shown_name

    path = args.db or default_db_path()
    if not os.path.exists(path):
        err("error: no Blackboard store at %s" % path)
        return EXIT_ENV
    if not os.path.isfile(path):
        raise UsageError("%s is not a Blackboard store (not a file)" % path)
    try:
        store = Store.read_only(path)
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
                err("error: the Blackboard store %s has no value named %r%s" % (path, args.name,
                                                                                did_you_mean(args.name, known)))
                return EXIT_FAILED
            print("%-26s %-10s %-20s %-22s %s" % ("time", "call_id", "module.function", "type", "value"))
            for v in values:
                try:
                    t = datetime.datetime.fromtimestamp(v.stamp).isoformat(sep=" ", timespec="milliseconds")
                except (TypeError, ValueError, OverflowError, OSError):  # an old or foreign store's row
                    t = str(v.stamp)
                print("%-26s %-10s %-20s %-22s %s" % (t, (v.call_id or "-")[:10], "%s.%s" % (v.basic_mod, v.function),
                                                       v.rostype, v.msg))
            return EXIT_OK
        print("%-24s %6s  %-22s %s" % ("name", "count", "type", "latest value"))
        for name, count, latest in store.latest_each():  # each name as stored: an old store may hold ''
            print("%-24s %6d  %-22s %s" % (shown_name(name), count, latest.rostype, latest.msg))
        return EXIT_OK
    finally:
        store.close()


def cmd_test(args: argparse.Namespace) -> int:
    from coordinator.testing.scenario import run_scenarios

    return run_scenarios(args.scenarios, modules=args.modules, coverage=args.coverage)


def _runs_dir(args: argparse.Namespace) -> None:
    """``--dir`` given names a folder (a typo is no "no recorded runs", exit 0); the default one may not
    exist yet (nothing recorded). ``$BMTREE_MAX_LOG_MB``, read with the logs, is checked first."""
    from coordinator.runlog import max_log_bytes

    max_log_bytes()
    if args.dir is not None and not os.path.isdir(args.dir):
        raise UsageError("--dir %s: %s" % (args.dir, "not a folder" if os.path.exists(args.dir) else
                                            "no such folder (the default is $ROS_HOME/bmtree/runs)"))


def cmd_runs(args: argparse.Namespace) -> int:
    from coordinator.replay import cmd_runs as runs

    _runs_dir(args)
    return runs(args)


def cmd_replay(args: argparse.Namespace) -> int:
    from coordinator.replay import cmd_replay as replay

    _runs_dir(args)

    if args.web:
        from coordinator.webview import cmd_replay_web

        return cmd_replay_web(args)
    return replay(args)


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bmtree", description="Behaviour-tree task coordinator for basic-module robots.")
    p.add_argument("--version", action="version", version="bmtree %s" % __version__)
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    def with_modules(sp: argparse.ArgumentParser, more: str = "") -> None:
        sp.add_argument("--modules", action="append", metavar="PATH", type=path_arg("a definition file or folder"),
                        help="more module definitions, file or directory (repeatable; added to the simulated "
                             "robot's, the ROS packages' on $ROS_PACKAGE_PATH and $BMTREE_MODULE_PATH)" + more)

    def run_options(sp: argparse.ArgumentParser) -> None:
        with_modules(sp)
        sp.add_argument("--world", type=path_arg("a world file"), help="world file for --sim (default: the shipped house)")
        sp.add_argument("--ros-ip", type=text("an IPv4 address of this machine"), metavar="ADDR",
                        help="with --sim: the address the private graph listens on (default 127.0.0.1, loopback "
                             "only; give this machine's address to let other machines in: ROS 1 has no "
                             "authentication)")
        sp.add_argument("--port", type=count(1, "a TCP port", 65535), metavar="PORT",
                        help="with --sim: the private master's port (default: a free one), so that a watch can be "
                             "started before the run (ROS_MASTER_URI=http://127.0.0.1:PORT/ bmtree watch --follow)")
        sp.add_argument("--set", action="append", metavar="KEY=VALUE", help="set a tree input (YAML value)")
        sp.add_argument("--call-timeout", type=seconds(), default=30.0, help="default timeout of a call (s)")
        sp.add_argument("--period", type=seconds(), default=0.25, help="longest time between ticks (s)")
        sp.add_argument("--max-duration", type=seconds("no limit"),
                        help="stop the task after this many seconds (0: no limit, the default)")
        sp.add_argument("--wait", type=seconds("do not wait"), default=10.0,
                        help="how long to wait for the master and modules (s)")
        sp.add_argument("--max-bytes", type=count(MIN_MAX_BYTES, what="a ping's answer must fit"), default=1 << 20, help="largest payload accepted (bytes)")
        sp.add_argument("--liveness", type=seconds("off"), default=0.25, metavar="SECONDS",
                        help="how often the nodes owing answers, or events a wait_event waits for, are checked; "
                             "a dead module's calls and waits fail (module_lost) about this long after it died "
                             "(0: off, calls wait their timeout)")
        sp.add_argument("-q", "--quiet", action="store_true", help="no live tree display")
        sp.add_argument("--record", metavar="PATH", type=path_arg("a run log file"), help="write the run log to PATH (default: a new file under "
                                                         "$ROS_HOME/bmtree/runs/)")
        sp.add_argument("--no-record", action="store_true", help="write no run log")
        sp.add_argument("--keep-runs", type=count(), default=None, metavar="N",
                        help="keep the newest N runs under $ROS_HOME/bmtree/runs/ (default $BMTREE_KEEP_RUNS or 50)")

    d = sub.add_parser("demo", help="run find_apple on the simulated robot (private master)")
    run_options(d)
    d.set_defaults(func=cmd_demo, command_parser=d)
    r = sub.add_parser("run", help="run a tree against the live modules (or --sim)")
    r.add_argument("tree", type=path_arg("a tree file"))
    r.add_argument("--sim", action="store_true", help="bring up a private simulated robot for this run")
    r.add_argument("--module", action="append", metavar="DEF.json=FILE.py:CLASS|EXECUTABLE|SCRIPT.yaml",
                   type=text("DEF.json=FILE.py:CLASS, DEF.json=EXECUTABLE or DEF.json=SCRIPT.yaml"),
                   help="with --sim: start your module beside the simulated ones, a Python class, (no ':') a C++ "
                        "module's executable with a bmtree-bridge, or (.yaml) a scripted stand-in for a module not "
                        "written yet (repeatable; replaces a simulated one of its name)")
    r.add_argument("--legacy", action="append", metavar="MODULE=/NODE", type=text("MODULE=/NODE"),
                   help="the node of an original module whose node is not named /MODULE (repeatable)")
    r.add_argument("--control", action="store_true", help="let 'bmtree watch' and 'bmtree control' steer this run "
                   "(pause, step, breakpoints, forced outcomes, blackboard writes; ROS 1 has no authentication)")
    run_options(r)
    r.set_defaults(func=cmd_run, command_parser=r)
    c = sub.add_parser("check", help="validate trees (and module definitions, .json) without running them")
    c.add_argument("trees", nargs="+", type=path_arg("a tree file"))
    c.add_argument("--strict", action="store_true", help="warnings are errors (exit 2)")
    with_modules(c)
    c.set_defaults(func=cmd_check)
    sc = sub.add_parser("schema", help="the JSON Schema of tree files, or the language reference's kind tables")
    sc.add_argument("--markdown", action="store_true", help="the kind tables of trees/README.md instead")
    sc.add_argument("--write", metavar="README", type=path_arg("the language reference"), help="with --markdown: replace the tables in this file")
    sc.set_defaults(func=cmd_schema)
    rd = sub.add_parser("render", help="draw a tree as dot, svg or png")
    rd.add_argument("tree", type=path_arg("a tree file"))
    rd.add_argument("-o", "--output", required=True, type=path_arg("a .dot, .svg or .png file"))
    with_modules(rd)
    rd.set_defaults(func=cmd_render)
    m = sub.add_parser("modules", help="list module definitions, or the modules running now (--live)")
    m.add_argument("paths", nargs="*", type=path_arg("a definition file or folder"))
    m.add_argument("--live", action="store_true", help="the modules running now on $ROS_MASTER_URI")
    m.add_argument("--wait", type=seconds("do not wait"), default=2.0, help="how long to wait for the master with --live (s)")
    m.set_defaults(func=cmd_modules)
    b = sub.add_parser("blackboard", help="inspect the Blackboard node's store offline")
    bsub = b.add_subparsers(dest="bb_command", metavar="ACTION")
    bsub.required = True
    dump = bsub.add_parser("dump", help="latest value of every name, or the history of one")
    dump.add_argument("--db", type=path_arg("a Blackboard store"), help="store file (default $ROS_HOME/bmtree/blackboard.sqlite)")
    dump.add_argument("--name", type=text("a name"), help="show the history of this name (or module/function/name)")
    dump.add_argument("--history", type=count(), default=20, help="how many values of --name")
    dump.set_defaults(func=cmd_blackboard)
    t = sub.add_parser("test", help="run YAML test scenarios against mocked modules",
                       epilog="The scenario file format: docs/scenarios.md (top level: tree, modules, scenarios; "
                              "expect: status, calls (or calls: {in_order: [...]}), blackboard, reason, duration, "
                              "cleanup).")
    t.add_argument("scenarios", nargs="+", metavar="SCENARIO.yaml", type=path_arg("a scenario file"))
    t.add_argument("--coverage", action="store_true",
                   help="then report which nodes of the trees ran and which outcomes they reached")
    with_modules(t, ". Given, it wins: a scenario file's own top-level 'modules:' is then not loaded (only checked)")
    t.set_defaults(func=cmd_test)
    rs = sub.add_parser("runs", help="list recorded runs (newest first)")
    rs.add_argument("--dir", type=path_arg("a folder"), help="where the run logs are (default $ROS_HOME/bmtree/runs)")
    rs.add_argument("-n", "--limit", type=count(0, what="0: all"), default=0, help="only the newest N (0: all)")
    rs.set_defaults(func=cmd_runs)
    rp = sub.add_parser("replay", help="show a recorded run again, or turn it into a test scenario")
    rp.add_argument("run", type=text("a run"), help="a run log file, 'last', its number in 'bmtree runs', or the start of its name")
    rp.add_argument("--dir", type=path_arg("a folder"), help="where the run logs are (default $ROS_HOME/bmtree/runs)")
    how = rp.add_mutually_exclusive_group()
    how.add_argument("--at", type=seconds("the start"), metavar="SECONDS", help="the tree, blackboard and calls at that moment")
    how.add_argument("--step", action="store_true", help="tick by tick (Enter for the next one on a terminal)")
    how.add_argument("--failure", action="store_true", help="jump to the failure the run's reason names (for a run stopped "
                     "from outside: its last tick before the stop): where, why, the failing call's inputs, the "
                     "state after that tick")
    how.add_argument("--scenario", metavar="OUT.yaml", type=path_arg("a scenario file to write"), help="write a 'bmtree test' scenario that replays this run")
    rp.add_argument("--speed", type=factor(), metavar="X", help="play at X times the recorded pace (on a terminal "
                                                             "redrawn in place, like the live display)")
    how.add_argument("--web", action="store_true", help="serve the run as a page with a timeline to scrub")
    rp.add_argument("--bind", type=bind_address, default="127.0.0.1", help="address of the page with --web (default loopback)")
    rp.add_argument("--port", type=PORT, default=8765, help="port of the page with --web (0: any free one)")
    rp.set_defaults(func=cmd_replay)
    from coordinator.btimport import add_import_parser
    from coordinator.watch import add_control_parser, add_watch_parser

    add_watch_parser(sub)
    add_control_parser(sub)
    add_import_parser(sub)
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
        err(str(exc))
        return EXIT_INVALID
    except PlainError as exc:
        err(str(exc))
        return EXIT_INVALID
    except InvalidInput as exc:
        err("error: %s" % exc)
        return EXIT_INVALID
    except BrokenPipeError:  # the reader went away (`bmtree replay last | head`): not bmtree's error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # nothing more to flush at exit
        if args.command in _RUNS_A_TREE:
            err("stopped: the output was closed")
            return EXIT_ENV
        return EXIT_OK
    except (EnvironmentProblem, OSError) as exc:
        err("error: %s" % exc)
        return EXIT_ENV
    except KeyboardInterrupt:
        err("interrupted")
        return EXIT_ENV
