"""Decorators: ``retry``, ``timeout`` (on the run's clock), ``inverter``, ``force_*`` (py_trees'); loops are in ``loops``."""
from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import Any, Dict, FrozenSet, Iterable, Iterator, List, Optional, Tuple

import py_trees
from py_trees.common import Status

from coordinator.bounds import beyond_bound
from coordinator.errors import Pos, TreeError
from coordinator.nodes.base import (
    NEVER,
    Flow,
    NodeKind,
    Option,
    fixed,
    join,
    meet,
    param_keys,
    param_type_errors,
    run_param,
)
from coordinator.nodes.timeouts import long_seconds
from coordinator.treeast import TreeNode
from coordinator.values import read_at
from coordinator.yamlsrc import bool_hint

__all__ = ["CHILD", "Counted", "Guarded", "KINDS", "Retry", "RetrySpec", "Timeout", "TimesSpec", "SecondsSpec",
           "INDEX_HELP", "index_option", "once"]


@dataclass(frozen=True)
class TimesSpec:
    times: Optional[int]


@dataclass(frozen=True)
class SecondsSpec:
    seconds: Optional[float]


@dataclass(frozen=True)
class RetrySpec:
    times: Any
    delay: Any = None  # seconds between a failed attempt and the next (a number or a reference)
    delay_pos: Optional[Pos] = None
    index: str = ""    # the tree key each attempt's number is written to (none if "")


class Guarded(py_trees.decorators.Decorator):
    """A decorator that can end without ticking its child: when a parameter is bad when it starts
    (FAILURE with the reason) or its loop has nothing to run (``finish_early``)."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, ctx: Any):
        super().__init__(name=name, child=child)
        self.ctx = ctx
        self.early: Optional[Status] = None

    def finish_early(self, status: Status, reason: str = "") -> None:
        self.early = status
        self.feedback_message = reason

    def param(self, value: Any, type_name: str, label: str) -> Any:
        """A count or duration now (None after ``finish_early(FAILURE, why)`` if it cannot be used)."""
        v, why = run_param(value, self.ctx.lookup, type_name, label)
        if why:
            self.finish_early(Status.FAILURE, why)
        return v

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        if self.status != Status.RUNNING:
            self.early = None
            self.feedback_message = ""
            self.initialise()
        if self.early is None and not self.holding():
            yield from self.decorated.tick()
        new_status = self.early if self.early is not None else self.update()
        if new_status != Status.RUNNING:
            self.stop(new_status)
        self.status = new_status
        yield self

    def holding(self) -> bool:
        """True while the child is not to be ticked (a retry waiting out its delay)."""
        return False

    def number(self, key: str, n: int) -> None:
        """Write run ``n`` (0 for the first) to the loop's ``index`` key, if it has one, before the run starts."""
        if key:
            self.ctx.write(key, n)

    def rerun(self, message: str) -> Status:
        """Run the child again from the start, at once (not at the next period)."""
        self.feedback_message = message
        self.decorated.stop(Status.INVALID)
        self.ctx.wake_after(0.0)
        return Status.RUNNING


def _failure_of(b: py_trees.behaviour.Behaviour) -> str:
    """The failure text of the deepest failed node under ``b`` (what a waiting retry waits after)."""
    for node in reversed(list(b.iterate())):
        if node.status == Status.FAILURE and node.feedback_message:
            return node.feedback_message
    return ""


