"""Composites: ``sequence``, ``selector``, ``parallel`` (py_trees' own)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, FrozenSet, Iterator, List, Optional, Tuple

import py_trees
from py_trees.common import Status

from comm.errors import did_you_mean
from coordinator.errors import TreeError
from coordinator.nodes.base import (
    NEVER,
    TYPES,
    Flow,
    NodeKind,
    Option,
    ValueType,
    check_choice,
    join,
    meet,
    where,
)
from coordinator.treeast import TreeNode, walk

__all__ = ["EndedBy", "FirstSuccess", "KINDS", "MemorySpec", "NamedEnd", "POLICIES", "ParallelSpec"]


@dataclass(frozen=True)
class MemorySpec:
    memory: bool = True


@dataclass(frozen=True)
class ParallelSpec:
    policy: str = "all"
    synchronise: bool = True
    succeed_on: Tuple[int, ...] = ()   # the positions of the children named by ``succeed_on`` (none: ``policy``)
    ended_by: str = ""                 # the tree key given the name of the child whose ending ended it


# ``succeed_on``'s type, for the JSON Schema (registered here: only the parallel takes it)
TYPES.setdefault("names", ValueType("names", "list of child names", {
    "type": "array", "minItems": 1, "uniqueItems": True, "items": {"type": "string", "minLength": 1}}))
POLICIES = ("all", "one", "first_success")
TYPES.setdefault("parallel_policy", ValueType("parallel_policy", " or ".join("`%s`" % p for p in POLICIES),
                                              {"enum": list(POLICIES)}))


class EndedBy:
    """A parallel's ``ended_by``: when it ends, the name of the child whose ending ended it is written to a
    tree key (SMACH's Concurrence outcome map with several outcomes: which of them happened): the child
    that failed (under ``first_success``, the last of them); else the one that succeeded (under ``all``
    and ``succeed_on``, the last of those it waited for). Not written when the parallel is halted."""

    def __init__(self, ctx: Any, key: str, policy: str, waited: Tuple[int, ...] = ()):
        self.ctx, self.key, self.policy, self.waited = ctx, key, policy, waited
        self.order: List[py_trees.behaviour.Behaviour] = []   # children in the order they ended

    def start(self) -> None:
        self.order = []

    def note(self, parallel: py_trees.composites.Composite) -> None:
        """After each tick of ``parallel``: the children that ended, and its own end."""
        children = parallel.children
        self.order.extend(c for c in children if c.status in (Status.SUCCESS, Status.FAILURE) and c not in self.order)
        if parallel.status not in (Status.SUCCESS, Status.FAILURE):
            return
        ended = [c for c in self.order if c.status == parallel.status
                 and (parallel.status == Status.FAILURE or not self.waited or children.index(c) in self.waited)]
        if not ended:
            return
        if parallel.status == Status.FAILURE:   # (but first_success, one tick's failures end it: the first)
            last = self.policy == "first_success"
        else:
            last = self.policy == "all" or bool(self.waited)
        self.ctx.write(self.key, (ended[-1] if last else ended[0]).name)


class NamedEnd(py_trees.composites.Parallel):
    """py_trees' parallel, telling which child ended it (:class:`EndedBy`)."""

    def __init__(self, name: str, policy: Any, children: List[py_trees.behaviour.Behaviour], ended_by: EndedBy):
        super().__init__(name, policy=policy, children=children)
        self.ended_by = ended_by

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        if self.status != Status.RUNNING:
            self.ended_by.start()
        for node in super().tick():
            if node is self:
                self.ended_by.note(self)
            yield node


class FirstSuccess(py_trees.composites.Composite):
    """A parallel that succeeds at the first child that succeeds (the others halted) and fails only when
    every child has failed (BehaviorTree.CPP's Parallel with ``success_count: 1`` and ``failure_count``
    all: detectors racing). A child that failed is not ticked again; the failure's reason names each
    child's (its children are reset once it failed, so that the reason is the parallel's own)."""

    def __init__(self, name: str, children: List[py_trees.behaviour.Behaviour], ended_by: Optional[EndedBy] = None):
        super().__init__(name=name, children=children)
        self.failures: List[str] = []
        self.ended_by = ended_by

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        if self.status != Status.RUNNING:
            for child in self.children:
                if child.status != Status.INVALID:
                    child.stop(Status.INVALID)
            self.failures = []
            self.feedback_message = ""
            self.initialise()
            if self.ended_by is not None:
                self.ended_by.start()
        for child in self.children:
            if child.status == Status.FAILURE:   # it failed in an earlier tick: it stays failed
                continue
            yield from child.tick()
            if child.status == Status.FAILURE:
                self.failures.append("%s: %s" % (child.name, _failure_text(child)))
        winner = next((c for c in self.children if c.status == Status.SUCCESS), None)
        if winner is not None:
            self.current_child = winner
            self.feedback_message = "%s succeeded" % winner.name
            self._ended(Status.SUCCESS)
            self.stop(Status.SUCCESS)
        elif all(c.status == Status.FAILURE for c in self.children):
            self.current_child = self.children[-1] if self.children else None
            self.feedback_message = "all %d children failed: %s" % (len(self.children), "; ".join(self.failures))
            self._ended(Status.FAILURE)
            for child in self.children:   # (the reason is this one's, naming each failure)
                child.stop(Status.INVALID)
            self.stop(Status.FAILURE)
        else:
            self.status = Status.RUNNING
            self._ended(Status.RUNNING)
        yield self

    def _ended(self, status: Status) -> None:
        if self.ended_by is not None:   # (before its children are reset: which failed last)
            self.status = status
            self.ended_by.note(self)

    def stop(self, new_status: Status = Status.INVALID) -> None:
        for child in self.children:
            if child.status == Status.RUNNING:
                child.stop(Status.INVALID)
        py_trees.composites.Composite.stop(self, new_status)


def _failure_text(b: py_trees.behaviour.Behaviour) -> str:
    """The failure text of the deepest failed node under ``b`` (its own when none says more)."""
    for node in reversed(list(b.iterate())):
        if node.status == Status.FAILURE and node.feedback_message:
            return node.feedback_message
    return "failed"


class _Composite(NodeKind):
    family = "composite"
    value = ("children", "list of children")

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Any) -> Any:
        spec = self.spec(p, node, raw)
        p.children(node, value, at)
        if getattr(spec, "memory", True) is False:   # reactive: only its last lasting child may run
            from coordinator.reactive import restart_problems

            for where_, message in restart_problems(node):
                p.err(where_, message)
        return spec

    def spec(self, p: Any, node: TreeNode, raw: Any) -> Any:
        return MemorySpec(memory=p.opt(node, raw, self.option("memory")))

    def value_schema(self) -> Dict[str, Any]:
        inline = {"type": "object", "required": ["children"], "additionalProperties": False,
                  "properties": dict(self.schema_options(), children={"$ref": "#/definitions/children"},
                                     name={"type": "string"})}
        return {"anyOf": [{"$ref": "#/definitions/children"}, inline]}

    def schema_options(self) -> Dict[str, Any]:
        return {o.name: dict(TYPES[o.type].schema) for o in self.options}


