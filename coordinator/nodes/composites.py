"""Composites: ``sequence``, ``selector``, ``parallel`` (py_trees' own)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, FrozenSet, List, Tuple

import py_trees

from coordinator.errors import TreeError
from coordinator.nodes.base import TYPES, Flow, NodeKind, Option, check_choice
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

    def flow(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> FrozenSet[str]:
        cur = avail
        for c in node.children:
            written = c.nodekind.flow(c, cur, f)   # f.of(c, cur), without a call per child
            if written:
                cur = cur | written
        return cur - avail

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return py_trees.composites.Sequence(node.name, memory=node.spec.memory,
                                            children=[child(c) for c in node.children])


class Selector(_Composite):
    name = "selector"
    summary = "children in order until one succeeds"
    options = (Option("memory", "bool", "`false` re-checks earlier children on every tick (reactive priorities)",
                      default=True),)

    def flow(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> FrozenSet[str]:
        ws = [f.of(c, avail) for c in node.children]
        return frozenset.intersection(*ws) if ws else frozenset()

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return py_trees.composites.Selector(node.name, memory=node.spec.memory,
                                            children=[child(c) for c in node.children])


class Parallel(_Composite):
    name = "parallel"
    summary = "children ticked together"
    options = (Option("policy", "policy", "`all`: succeed when all do; `one`: succeed when one does, halting the "
                                          "others", default="all"),
               Option("synchronise", "bool", "with `all`, a child that succeeded is not ticked again",
                      default=True))

    def spec(self, p: Any, node: TreeNode, raw: Any) -> Any:
        return ParallelSpec(policy=check_choice(p, raw, "policy", ("all", "one"), "all"),
                            synchronise=p.opt(node, raw, self.option("synchronise")))

    def flow(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> FrozenSet[str]:
        ws = [f.of(c, avail) for c in node.children]
        if not ws:
            return frozenset()
        return frozenset().union(*ws) if node.spec.policy == "all" else frozenset.intersection(*ws)

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
                                                             fb.qualified, fa.qualified, _where(na.pos, nb.pos),
                                                             node.name, _where(node.pos, nb.pos), fa.module)))
        return out

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        if node.spec.policy == "all":
            policy = py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=node.spec.synchronise)
        else:
            policy = py_trees.common.ParallelPolicy.SuccessOnOne()
        return py_trees.composites.Parallel(node.name, policy=policy, children=[child(c) for c in node.children])


KINDS = (Sequence(), Selector(), Parallel())


def _where(pos: Any, seen_from: Any) -> str:
    return "line %d" % pos.line if pos.file == seen_from.file else "%s:%d" % (pos.file, pos.line)
