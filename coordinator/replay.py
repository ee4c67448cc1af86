"""``bmtree runs`` and ``bmtree replay``: recorded runs listed, shown again, or made a scenario.

A replay rebuilds the recorded tree's shape as plain py_trees behaviours and applies
the recorded status changes to it, showing them to the live display itself, so it
prints exactly what the live display printed (and, with ``--at``/``--step``/``--failure``, the tree, the tree blackboard
and the calls in flight at a moment). ``--scenario`` writes a ``bmtree test`` file
whose mocks answer as the modules answered (see :mod:`coordinator.scenariogen`).
"""
from __future__ import annotations

import datetime
import json
import os
import sys
import types
from typing import Any, Callable, Dict, List, NamedTuple, Optional, TextIO, Tuple

import py_trees
from py_trees.common import Status

from coordinator.runevents import Notice, RunObserver, control_line
from coordinator.runlog import RunLog, RunLogError, default_runs_dir, list_runs, read_log
from coordinator.runner import Display

__all__ = ["Replay", "find_run", "cmd_runs", "cmd_replay"]


class _Leaf(py_trees.behaviour.Behaviour):
    def update(self) -> Status:
        return self.status


class _Decorator(py_trees.decorators.Decorator):
    def update(self) -> Status:
        return self.status


class _Composite(py_trees.composites.Composite):
    """A recorded composite that is none of py_trees' own: it holds its children, never ticks."""

    def tick(self) -> Any:
        yield self

    def stop(self, new_status: Status = Status.INVALID) -> None:
        self.status = new_status


def _skeleton(nodes: List[Dict[str, Any]]) -> Tuple[Any, Dict[int, Any]]:
    """Behaviours shaped like the recorded tree (for the display), by recorded id."""
    kids: Dict[Any, List[Dict[str, Any]]] = {}
    for n in nodes:
        kids.setdefault(n.get("parent"), []).append(n)
    by_id: Dict[int, Any] = {}

    def make(n: Dict[str, Any], depth: int) -> Any:
        if depth > 200:
            raise RunLogError("the recorded tree is deeper than 200 levels")
        children = [make(c, depth + 1) for c in kids.get(n["id"], [])]
        name, shape = str(n.get("name", "?")), n.get("shape")
        if shape == "sequence":
            b = py_trees.composites.Sequence(name, memory=bool(n.get("memory")), children=children)
        elif shape == "selector":
            b = py_trees.composites.Selector(name, memory=bool(n.get("memory")), children=children)
        elif shape == "parallel":
            b = py_trees.composites.Parallel(name, policy=py_trees.common.ParallelPolicy.SuccessOnAll(),
                                             children=children)
        elif shape == "decorator" and len(children) == 1:
            b = _Decorator(name=name, child=children[0])
        elif children:  # a composite of another shape (switch), or one a newer bmtree wrote
            b = _Composite(name=name, children=children)
        else:
            b = _Leaf(name)
        by_id[n["id"]] = b
        return b

    roots = kids.get(None, [])
    if len(roots) != 1:
        raise RunLogError("the recorded tree has %d roots" % len(roots))
    return make(roots[0], 0), by_id


class Failure(NamedTuple):
    """Where a failure started: its place among the status changes, its tick record, node and message."""

    seq: int
    index: int
    node: int
    message: str
    t: float