class Sequence(_Composite):
    name = "sequence"
    summary = "children in order until one fails"
    options = (Option("memory", "bool", "a child that succeeded is not ticked again", default=True),)

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Succeeds when every child does, each reading what the earlier ones wrote; fails at a child that
        fails, after the earlier ones succeeded. Children after one that never succeeds never run: they
        are still checked, with what the others before them write."""
        cur = avail
        ok: FrozenSet[str] = frozenset()
        failed = NEVER
        for c in node.children:
            cs, cf = f.outcome(c, cur)
            if cf is not NEVER and ok is not NEVER:
                failed = meet((failed, ok | cf))
            ok = join(ok, cs)
            if cs:   # (NEVER is empty)
                cur = cur | cs
        return ok, failed

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return py_trees.composites.Sequence(node.name, memory=node.spec.memory,
                                            children=[child(c) for c in node.children])


class Selector(_Composite):
    name = "selector"
    summary = "children in order until one succeeds"
    options = (Option("memory", "bool", "`false` re-checks earlier children on every tick (reactive priorities)",
                      default=True),)

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Succeeds at the first child that does, the earlier ones having failed: a child that never
        succeeds (a ``force_failure`` fallback) is no way to succeed, so its writes are not required of
        the others. Fails when every child failed."""
        cur = avail
        ok = NEVER
        failed: FrozenSet[str] = frozenset()   # what the children so far surely wrote, all having failed
        for c in node.children:
            cs, cf = f.outcome(c, cur)
            ok = meet((ok, join(failed, cs)))
            failed = join(failed, cf)
            if cf:   # (NEVER is empty: the later children never run, and are checked as they are)
                cur = cur | cf
        return ok, failed

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return py_trees.composites.Selector(node.name, memory=node.spec.memory,
                                            children=[child(c) for c in node.children])


