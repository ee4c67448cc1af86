"""Loops: ``repeat`` (N times, or until / while a condition) and ``for_each`` (once per element of a list).

Every loop is bounded: ``repeat``'s count is its maximum of runs, ``for_each`` refuses a list longer
than its ``max``; reaching the bound is FAILURE with the reason, so a tree cannot spin forever.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, FrozenSet, Iterable, List, Optional, Tuple

import py_trees
from py_trees.common import Status

from coordinator.errors import Pos, TreeError
from coordinator.expr import Expr, ExprError, kind_of
from coordinator.exprhints import quoted_key_warnings
from coordinator.nodes.base import (
    NEVER,
    Flow,
    NodeKind,
    Option,
    check_choice,
    fixed,
    join,
    meet,
    param_keys,
    param_type_errors,
)
from coordinator.nodes.decorators import (
    CHILD,
    INDEX_HELP,
    Counted,
    Guarded,
    TimesSpec,
    forever,
    index_option,
    once,
)
from coordinator.refs import Computed, Ref, RefError, refs_in, resolve, unwrap
from coordinator.treeast import TreeNode
from coordinator.values import expr_errors, read_at
from coordinator.yamlsrc import bool_hint

__all__ = ["DEFAULT_MAX", "ForEach", "ForEachSpec", "KINDS", "Repeat", "RepeatSpec", "expr_option"]

DEFAULT_MAX = 100
"""The longest list ``for_each`` runs over unless its ``max`` says otherwise."""


def expr_option(p: Any, raw: Any, key: str) -> Optional[Expr]:
    """An expression option (``until``, ``while``), or None after reporting where it is malformed."""
    value, at = raw[key], raw.val_pos[key]
    if not isinstance(value, str) or not value.strip():
        p.err(at, "%r takes an expression string, e.g. 'answer == \"yes\"'" % key)
        return None
    try:
        return Expr.parse(value)
    except ExprError as exc:
        p.err(Pos(at.file, at.line, at.column + exc.offset), "bad expression in %r: %s" % (key, exc))
        return None


def expr_type_errors(expr: Optional[Expr], at: Optional[Pos], types: Dict[str, set], errors: List[TreeError]) -> None:
    if expr is None or at is None:
        return
    for off, msg in expr_errors(expr, types):
        errors.append(TreeError(Pos(at.file, at.line, at.column + off), msg))


# repeat ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RepeatSpec(TimesSpec):
    mode: str = ""                  # '' (N runs), 'until' or 'while'
    cond: Optional[Expr] = None
    cond_pos: Optional[Pos] = None
    index: str = ""                 # the tree key each run's number is written to (none if "")


class Repeat(Guarded):
    """Run the child again while it succeeds: N times, or until / while the condition holds, at most N runs."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, spec: RepeatSpec, ctx: Any):
        super().__init__(name, child, ctx)
        self.spec = spec

    def initialise(self) -> None:
        self.runs = 0
        self.times = self.param(self.spec.times, "count", "count of repeat")
        if self.times is not None:
            self.number(self.spec.index, 0)   # (before ``while`` is checked: it may read it)
        if self.times is not None and self.spec.mode == "while":
            holds = self._holds()
            if holds is None:
                self.finish_early(Status.FAILURE, self.feedback_message)
            elif not holds:
                self.finish_early(Status.SUCCESS, "while %s is false: no run" % self.spec.cond.text)

    def _holds(self) -> Optional[bool]:
        """The condition now (None, the reason in the feedback, when it cannot be evaluated)."""
        try:
            return self.spec.cond.evaluate(self.ctx.lookup)
        except (KeyError, RefError) as exc:
            self.feedback_message = "%s %s: %s" % (self.spec.mode, self.spec.cond.text,
                                                   exc.args[0] if exc.args else exc)
            return None

    def update(self) -> Status:
        if self.decorated.status != Status.SUCCESS:
            if self.decorated.status == Status.FAILURE:
                self.feedback_message = ""   # the child's own reason is the reason
            return self.decorated.status
        self.runs += 1
        mode = self.spec.mode
        if not mode:
            if self.runs >= self.times:
                return Status.SUCCESS
            self.number(self.spec.index, self.runs)
            return self.rerun("run %d of %d succeeded" % (self.runs, self.times))
        if mode == "while":   # the next run's number, which its condition may read
            self.number(self.spec.index, self.runs)
        holds = self._holds()
        if holds is None:
            return Status.FAILURE
        if holds == (mode == "until"):
            self.feedback_message = "%s %s after %d run%s" % (mode, self.spec.cond.text, self.runs,
                                                              "s" if self.runs > 1 else "")
            return Status.SUCCESS
        if self.runs >= self.times:
            self.feedback_message = "reached its maximum of %d runs while %s %s%s" % (
                self.times, self.spec.cond.text, "was still false" if mode == "until" else "still held",
                self.spec.cond.values_read(self.ctx.lookup))
            return Status.FAILURE
        if mode == "until":
            self.number(self.spec.index, self.runs)
        return self.rerun("run %d of at most %d: %s %s not yet" % (self.runs, self.times, mode, self.spec.cond.text))