class Replay:
    """Steps through a run log, keeping the tree, the tree blackboard and the calls in flight."""

    def __init__(self, log: RunLog):
        self.log = log
        try:
            self.nodes = {int(n["id"]): n for n in log.tree.get("nodes") or []}
            self.root, self.by_id = _skeleton(list(self.nodes.values()))
        except (KeyError, TypeError, ValueError) as exc:
            raise RunLogError("%s:1: the tree record is malformed: %s" % (log.path, exc))
        self.blackboard: Dict[str, Any] = dict(log.tree.get("blackboard") or {})
        self.pending: Dict[str, Dict[str, Any]] = {}
        self.finished: List[Dict[str, Any]] = []
        self.events: List[Dict[str, Any]] = []
        self.control: List[Dict[str, Any]] = []  # the operator's commands (run --control), and breakpoints hit
        self.paused = False
        self.notices: List[Dict[str, Any]] = []  # what happened to the ROS graph (the master went away...)
        self.index = 1
        self.t = 0.0

    def apply(self, rec: Dict[str, Any], display: Optional[RunObserver] = None) -> None:
        """One record; a tick's changes are also shown to ``display`` (the live display)."""
        kind = rec.get("type")
        self.t = float(rec.get("t") or self.t)
        if kind == "tick":
            changes = []
            for change in rec.get("changes") or []:
                b = self.by_id.get(change[0])
                if b is None:
                    continue
                old, new = b.status, Status(change[1])
                b.status = new
                b.feedback_message = change[2] if len(change) > 2 else ""
                # as it was at this change: a retry may restart the leaf in the same tick
                changes.append((types.SimpleNamespace(name=b.name, feedback_message=b.feedback_message), old, new))
            if display is not None:
                display.on_tick(self.root, changes, self.t)
        elif kind == "call_start":
            self.pending[str(rec.get("call_id"))] = rec
        elif kind == "call_end":
            start = self.pending.pop(str(rec.get("call_id")), None)
            self.finished.append(dict(rec, started=(start or {}).get("t", rec.get("t"))))
        elif kind == "write":
            self.blackboard[str(rec.get("key"))] = rec.get("value")
        elif kind == "event":
            self.events.append(rec)
        elif kind == "notice":
            self.notices.append(rec)
            if display is not None:
                display.on_notice(Notice(str(rec.get("what")), str(rec.get("text"))), self.t)
        elif kind == "control":
            self.control.append(rec)
            if "paused" in rec:
                self.paused = bool(rec["paused"])
            if display is not None:
                display.on_control(rec, self.t)

    def next(self, display: Optional[RunObserver] = None) -> Optional[Dict[str, Any]]:
        if self.index >= len(self.log.records):
            return None
        rec = self.log.records[self.index]
        self.index += 1
        try:
            self.apply(rec, display)
        except (TypeError, ValueError, KeyError, IndexError) as exc:
            raise RunLogError("%s: record %d (%s) is malformed: %s" % (self.log.path, self.index, rec.get("type"), exc))
        return rec

    def to_failure(self, f: Failure) -> None:
        """Apply the records up to failure ``f``'s own change: its tick only as far as that change
        (not a retry restarting the failed leaf later in the same tick)."""
        while self.index < f.index and self.next() is not None:
            pass
        before = sum(len(r.get("changes") or []) for r in self.log.records[:f.index] if r.get("type") == "tick")
        rec = self.log.records[f.index]
        self.apply(dict(rec, changes=(rec.get("changes") or [])[:max(0, f.seq - before)]))
        self.index = f.index + 1

    def until(self, stop: Callable[[Dict[str, Any]], bool]) -> bool:
        """Apply records up to and including the first for which ``stop`` is true; False if none is."""
        while True:
            rec = self.next()
            if rec is None:
                return False
            if stop(rec):
                return True

    def failures(self) -> Tuple[Optional[Failure], List[Failure]]:
        """Where failures started, over the whole log (a leaf, or a node failing by itself: a timeout
        that fired): the one that ended the run (None if none did), and those the tree recovered from
        (an ancestor succeeded later: a selector moved on, a retry succeeded), in order."""
        parent = {i: n.get("parent") for i, n in self.nodes.items()}
        kids: Dict[Any, List[int]] = {}
        for i, p in parent.items():
            kids.setdefault(p, []).append(i)
        status: Dict[int, str] = {}
        succeeded: Dict[int, int] = {}
        origins: List[Failure] = []
        seq = 0
        for index, rec in enumerate(self.log.records):
            if rec.get("type") != "tick":
                continue
            for change in rec.get("changes") or []:
                seq += 1
                nid, new = change[0], change[1]
                status[nid] = new
                if new == "SUCCESS":
                    succeeded[nid] = seq
                elif new == "FAILURE" and (not kids.get(nid) or (len(change) > 2 and change[2] and all(
                        status.get(k) != "FAILURE" for k in kids[nid]))):
                    origins.append(Failure(seq, index, nid, change[2] if len(change) > 2 else "failed",
                                           float(rec.get("t") or 0.0)))

        def ancestors(nid: Any) -> List[Any]:
            out = []
            while parent.get(nid) is not None and len(out) < 200:
                nid = parent[nid]
                out.append(nid)
            return out

        recovered = [f for f in origins if any(succeeded.get(a, -1) > f.seq for a in ancestors(f.node))]
        ended = None
        end = self.log.end
        if end is not None and end.get("status") == "FAILURE":
            unrecovered = [f for f in origins if f not in recovered]
            ended = unrecovered[-1] if unrecovered else None
        return ended, recovered

    def snapshot(self, out: TextIO) -> None:
        """The tree, the tree blackboard and the calls in flight now."""
        out.write(py_trees.display.unicode_tree(self.root, show_status=True) + "\n")
        if self.paused:
            out.write("paused by control (%s)\n" % control_line(self.control[-1]))
        out.write("tree blackboard:\n")
        for k in sorted(self.blackboard):
            out.write("  %s = %s\n" % (k, json.dumps(self.blackboard[k], ensure_ascii=False)))
        out.write("calls in flight:%s\n" % ("" if self.pending else " none"))
        for rec in self.pending.values():
            out.write("  %-26s since %.3fs  inputs %s  (node %s)\n" % (
                rec.get("target"), float(rec.get("t") or 0.0), json.dumps(rec.get("inputs"), ensure_ascii=False),
                self._where(rec.get("node"))))

    def _where(self, node_id: Any) -> str:
        n = self.nodes.get(node_id) if isinstance(node_id, int) else None
        if n is None:
            return "?"
        return "'%s' %s:%s" % (n.get("name"), n.get("file", "?"), n.get("line", "?"))