class Parallel(_Composite):
    name = "parallel"
    summary = ("children ticked together; it fails as soon as one child fails, halting the others (but with "
               "`policy: first_success`: when all have failed)")
    options = (Option("policy", "parallel_policy", "`all`: succeed when all do; `one`: succeed when one does, "
                                                   "halting the others (a child that fails first still fails the "
                                                   "parallel); `first_success`: succeed when one does, halting the "
                                                   "others, and fail only when all have failed (detectors racing; "
                                                   "a failed child is not run again)", default="all"),
               Option("succeed_on", "names", "instead of `policy`: succeed when the children of these names "
                                             "(their `name:`) have succeeded, halting the others (SMACH's "
                                             "Concurrence outcome map); any child failing still fails it"),
               Option("synchronise", "bool", "with `all` or `succeed_on`, a child that succeeded is not ticked "
                                             "again", default=True),
               Option("ended_by", "key", "a tree key given, when the parallel ends, the name of the child whose "
                                         "ending ended it (its `name:`): the one that failed (with "
                                         "`first_success`: the last to fail), else the one that succeeded (with "
                                         "`all` or `succeed_on`: the last awaited); not written when it is "
                                         "halted", shown="none"))

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Any) -> Any:
        policy = check_choice(p, raw, "policy", POLICIES, "all")
        synchronise = p.opt(node, raw, self.option("synchronise"))
        if "succeed_on" in raw and "policy" in raw:
            p.err(raw.key_pos["succeed_on"], "parallel takes 'succeed_on' or 'policy', not both: succeed_on (these "
                                             "children succeed) replaces policy (all or one)")
        p.children(node, value, at)
        selected: Tuple[int, ...] = ()
        if "succeed_on" in raw:   # the children's names are known now
            selected = _selected(p, node, raw["succeed_on"], raw.val_pos["succeed_on"])
        ended_by = p.opt(node, raw, self.option("ended_by")) if "ended_by" in raw else ""
        return ParallelSpec(policy=policy, synchronise=synchronise, succeed_on=selected, ended_by=ended_by or "")

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """py_trees' parallel fails as soon as any child fails (the others halted: only the failed one's
        writes are sure), under every policy. ``all`` succeeds when every child has; ``one`` when a child
        has and none failed (the others halted): what any child that can succeed writes; ``succeed_on``
        when the children it names have (the others halted): what those write. Its ``ended_by`` key is
        written either way."""
        ok, failed = self._outcome(node, avail, f)
        key = frozenset([node.spec.ended_by]) if node.spec.ended_by else frozenset()
        return join(ok, key), join(failed, key)

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        return {node.spec.ended_by: None} if node.spec.ended_by else {}

    def never_matches(self, node: TreeNode, key: str, label: Any, contains: bool, seen_from: Any) -> Optional[str]:
        """For a ``switch`` on its ``ended_by`` key: why case ``label`` is no child's name ('' when it may be;
        None for another key), as a call says of its status: a misspelt name would silently never run."""
        if key != node.spec.ended_by:
            return None
        names = [c.name for c in node.children]
        text = str(label)
        if (any(text.lower() in n.lower() for n in names) if contains else text in names):
            return ""
        return "case %r never matches: $%s is the name of the child that ended the parallel at %s, one of %s%s" % (
            label, key, where(node.pos, seen_from), ", ".join(repr(n) for n in names), did_you_mean(text, names))

    def _outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        outs = [f.outcome(c, avail) for c in node.children]   # together: none reads what another writes
        if not outs:
            return frozenset(), NEVER
        if node.spec.policy == "first_success":   # succeeds by one child (the others halted); fails when all did
            failed = frozenset()
            for _, cf in outs:
                failed = join(failed, cf)
            return meet(cs for cs, _ in outs), failed
        failed = meet(cf for _, cf in outs)
        if node.spec.succeed_on:
            ok: FrozenSet[str] = frozenset()
            for i in node.spec.succeed_on:
                ok = join(ok, outs[i][0])
            return ok, failed
        if node.spec.policy == "all":
            ok = frozenset()
            for cs, _ in outs:
                ok = join(ok, cs)
            return ok, failed
        return meet(cs for cs, _ in outs), failed

    def warnings(self, node: TreeNode) -> List[TreeError]:
        """Two children that can call non-concurrent functions of one module at the same time: the
        module rejects the second call (``busy with call …``), as it would on the robot."""
        per_child: List[List[Tuple[Any, TreeNode]]] = []
        for c in node.children:
            per_child.append([(fn, n) for n in walk(c) for fn in n.nodekind.functions(n) if not fn.concurrent])
        out = []
        for i, first in enumerate(per_child):
            for later in per_child[i + 1:]:
                for fa, na in first:
                    for fb, nb in later:
                        if fa.module == fb.module:
                            out.append(TreeError(nb.pos, "warning: %s can run while %s (%s) runs, under parallel %r "
                                                         "(%s): module %r runs one non-concurrent function at a "
                                                         "time and would reject it as busy" % (
                                                             fb.qualified, fa.qualified, where(na.pos, nb.pos),
                                                             node.name, where(node.pos, nb.pos), fa.module)))
        return out

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        children = [child(c) for c in node.children]
        spec = node.spec
        ended_by = EndedBy(ctx, spec.ended_by, spec.policy, spec.succeed_on) if spec.ended_by else None
        if spec.succeed_on:
            policy: py_trees.common.ParallelPolicy.Base = py_trees.common.ParallelPolicy.SuccessOnSelected(
                [children[i] for i in spec.succeed_on], synchronise=spec.synchronise)
        elif spec.policy == "first_success":
            return FirstSuccess(node.name, children, ended_by)
        elif spec.policy == "all":
            policy = py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=spec.synchronise)
        else:
            policy = py_trees.common.ParallelPolicy.SuccessOnOne()
        if ended_by is not None:
            return NamedEnd(node.name, policy, children, ended_by)
        return py_trees.composites.Parallel(node.name, policy=policy, children=children)


