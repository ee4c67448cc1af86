"""A recorded run stepped through: the tree's shape, its statuses, the tree blackboard and the calls.

:class:`Replay` rebuilds the recorded tree as plain py_trees behaviours and applies the run log's
records to it one by one, so that ``bmtree replay`` (:mod:`coordinator.replay`) and the replay page
(:mod:`coordinator.webview`) show a moment of the run as the live display showed it; it also finds
where the run's failures started (by the live reason's rule) and the calls that failed.
"""
from __future__ import annotations

import bisect
import json
import types
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Set, TextIO, Tuple

import py_trees
from py_trees.common import Status

from coordinator.reasons import FailureTrail, originates
from coordinator.runevents import IncludeArgs, Notice, RunObserver, control_line, tree_drawing
from coordinator.runlog import RunLog, RunLogError

__all__ = ["Failure", "Replay"]


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
    """Where a failure started: its place among the status changes, its tick record, node and message;
    for one the run got past, the nearest ancestor that did not pass it up (``by``: it took another
    child or ran it again, ``recovered`` if it then succeeded), and the include it was in with the
    arguments it had then (``within``)."""

    seq: int
    index: int
    node: int
    message: str
    t: float
    by: Optional[int] = None
    recovered: bool = False
    within: str = ""


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
        self.parent = {i: n.get("parent") for i, n in self.nodes.items()}
        self.kids: Dict[Any, List[int]] = {}
        for i, p in self.parent.items():
            self.kids.setdefault(p, []).append(i)
        self.args = IncludeArgs.of_nodes(self.nodes.values())
        self.main, self.cleanup_ids = _root_and_cleanup(self.nodes, self.kids)
        self.pending: Dict[str, Dict[str, Any]] = {}
        self.finished: List[Dict[str, Any]] = []
        self.events: List[Dict[str, Any]] = []
        self.control: List[Dict[str, Any]] = []  # the operator's commands (run --control), and breakpoints hit
        self.paused = False
        self.paused_by: Optional[Dict[str, Any]] = None  # the control record that paused it (not a later refusal)
        self.notices: List[Dict[str, Any]] = []  # what happened to the ROS graph (the master went away...)
        self.index = 1
        self.t = 0.0

    def apply(self, rec: Dict[str, Any], display: Optional[RunObserver] = None) -> None:
        """One record; a tick's changes are also shown to ``display`` (the live display)."""
        kind = rec.get("type")
        self.t = float(rec.get("t") or self.t)
        if kind == "tick":
            changes = []
            self.args.tick(rec.get("changes") or [])   # first: an include's line says its arguments' values
            for change in rec.get("changes") or []:
                b = self.by_id.get(change[0])
                if b is None:
                    continue
                old, new = b.status, Status(change[1])
                b.status = new
                b.feedback_message = change[2] if len(change) > 2 else ""
                # as it was at this change: a retry may restart the leaf in the same tick
                changes.append((types.SimpleNamespace(name=self._named(self.args, change[0]),
                                                      feedback_message=b.feedback_message), old, new))
            if display is not None:
                display.on_tick(self.root, changes, self.t)
        elif kind == "call_start":
            self.pending[str(rec.get("call_id"))] = rec
        elif kind == "call_end":
            start = self.pending.pop(str(rec.get("call_id")), None)
            self.finished.append(dict(rec, started=(start or {}).get("t", rec.get("t"))))
        elif kind == "write":
            self.blackboard[str(rec.get("key"))] = rec.get("value")
            self.args.write(str(rec.get("key")), rec.get("value"))
        elif kind == "event":
            self.events.append(rec)
        elif kind == "notice":
            self.notices.append(rec)
            if display is not None:
                display.on_notice(Notice(str(rec.get("what")), str(rec.get("text"))), self.t)
        elif kind == "control":
            self.control.append(rec)
            if "paused" in rec:
                if rec["paused"] and not self.paused:
                    self.paused_by = rec
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

    def to_tick(self, index: int) -> None:
        """Apply the records up to and including the tick record ``index``, and draw the state after
        that tick: a node it halted is shown halted; one it reset after it ended keeps that outcome
        (a retry or loop resets the failed leaf in the tick it failed)."""
        while self.index < index and self.next() is not None:
            pass
        rec = self.log.records[index]
        changes = rec.get("changes") or []
        now = {c[0]: (self.by_id[c[0]].status, self.by_id[c[0]].feedback_message) for c in changes
               if c[0] in self.by_id}
        shown: Dict[Any, Tuple[Status, str]] = {}
        for c in changes:
            if c[0] not in now:
                continue
            new = Status(c[1])
            was, said = now[c[0]]
            if new is Status.INVALID and was is Status.RUNNING:
                shown[c[0]] = (Status.INVALID, "halted")
            elif new is Status.INVALID and was in (Status.SUCCESS, Status.FAILURE):
                shown[c[0]] = (was, said)
            else:
                shown.pop(c[0], None)
            now[c[0]] = (new, c[2] if len(c) > 2 else "")
        self.next()
        self.index = index + 1
        for nid, (status, said) in shown.items():
            self.by_id[nid].status, self.by_id[nid].feedback_message = status, said

    def stop_tick(self) -> Optional[int]:
        """The tick record of a stop from outside (Ctrl-C, ``max_duration``: the root halted while
        running, not ended by the tree), or None."""
        root = self.main
        ticks = [i for i, r in enumerate(self.log.records) if r.get("type") == "tick"]
        if not ticks or (self.log.end is None and not self.cleanup_ids):  # killed: no stop, unless the cleanup ran
            return None
        if self.cleanup_ids:  # with cleanup: the stop halted root, the cleanup's ticks came after it
            return next((i for i in ticks if any(c[0] == root and c[1] == "INVALID"
                                                 for c in self.log.records[i].get("changes") or [])), None)
        last = self.log.records[ticks[-1]].get("changes") or []
        return ticks[-1] if any(c[0] == root and c[1] == "INVALID" for c in last) else None

    def cut_calls(self) -> Set[str]:
        """The calls of the cleanup halted because it was cut short (its time limit, a stop): those
        halted just before the tick in which the cleanup's top node was halted."""
        top = self.kids.get(self.kids.get(None, [None])[0], [])
        if not self.cleanup_ids or len(top) != 2:
            return set()
        records = self.log.records
        ticks = [i for i, r in enumerate(records) if r.get("type") == "tick"]
        cut = next((i for i in ticks if any(c[0] == top[1] and c[1] == "INVALID"
                                            for c in records[i].get("changes") or [])), None)
        if cut is None:
            return set()
        before = max((i for i in ticks if i < cut), default=0)
        return {str(r.get("call_id")) for r in records[before + 1:cut] if r.get("type") == "call_end"
                and r.get("status") == "halted" and r.get("node") in self.cleanup_ids}

    def until(self, stop: Callable[[Dict[str, Any]], bool]) -> bool:
        """Apply records up to and including the first for which ``stop`` is true; False if none is."""
        while True:
            rec = self.next()
            if rec is None:
                return False
            if stop(rec):
                return True

    def failures(self) -> Tuple[Optional[Failure], List[Failure]]:
        """Where failures started, over the whole log, by the rule of the live reason
        (:class:`coordinator.reasons.FailureTrail`): the one that ended the run (None if none did:
        it succeeded, or was stopped from outside), and the others before it, in order, each with the
        nearest ancestor that went on past it (a ``for_each`` took its next element, a selector its
        next child, a retry made its next attempt), ``recovered`` if that ancestor then succeeded."""
        trail = FailureTrail(self.parent.get)
        status: Dict[int, str] = {}
        args = IncludeArgs.of_nodes(self.nodes.values())
        found: Dict[int, Failure] = {}
        at: Dict[int, Tuple[int, int]] = {}   # an origin's seq -> its tick record and place in it
        timeline: Dict[Any, List[Tuple[int, int, str]]] = {}   # node -> its changes (record, place, status)
        for index, rec in enumerate(self.log.records):
            kind = rec.get("type")
            if kind == "write":
                args.write(str(rec.get("key")), rec.get("value"))
            if kind != "tick":
                continue
            changes = rec.get("changes") or []
            here = []
            for pos, change in enumerate(changes):
                nid, new = change[0], change[1]
                message = change[2] if len(change) > 2 else ""
                kids = self.kids.get(nid, [])
                origin = new == "FAILURE" and originates(
                    self.nodes.get(nid, {}).get("kind"), not kids, message,
                    any(status.get(k) == "FAILURE" for k in kids))
                status[nid] = new
                timeline.setdefault(nid, []).append((index, pos, new))
                o = trail.change(nid, Status(new), origin, message, float(rec.get("t") or 0.0))
                if o is not None:
                    here.append((o, pos))
            for o, pos in here:  # the nearest include above it, with its arguments then; who went on
                up = trail.ancestors(o.behaviour)
                inc = next((a for a in up if self.nodes.get(a, {}).get("kind") == "include"), None)
                at[o.seq] = (index, pos)
                found[o.seq] = Failure(o.seq, index, o.behaviour, o.message, o.time,
                                       by=self._went_on(changes, pos, o.behaviour),
                                       within=self._named(args, inc) if inc is not None else "")
            args.tick(changes)
        ended = None
        end = self.log.end
        if end is not None and end.get("status") == "FAILURE" and self.stop_tick() is None:
            cause = next((o for o in reversed(trail.origins)  # root's, never its cleanup's
                          if o.behaviour not in self.cleanup_ids and trail.recovered_by(o) is None), None)
            ended = found[cause.seq] if cause is not None else None
        others = []
        for o in trail.origins:
            if (ended is not None and o.seq >= ended.seq) or o.behaviour in self.cleanup_ids:
                continue
            f = found[o.seq]
            if f.by is not None:
                f = f._replace(recovered=_ended_in_success(timeline.get(f.by, []), *at[o.seq]))
            others.append(f)
        return ended, others

    def _went_on(self, changes: List[Any], pos: int, node: Any) -> Optional[int]:
        """The nearest ancestor of ``node`` (whose failure is change ``pos`` of a tick's ``changes``)
        that did not pass that failure up: it took another child, ran the child again, succeeded, or
        kept running. Ancestors that failed later in the same tick for another reason (a selector whose
        next child failed at once) went on all the same, so "failed in this tick" is not enough: the
        failure is passed up only by a parent whose next change is FAILURE with nothing under it run
        in between (a parallel's other children are ticked anyway). None when it reached root (above
        it, a ``with_cleanup`` running the cleanup did not get past it)."""
        at = pos
        for a in self._ancestors(node):
            if self.nodes.get(a, {}).get("kind") == "with_cleanup":
                return None
            nxt = next((i for i in range(at + 1, len(changes)) if changes[i][0] == a), None)
            if nxt is None or changes[nxt][1] != "FAILURE":
                return a
            if self.nodes.get(a, {}).get("kind") != "parallel" and any(
                    changes[i][1] != "INVALID" and a in self._ancestors(changes[i][0])
                    for i in range(at + 1, nxt)):
                return a
            at = nxt
        return None

    def _ancestors(self, node: Any) -> List[Any]:
        out: List[Any] = []
        node = self.parent.get(node)
        while node is not None and len(out) < 1000:
            out.append(node)
            node = self.parent.get(node)
        return out

    def failing_call(self, f: Failure) -> Tuple[Optional[Dict[str, Any]], Optional[Dict[str, Any]]]:
        """The call of failure ``f`` (made at or under its node before it: the failed call, or the
        call a timeout halted): its start and end records (None when there is none)."""
        under, todo = set(), [f.node]
        while todo:
            n = todo.pop()
            under.add(n)
            todo.extend(self.kids.get(n, []))
        start = None
        for rec in self.log.records[:f.index]:
            if rec.get("type") == "call_start" and rec.get("node") in under:
                start = rec
        if start is None:
            return None, None
        end = next((r for r in self.log.records if r.get("type") == "call_end"
                    and r.get("call_id") == start.get("call_id")), None)
        if end is not None and end.get("status") == "succeeded":
            return None, None   # not the failure's call (a call leaf whose next call could not be built: no record)
        return start, end

    def snapshot(self, out: TextIO, stopped: str = "") -> None:
        """The tree (includes with the values their arguments had), the tree blackboard and the calls
        in flight now; ``stopped``: what then happened to those calls (the run was stopped)."""
        ids = {b: i for i, b in self.by_id.items()}
        drawing = tree_drawing(self.root, lambda b, name: self._named(self.args, ids[b])
                               if ids.get(b) in self.args.values else name) + "\n"
        getattr(out, "write_drawing", out.write)(drawing)   # (a TerminalText would escape its colours)
        if self.paused:
            out.write("paused by control (%s)\n" % control_line(self.paused_by or self.control[-1]))
        out.write("tree blackboard:\n")
        for k in sorted(self.blackboard):
            out.write("  %s = %s\n" % (k, json.dumps(self.blackboard[k], ensure_ascii=False)))
        out.write("calls in flight%s:%s\n" % (" (%s)" % stopped if stopped and self.pending else "",
                                              "" if self.pending else " none"))
        for rec in self.pending.values():
            out.write("  %-26s since %.3fs  inputs %s  (node %s)\n" % (
                rec.get("target"), float(rec.get("t") or 0.0), json.dumps(rec.get("inputs"), ensure_ascii=False),
                self._where(rec.get("node"))))

    def stop_time(self, stop: Optional[int]) -> float:
        """When the run was stopped from outside (the stop's tick ``stop``): with a cleanup, that tick's
        time (the cleanup ran after it); else when the run was last alive."""
        if stop is not None and self.cleanup_ids:
            return float(self.log.records[stop].get("t") or 0.0)
        return self.log.last_alive

    def _named(self, args: IncludeArgs, node_id: Any) -> str:
        """An include's name with the values its arguments had (``search_room(room="kitchen")``)."""
        return args.name(node_id, str(self.nodes.get(node_id, {}).get("name", "?")))

    def _where(self, node_id: Any) -> str:
        n = self.nodes.get(node_id) if isinstance(node_id, int) else None
        if n is None:
            return "?"
        return "'%s' %s:%s" % (n.get("name"), n.get("file", "?"), n.get("line", "?"))


def _ended_in_success(changes: List[Tuple[int, int, str]], index: int, pos: int) -> bool:
    """Whether a node's first end after change ``pos`` of record ``index`` (its ``changes``, in order) is
    SUCCESS: the node that went on past a failure recovered from it (halted or failed: it did not)."""
    for _i, _p, new in changes[bisect.bisect_right(changes, (index, pos, "\uffff")):]:
        if new != "RUNNING":
            return new == "SUCCESS"
    return False


def _root_and_cleanup(nodes: Dict[int, Dict[str, Any]], kids: Dict[Any, List[int]]) -> Tuple[Any, Set[int]]:
    """The recorded tree's root, and the ids of its cleanup (none without ``cleanup:``)."""
    top = kids.get(None, [None])[0]
    below = kids.get(top, [])
    if nodes.get(top, {}).get("kind") != "with_cleanup" or len(below) != 2:
        return top, set()
    under, todo = set(), [below[1]]
    while todo:
        n = todo.pop()
        under.add(n)
        todo.extend(kids.get(n, []))
    return below[0], under