class RepeatKind(Counted):
    name = "repeat"
    value = ("count", "runs (≥ 1); with `until`/`while`, the maximum of runs")
    label = "count"
    summary = ("run the child N times in a row while it succeeds; with `until`/`while`, until the condition "
               "holds / while it holds; the maximum reached is FAILURE")
    options = (CHILD,
               Option("until", "expr", "checked after each successful run: SUCCESS once it is true"),
               Option("while", "expr", "checked before each run: SUCCESS once it is false (maybe no run)"),
               Option("index", "key", INDEX_HELP % ("run", "run", "run") + "; `while` reads the number of the "
                                      "run it is checked before", shown="none"))
    lasts = "a repeat is RUNNING between its runs"

    def lasting(self, node: TreeNode) -> str:
        return "" if once(node.spec.times) else self.lasts

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Any) -> Any:
        times = None if forever(p, node, value, at) else p.typed(node, self.label, value, at, self.value[0])
        modes = [m for m in ("until", "while") if m in raw]
        if len(modes) > 1:
            p.err(raw.key_pos["while"], "repeat takes 'until' or 'while', not both")
        mode = modes[0] if modes else ""
        cond = expr_option(p, raw, mode) if mode else None
        if "child" in raw:
            p.child(node, raw["child"], raw.val_pos["child"])
        return RepeatSpec(times, mode, cond, raw.val_pos[mode] if mode else None, index_option(p, raw))

    def default_name(self, node: TreeNode) -> str:
        s = node.spec
        if s.mode and s.cond is not None:
            return "repeat %s %s (at most %s)" % (s.mode, s.cond.text, s.times)
        return "repeat x%s" % s.times

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Succeeds after a successful run of its child (``while``: maybe with no run, writing nothing);
        fails when a run fails, when ``until`` reaches the maximum or cannot be worked out (after a
        successful run), or at once when its count (a reference) cannot be used."""
        s = node.spec
        f.need(node, param_keys(s.times), avail)
        key = frozenset([s.index]) if s.index else frozenset()
        if s.mode == "while" and s.cond is not None:
            f.need(node, s.cond.keys, avail | key)
        nothing: FrozenSet[str] = frozenset()
        ok, failed = f.outcome(node.children[0], avail | key) if node.children else (nothing, nothing)
        ok, failed = join(key, ok), join(key, failed)
        if s.mode == "until" and s.cond is not None:
            f.need(node, s.cond.keys, avail | ok)   # (NEVER is empty: never evaluated, still checked)
            failed = meet((failed, ok))
        if s.mode == "while":   # maybe no run: only its index (written before the condition) is sure
            sure = key if fixed(s.times) else nothing
            return sure, sure
        return ok, failed if fixed(s.times) else meet((failed, nothing))

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        return {node.spec.index: None} if node.spec.index else {}

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        super().check_types(node, types, errors)
        expr_type_errors(node.spec.cond, node.spec.cond_pos, types, errors)
        errors.extend(quoted_key_warnings(node.spec.cond, node.spec.cond_pos, types))

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        s = node.spec
        return (super().read_pos(node, key)
                or (read_at(s.cond, s.cond_pos, key) if s.cond is not None and s.cond_pos is not None else None))

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return Repeat(node.name, child(node.children[0]), node.spec, ctx)


# for_each -------------------------------------------------------------------------------------
_GO_ON = (" (to go on to the next element when one fails, as SMACH's Iterator with a 'continue' outcome: put "
          "the child in force_success, and keep what failed with its call's status: KEY)")


@dataclass(frozen=True)
class ForEachSpec:
    items: Any                      # a list literal (may hold references), a Ref or an ExprValue
    key: str = ""
    policy: str = "all"
    max: Any = DEFAULT_MAX
    max_pos: Optional[Pos] = None
    index: str = ""                 # the tree key the element's position is written to (none if "")


class ForEach(Guarded):
    """Run the child once per element, the element written to ``key`` first.

    ``all``: FAILURE at the first element whose run fails; ``one``: SUCCESS at the first that succeeds.
    """

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, spec: ForEachSpec, ctx: Any):
        super().__init__(name, child, ctx)
        self.spec = spec
        self.items: List[Any] = []
        self.i = 0

    def initialise(self) -> None:
        spec = self.spec
        limit = self.param(spec.max, "count", "max of for_each")
        if limit is None:
            return
        try:
            items = unwrap(resolve(spec.items, self.ctx.lookup))
        except (KeyError, RefError) as exc:
            self.finish_early(Status.FAILURE, "cannot read the list: %s" % (exc.args[0] if exc.args else exc))
            return
        if not isinstance(items, (list, tuple)):
            self.finish_early(Status.FAILURE, "%s is a %s, not a list" % (spec.items, kind_of(items)))
            return
        if len(items) > limit:
            self.finish_early(Status.FAILURE, "the list has %d elements, more than max %d" % (len(items), limit))
            return
        self.items = list(items)
        if not self.items:
            self.finish_early(Status.SUCCESS if spec.policy == "all" else Status.FAILURE,
                              "the list is empty" + ("" if spec.policy == "all" else ": nothing succeeded"))
            return
        self._bind(0)

    def _bind(self, i: int) -> None:
        self.i = i
        self.ctx.write(self.spec.key, self.items[i])
        if self.spec.index:
            self.ctx.write(self.spec.index, i)
        self.feedback_message = "element %d of %d: %s = %r" % (i + 1, len(self.items), self.spec.key,
                                                               unwrap(self.items[i]))

    def update(self) -> Status:
        status = self.decorated.status
        if status == Status.RUNNING:
            return status
        done = Status.SUCCESS if self.spec.policy == "one" else Status.FAILURE
        if status == done or self.i + 1 >= len(self.items):
            if status == Status.SUCCESS:
                self.feedback_message = "%s at element %d of %d" % (
                    "succeeded" if self.spec.policy == "one" else "all succeeded", self.i + 1, len(self.items))
            else:
                self.feedback_message = ""   # the child's own reason is the reason
            return status
        self._bind(self.i + 1)
        return self.rerun(self.feedback_message)


class ForEachKind(NodeKind):
    name = "for_each"
    family = "decorator"
    value = ("list", "a list: `[a, b]`, `$key` or `$( … )`")
    summary = "run the child once per element, the element written to the key `as` first"
    options = (Option("as", "key", "the tree key each element is written to", required=True),
               Option("index", "key", "a tree key the element's position is written to (0 for the first: "
                                      "`$(at(names, i))` reads the same position of another list)", shown="none"),
               CHILD,
               Option("policy", "policy", "`all`: every run must succeed (FAILURE at the first that fails); "
                                          "`one`: SUCCESS at the first run that succeeds (a search)", default="all"),
               Option("max", "count", "the longest list run over; a longer one is FAILURE", default=DEFAULT_MAX))
    lasts = "a for_each is RUNNING between its elements"

    def lasting(self, node: TreeNode) -> str:
        items = node.spec.items
        return "" if isinstance(items, list) and len(items) <= 1 else self.lasts

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> ForEachSpec:
        items: Any = None
        limit = p.opt(node, raw, self.option("max"))
        if isinstance(value, list) or (isinstance(value, str) and value.startswith("$") and not
                                       value.startswith("$$")):
            items = p.literal_at(raw, self.name, at)
            if isinstance(items, list) and isinstance(limit, int) and len(items) > limit:
                p.err(at, "for_each over %d elements, more than max %d (raise 'max'): write max: %d, or give a "
                          "shorter list" % (len(items), limit, len(items)))
        else:
            p.err(at, "for_each takes a list: [a, b], a $reference or a $( … ) expression, got %r" % (value,))
        key = raw.get("as")
        if "as" in raw and (not isinstance(key, str) or not key.isidentifier()):
            p.err(raw.val_pos["as"], "'as' must be a tree key (an identifier), got %r%s" % (key, bool_hint(key)))
            key = None
        index = index_option(p, raw, key or "")
        spec = ForEachSpec(items, key or "", check_choice(p, raw, "policy", ("all", "one"), "all", _GO_ON), limit,
                           raw.val_pos["max"] if "max" in raw else None, index or "")
        if "child" in raw:
            p.child(node, raw["child"], raw.val_pos["child"])
        return spec

    def default_name(self, node: TreeNode) -> str:
        items = node.spec.items
        shown = str(items) if isinstance(items, (Ref, Computed)) else "[%s]" % ", ".join(map(str, items or []))
        return "for each %s in %s" % (node.spec.key, shown)

    def reads(self, node: TreeNode) -> Iterable[str]:
        return [r.key for r in refs_in(node.spec.items)] + param_keys(node.spec.max)

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """A run writes the ``as`` key, then what the child writes. ``all`` succeeds when every run did
        (or with an empty list: nothing written), fails at the first run that fails; ``one`` succeeds at
        the first run that succeeds, fails when all failed (or with an empty list). Either fails at once
        on a list or ``max`` that cannot be used (a reference)."""
        spec = node.spec
        f.need(node, self.reads(node), avail)
        nothing: FrozenSet[str] = frozenset()
        key = frozenset(k for k in (spec.key, spec.index) if k)
        ok, failed = f.outcome(node.children[0], avail | key) if node.children else (nothing, nothing)
        run_ok, run_failed = join(key, ok), join(key, failed)
        items = spec.items
        nonempty = isinstance(items, list) and bool(items)   # surely one run at least
        empty = isinstance(items, list) and not items
        if spec.policy == "all":
            ok = run_ok if nonempty else meet((run_ok, nothing))
            failed = NEVER if empty else run_failed
        else:
            ok = NEVER if empty else run_ok
            failed = run_failed if nonempty else nothing
        if not fixed(items, spec.max):
            failed = meet((failed, nothing))
        return ok, failed

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        return {k: None for k in (node.spec.key, node.spec.index) if k}

    def copies(self, node: TreeNode) -> Dict[str, Ref]:
        """The ``as`` key holds an element of the list: of a ``$reference``, its element type (``$poses[0]``)."""
        items = node.spec.items
        return {node.spec.key: Ref(items.key, items.path + (0,))} if isinstance(items, Ref) and node.spec.key else {}

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        spec = node.spec
        param_type_errors(spec.items, lambda: node.value_pos or node.pos, types, "list", "for_each", errors,
                          spec.max if isinstance(spec.max, int) else None)   # (a tree input's list: not too long)
        if spec.max_pos is not None:
            param_type_errors(spec.max, spec.max_pos, types, "count", "max of for_each", errors)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        return read_at(node.spec.items, node.value_pos, key) if node.value_pos is not None else None

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return ForEach(node.name, child(node.children[0]), node.spec, ctx)


KINDS = (RepeatKind(), ForEachKind())