class Timeout(Guarded):
    """FAILURE (and the child halted) when the child runs longer than ``duration`` on the run's clock."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, duration: Any, ctx: Any):
        super().__init__(name, child, ctx)
        self.duration_param = duration
        self.duration = 0.0

    def initialise(self) -> None:
        self.duration = self.param(self.duration_param, "seconds", "duration of timeout")
        if self.duration is None:
            return
        self.deadline = self.ctx.clock.now() + self.duration
        self.ctx.wake_after(self.duration)

    def update(self) -> Status:
        status = self.decorated.status
        if status == Status.RUNNING and self.ctx.clock.now() >= self.deadline:
            self.feedback_message = "timed out after %gs" % self.duration
            return Status.FAILURE
        return status


class Retry(Guarded):
    """Re-run a failing child, at most ``times`` attempts in all, ``delay`` seconds apart (on the
    run's clock; the child is not ticked meanwhile)."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, times: Any, ctx: Any, delay: Any = None,
                 index: str = ""):
        super().__init__(name, child, ctx)
        self.times_param = times
        self.delay_param = delay
        self.index = index
        self.resume_at: Optional[float] = None

    def initialise(self) -> None:
        self.runs = 0
        self.resume_at = None
        self.times = self.param(self.times_param, "count", "count of retry")
        self.delay = 0.0
        if self.times is not None and self.delay_param is not None:
            self.delay = self.param(self.delay_param, "seconds0", "delay of retry")
        if self.early is None:
            self.number(self.index, 0)

    def holding(self) -> bool:
        if self.resume_at is None:
            return False
        if self.ctx.clock.now() >= self.resume_at:
            self.resume_at = None  # the next attempt starts in this tick
            self.number(self.index, self.runs)
            return False
        return True

    def update(self) -> Status:
        if self.resume_at is not None:
            return Status.RUNNING
        if self.decorated.status == Status.FAILURE:
            self.runs += 1
            if self.runs < self.times:
                said = "attempt %d of %d failed" % (self.runs, self.times)
                if not self.delay:
                    self.number(self.index, self.runs)
                    return self.rerun(said)
                why = _failure_of(self.decorated)
                said += " (%s)" % why if why else ""
                self.decorated.stop(Status.INVALID)
                self.resume_at = self.ctx.clock.now() + self.delay
                self.ctx.wake_after(self.delay)
                self.feedback_message = "%s; the next in %gs" % (said, self.delay)
                return Status.RUNNING
            self.feedback_message = "failed in attempt %d of %d" % (self.runs, self.times)  # not the last rerun's
        return self.decorated.status


CHILD = Option("child", "node", "the decorated node", required=True)


def forever(p: Any, node: TreeNode, value: Any, at: Any) -> bool:
    """A negative count of ``retry``/``repeat`` (BehaviorTree.CPP's -1: forever), reported with why there is none."""
    if node.kind not in ("retry", "repeat") or isinstance(value, bool) or not isinstance(value, int):
        return False
    if beyond_bound("count", value):   # (also the check of a count, too large to be one)
        p.err(at or node.value_pos, "count of %s is %s" % (node.kind, beyond_bound("count", value)))
        return True
    if value >= 0:
        return False
    runs = "attempts" if node.kind == "retry" else "runs"
    p.err(at or node.value_pos, "count of %s is %d, BehaviorTree.CPP's 'forever': every bmtree loop is bounded, so "
                                "give the most %s it may take (%s: 100); see 'Every loop is bounded' in "
                                "trees/README.md" % (node.kind, value, runs, node.kind))
    return True


INDEX_HELP = ("a tree key the number of the %s is written to before it starts (0 for the first): "
              "`check: %s > 0` tells a later %s from the first")


def index_option(p: Any, raw: Any, other: Optional[str] = None) -> str:
    """A loop's ``index`` key ('' when none, or after reporting why it cannot be one); ``other``: the
    ``as`` key of a ``for_each``, which it may not be."""
    if "index" not in raw:
        return ""
    index = raw["index"]
    if not isinstance(index, str) or not index.isidentifier() or index == other:
        p.err(raw.val_pos["index"], "'index' must be a tree key (an identifier)%s, got %r%s" % (
            "" if other is None else " other than 'as'", index, bool_hint(index)))
        return ""
    return index


def once(times: Any) -> bool:
    """Whether a count is the literal 1: a loop of one run starts no next one (it is never RUNNING for that)."""
    return times == 1 and isinstance(times, int) and not isinstance(times, bool)


