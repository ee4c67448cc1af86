"""Composites: ``sequence``, ``selector``, ``parallel`` (py_trees' own)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, FrozenSet, List, Tuple

import py_trees

from coordinator.errors import TreeError
from coordinator.nodes.base import NEVER, TYPES, Flow, NodeKind, Option, check_choice, join, meet, where
from coordinator.treeast import TreeNode, walk

__all__ = ["KINDS", "MemorySpec", "ParallelSpec"]


@dataclass(frozen=True)
class MemorySpec:
    memory: bool = True


@dataclass(frozen=True)
class ParallelSpec:
    policy: str = "all"
    synchronise: bool = True


class _Composite(NodeKind):
    family = "composite"
    value = ("children", "list of children")

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Any) -> Any:
        spec = self.spec(p, node, raw)
        p.children(node, value, at)
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
    summary = "children ticked together; under either policy it fails as soon as one child fails, halting the others"
    options = (Option("policy", "policy", "`all`: succeed when all do; `one`: succeed when one does, halting the "
                                          "others (a child that fails first still fails the parallel: wrap it in "
                                          "`force_success` to let the others go on)", default="all"),
               Option("synchronise", "bool", "with `all`, a child that succeeded is not ticked again",
                      default=True))

    def spec(self, p: Any, node: TreeNode, raw: Any) -> Any:
        return ParallelSpec(policy=check_choice(p, raw, "policy", ("all", "one"), "all"),
                            synchronise=p.opt(node, raw, self.option("synchronise")))

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """py_trees' parallel fails as soon as any child fails (the others halted: only the failed one's
        writes are sure), under either policy. ``all`` succeeds when every child has; ``one`` when a child
        has and none failed (the others halted): what any child that can succeed writes."""
        outs = [f.outcome(c, avail) for c in node.children]   # together: none reads what another writes
        if not outs:
            return frozenset(), NEVER
        failed = meet(cf for _, cf in outs)
        if node.spec.policy == "all":
            ok: FrozenSet[str] = frozenset()
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
        if node.spec.policy == "all":
            policy = py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=node.spec.synchronise)
        else:
            policy = py_trees.common.ParallelPolicy.SuccessOnOne()
        return py_trees.composites.Parallel(node.name, policy=policy, children=[child(c) for c in node.children])


KINDS = (Sequence(), Selector(), Parallel())