def find_run(ref: str, directory: Optional[str] = None) -> str:
    """A run log by path, ``last``, number in ``bmtree runs`` (1 = newest) or start of its name."""
    if os.path.isfile(ref):
        return ref
    directory = directory or default_runs_dir()
    runs = list_runs(directory)
    if not runs:
        raise RunLogError("no recorded runs in %s" % directory)
    if ref in ("last", "latest"):
        return runs[-1].path
    if ref.isdigit() and len(ref) <= 6:
        k = int(ref)
        if not 1 <= k <= len(runs):
            raise RunLogError("there are %d recorded runs in %s; %s is not one of them" % (len(runs), directory, ref))
        return runs[-k].path
    hits = [r.path for r in runs if os.path.basename(r.path).startswith(ref)]
    if len(hits) != 1:
        raise RunLogError("%s runs in %s start with %r (use the number shown by 'bmtree runs')" % (
            "no" if not hits else "%d" % len(hits), directory, ref))
    return hits[0]


def cmd_runs(args: Any) -> int:
    directory = args.dir or default_runs_dir()
    runs = list_runs(directory)
    if not runs:
        print("no recorded runs in %s" % directory)
        return 0
    print("recorded runs in %s (newest first):" % directory)
    print("%3s  %-19s  %-24s %9s  %-10s %s" % ("#", "start", "tree", "duration", "result", "reason"))
    for k, r in enumerate(reversed(runs[-args.limit:] if args.limit else runs), 1):
        start = datetime.datetime.fromtimestamp(r.started).strftime("%Y-%m-%d %H:%M:%S")
        dur = "%.2fs" % r.duration if isinstance(r.duration, (int, float)) else "-"
        print("%3d  %-19s  %-24s %9s  %-10s %s" % (k, start, r.name[:24], dur, r.status, r.reason))
    return 0


def _report(replay: Replay, out: TextIO) -> None:
    end = replay.log.end
    name = replay.log.tree.get("name", "?")
    out.write("\n")
    if end is None:
        out.write("%s: the log ends at %.3fs without the run's end (the process was killed?)%s\n" % (
            name, replay.t, "; its last record was cut" if replay.log.truncated else ""))
    else:
        out.write("%s: %s in %.2f s (%s ticks)\n" % (name, end.get("status"), float(end.get("duration") or 0.0),
                                                     end.get("ticks")))
        if end.get("reason") and end.get("status") != "SUCCESS":
            out.write("reason: %s\n" % end.get("reason"))
    out.write("calls:\n")
    for c in replay.finished:
        out.write("  +%7.3fs  %-26s %-11s %7.3fs  %s\n" % (float(c.get("started") or 0.0), c.get("target"),
                                                         c.get("status"), float(c.get("duration") or 0.0),
                                                         c.get("error") or ""))
    for c in replay.pending.values():
        out.write("  +%7.3fs  %-26s %-11s %8s\n" % (float(c.get("t") or 0.0), c.get("target"), "no end", "-"))
    if replay.notices:
        out.write("the ROS graph:\n")
        for n in replay.notices:
            out.write("  +%7.3fs  %s\n" % (float(n.get("t") or 0.0), n.get("text")))
    if replay.control:
        out.write("control:\n")
        for c in replay.control:
            out.write("  +%7.3fs  %s\n" % (float(c.get("t") or 0.0), control_line(c)))