class Counted(NodeKind):
    """A decorator whose main value is a number and whose child is the ``child`` option."""

    family = "decorator"
    options = (CHILD,)
    behaviour: Any = None

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Any) -> Any:
        v = None if forever(p, node, value, at) else p.typed(node, self.label, value, at, self.value[0])
        if self.value[0] == "seconds":
            long_seconds(p, v, at, "duration of %s" % self.name)
        spec = self.make_spec(v)
        if "child" in raw:
            p.child(node, raw["child"], raw.val_pos["child"])
        return spec

    def param(self, node: TreeNode) -> Any:
        return node.spec.times

    def make_spec(self, v: Any) -> Any:
        return TimesSpec(v)

    def default_name(self, node: TreeNode) -> str:
        return "%s x%s" % (self.name, node.spec.times)

    def reads(self, node: TreeNode) -> Iterable[str]:
        return param_keys(self.param(node))

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        param_type_errors(self.param(node), lambda: node.value_pos or node.pos, types, self.value[0],
                          "%s of %s" % (self.label, self.name), errors)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        return read_at(self.param(node), node.value_pos, key) if node.value_pos is not None else None

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Succeeds when its child does (``timeout``: in time); fails on its own too (timed out, the child
        halted; a count or duration that cannot be used), having written nothing sure."""
        f.need(node, self.reads(node), avail)
        if not node.children:
            return frozenset(), frozenset()
        return f.outcome(node.children[0], avail)[0], frozenset()

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return self.behaviour(node.name, child(node.children[0]), node.spec.times, ctx)


class RetryKind(Counted):
    name = "retry"
    value = ("count", "attempts in all (≥ 1)")
    label = "count"
    summary = "re-run the child while it fails"
    options = (CHILD, Option("delay", "seconds0", "seconds between a failed attempt and the next (a module "
                                                 "restarting, a door opening)", shown="`0`"),
               Option("index", "key", INDEX_HELP % ("attempt", "attempt", "attempt"), shown="none"))
    behaviour = Retry
    lasts = "a retry is RUNNING between its attempts"

    def lasting(self, node: TreeNode) -> str:
        return "" if once(node.spec.times) else self.lasts

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Any) -> Any:
        times = super().parse(p, node, raw, value, at).times
        delay = p.opt(node, raw, self.option("delay"))
        if "delay" in raw:
            long_seconds(p, delay, raw.val_pos["delay"], "delay of retry")
        return RetrySpec(times, delay, raw.val_pos.get("delay"), index_option(p, raw))

    def reads(self, node: TreeNode) -> Iterable[str]:
        return param_keys(node.spec.times, node.spec.delay)

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Succeeds when an attempt does; fails when the last attempt failed, or at once when its count
        or delay (a reference) cannot be used. Each attempt is given its ``index`` first."""
        f.need(node, self.reads(node), avail)
        if not node.children:
            return frozenset(), frozenset()
        key = frozenset([node.spec.index]) if node.spec.index else frozenset()
        cs, cf = f.outcome(node.children[0], avail | key)
        cs, cf = join(key, cs), join(key, cf)
        return cs, cf if fixed(node.spec.times, node.spec.delay) else meet((cf, frozenset()))

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        return {node.spec.index: None} if node.spec.index else {}

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        super().check_types(node, types, errors)
        s = node.spec
        if s.delay is not None:
            param_type_errors(s.delay, s.delay_pos or node.pos, types, "seconds0", "delay of retry", errors)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        s = node.spec
        return super().read_pos(node, key) or (read_at(s.delay, s.delay_pos, key) if s.delay_pos is not None
                                               else None)

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return Retry(node.name, child(node.children[0]), node.spec.times, ctx, node.spec.delay, node.spec.index)


class TimeoutKind(Counted):
    name = "timeout"
    value = ("seconds", "seconds (> 0)")
    label = "duration"
    summary = "FAILURE, and the child halted (its calls cancelled), after N seconds"

    def make_spec(self, v: Any) -> Any:
        return SecondsSpec(v)

    def param(self, node: TreeNode) -> Any:
        return node.spec.seconds

    def default_name(self, node: TreeNode) -> str:
        seconds = node.spec.seconds  # a number: 'timeout 5s'; a reference or an expression as written
        return "timeout %ss" % seconds if isinstance(seconds, (int, float)) else "timeout %s" % seconds

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return Timeout(node.name, child(node.children[0]), node.spec.seconds, ctx)


class _Wrap(NodeKind):
    """A decorator whose main value is its child, and which maps its child's ending (``ends``)."""

    family = "decorator"
    value = ("node", "the child node")
    behaviour: Any = None

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Any) -> Any:
        p.child(node, value, at)
        return None

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        if not node.children:
            return frozenset(), frozenset()
        return self.ends(*f.outcome(node.children[0], avail))

    @abc.abstractmethod
    def ends(self, ok: FrozenSet[str], failed: FrozenSet[str]) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """What is surely written when this node succeeds and fails, from the same of its child."""

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return self.behaviour(node.name, child(node.children[0]))


class Inverter(_Wrap):
    name = "inverter"
    summary = "SUCCESS ↔ FAILURE"
    behaviour = py_trees.decorators.Inverter

    def ends(self, ok: FrozenSet[str], failed: FrozenSet[str]) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        return failed, ok


class ForceSuccess(_Wrap):
    name = "force_success"
    summary = "FAILURE → SUCCESS"
    behaviour = py_trees.decorators.FailureIsSuccess

    def ends(self, ok: FrozenSet[str], failed: FrozenSet[str]) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        return meet((ok, failed)), NEVER


class ForceFailure(_Wrap):
    name = "force_failure"
    summary = "SUCCESS → FAILURE"
    behaviour = py_trees.decorators.SuccessIsFailure

    def ends(self, ok: FrozenSet[str], failed: FrozenSet[str]) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        return NEVER, meet((ok, failed))


KINDS = (RetryKind(), TimeoutKind(), Inverter(), ForceSuccess(), ForceFailure())