def _selected(p: Any, node: TreeNode, names: Any, at: Any) -> Tuple[int, ...]:
    """The positions of the children ``succeed_on`` names (by their ``name:``), after reporting each name
    that is not one child's (at the name)."""
    if not isinstance(names, list) or not names or not all(isinstance(n, str) and n for n in names):
        p.err(at, "succeed_on takes a non-empty list of the names of children (their 'name:'), e.g. "
                  "succeed_on: [follow]; got %r" % (names,))
        return ()
    named: Dict[str, List[TreeNode]] = {}
    for c in node.children:
        named.setdefault(c.name, []).append(c)
    given = {c.name for c in node.children if c.name != c.nodekind.default_name(c)}   # written with name:
    out: List[int] = []
    for i, name in enumerate(names):
        where_ = names.item_pos[i] if hasattr(names, "item_pos") else at
        found = named.get(name, [])
        if names.index(name) < i:
            p.err(where_, "succeed_on names %r twice: list it once" % name)
        elif len(found) > 1:
            p.err(where_, "succeed_on: %d children of this parallel are named %r (%s): give the one to wait "
                          "for a name of its own" % (len(found), name, ", ".join(where(c.pos, where_)
                                                                                  for c in found)))
        elif not found:
            p.err(where_, "succeed_on: no child of this parallel is named %r%s" % (name, _names_hint(name, given)))
        else:
            out.append(node.children.index(found[0]))
    return tuple(out) if len(out) == len(names) else ()


def _names_hint(name: str, given: Any) -> str:
    """What a misspelt child name is likely meant to be, or how children get names."""
    close = did_you_mean(name, given)
    if close:
        return close
    if not given:
        return " (no child has a name: succeed_on picks children by their 'name:'; give the one to wait for " \
               "name: %s)" % name
    return " (children are picked by their 'name:'; named here: %s)" % ", ".join(
        "%r" % n for n in sorted(given))


KINDS = (Sequence(), Selector(), Parallel())