def _jump_to_failure(replay: Replay, out: TextIO) -> None:
    """``--failure``: the failure that ended the run (not one the tree recovered from), where, why,
    and the state then; for a run stopped from outside, the state just before the stop."""
    log = replay.log
    ended, recovered = replay.failures()
    end = log.end or {}

    def where(f: Failure) -> str:
        n = replay.nodes.get(f.node, {})
        return "'%s' (%s:%s): %s" % (n.get("name"), n.get("file", "?"), n.get("line", "?"), f.message)

    if ended is not None:
        replay.to_failure(ended)
        out.write("the failure that ended the run, at %.3fs: %s\n" % (ended.t, where(ended)))
    elif end.get("status") == "FAILURE" or end.get("status") == "INVALID" or not end:
        ticks = [i for i, r in enumerate(log.records) if r.get("type") == "tick"]
        stop = ticks[-2] if len(ticks) >= 2 and end else (ticks[-1] if ticks else 0)  # before the halting tick
        replay.until(lambda rec: replay.index > stop)
        out.write("no leaf's failure ended this run: %s\nthe state at %.3fs, its last tick before that:\n" % (
            end.get("reason") or "its log ends without the run's end (the process was killed?)", replay.t))
    elif recovered:
        replay.to_failure(recovered[0])
        out.write("the run succeeded; the tree recovered from %d failure%s, the first at %.3fs: %s\n" % (
            len(recovered), "" if len(recovered) == 1 else "s", recovered[0].t, where(recovered[0])))
    else:
        out.write("no leaf failed in this run\n")
        return
    if end.get("reason") and end.get("status") != "SUCCESS":
        out.write("the run ended %s: %s\n" % (end.get("status"), end.get("reason")))
    earlier = [f for f in recovered if ended is None or f.seq < ended.seq]
    if earlier and ended is not None:
        out.write("before it, the tree recovered from: %s\n" % "; ".join(
            "%s at %.3fs" % (where(f), f.t) for f in earlier[:5]))
    replay.snapshot(out)


def _test_command(log: RunLog, scenario: str) -> str:
    """``bmtree test`` of ``scenario`` with the definition files the run was given, and a word
    on the modules it knew only from the live graph (their definitions are in no file it had)."""
    import shlex

    from modules.definition import DefinitionError
    from modules.search import default_definitions

    given = [m for m in log.tree.get("modules") or [] if isinstance(m, str) and os.path.exists(m)]
    command = " ".join(["bmtree test"] + ["--modules %s" % shlex.quote(m) for m in given] + [shlex.quote(scenario)])
    try:
        known = set(default_definitions(given))
    except (DefinitionError, OSError) as exc:  # changed since the run: the test will say what is wrong
        return "%s (its definitions: %s)" % (command, str(exc).splitlines()[0])
    used = {str(n["target"]).split(".", 1)[0] for n in log.tree.get("nodes") or []
            if isinstance(n, dict) and isinstance(n.get("target"), str)}
    missing = sorted(used - known)
    if missing:
        return "%s, adding --modules with the definition of %s (the run had it from the live graph)" % (
            command, ", ".join(missing))
    return command


def cmd_replay(args: Any) -> int:
    out = sys.stdout
    path = find_run(args.run, args.dir)
    log = read_log(path)
    if args.scenario:
        from coordinator.scenariogen import write_scenario

        write_scenario(log, args.scenario)
        out.write("wrote %s (run it with: %s)\n" % (args.scenario, _test_command(log, args.scenario)))
        return 0
    replay = Replay(log)
    started = datetime.datetime.fromtimestamp(float(log.tree.get("started") or 0.0))
    out.write("replay of %s: %s, started %s\n" % (path, log.tree.get("name"), started.strftime("%Y-%m-%d %H:%M:%S")))
    if args.failure:
        _jump_to_failure(replay, out)
        return 0
    if args.at is not None:
        at = args.at
        while replay.index < len(log.records) and float(log.records[replay.index].get("t") or 0.0) <= at:
            replay.next()
        out.write("at %.3fs:\n" % at)
        replay.snapshot(out)
        return 0
    if args.step:
        interactive = sys.stdin.isatty()
        while True:
            rec = replay.next()
            if rec is None:
                break
            if rec.get("type") != "tick":
                continue
            out.write("\n--- tick %s at %.3fs ---\n" % (rec.get("n"), replay.t))
            replay.snapshot(out)
            if interactive:
                out.write("[Enter: next tick, q: quit] ")
                out.flush()
                if sys.stdin.readline().strip().lower().startswith("q"):
                    return 0
        _report(replay, out)
        return 0
    if args.speed:
        _play(replay, out, args.speed)
    else:
        display = Display(out, tty=False)
        while replay.next(display) is not None:
            pass
    _report(replay, out)
    return 0


def _play(replay: Replay, out: TextIO, speed: float) -> None:
    """At ``speed`` times the recorded pace; on a terminal redrawn in place, as the live display does."""
    import time

    display = Display(out)
    shown = 0.0
    while True:
        index = replay.index
        if index >= len(replay.log.records):
            break
        rec = replay.log.records[index]
        if rec.get("type") == "tick":
            time.sleep(max(0.0, (float(rec.get("t") or 0.0) - shown) / speed))
            shown = float(rec.get("t") or 0.0)
        replay.next(display)
    display.on_end(types.SimpleNamespace(duration=replay.t))
