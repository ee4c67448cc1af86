"""``include``: a subtree from another file, its ``inputs`` bound by ``args``."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, FrozenSet, Iterable, List, Optional

import py_trees

from comm.errors import did_you_mean
from coordinator.errors import Pos, TreeError
from coordinator.nodes.base import Flow, NodeKind, Option
from coordinator.nodes.leaves import SetKeys
from coordinator.refs import refs_in
from coordinator.treeast import REQUIRED, TreeFile, TreeNode
from coordinator.values import at_value_errors, read_at

__all__ = ["IncludeSpec", "KINDS"]


@dataclass
class IncludeSpec:
    path: Any
    args: Dict[str, Any] = field(default_factory=dict)
    tree: Optional[TreeFile] = None
    arg_pos: Dict[str, Pos] = field(default_factory=dict)   # where each argument's value is written

    def bound(self) -> Dict[str, Any]:
        """What the include sets when it starts: the subtree's defaults, then the arguments."""
        values = {k: v for k, v in self.tree.inputs.items() if v is not REQUIRED} if self.tree else {}
        values.update(self.args)
        return values


class IncludeKind(NodeKind):
    name = "include"
    family = "leaf"
    value = ("path", "a tree file (relative to this file)")
    summary = "the subtree, run as a sequence after setting its inputs"
    options = (Option("args", "inputs", "input name → value"),)

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> IncludeSpec:
        args_raw = p.mapping(raw, "args", at, "'args' must be a mapping of input name: value")
        spec = IncludeSpec(path=value, args={k: p.literal_at(args_raw, k, at) for k in args_raw},
                           arg_pos={k: args_raw.val_pos[k] for k in args_raw})
        if not isinstance(value, str) or not value:
            p.err(at, "include takes a file path")
            return spec
        sub = p.include(value, at)
        if sub is None:
            return spec
        spec.tree = sub
        for k in spec.args:
            if k not in sub.inputs:
                p.err(args_raw.key_pos[k], "%s has no input %r%s" % (value, k, did_you_mean(k, sub.inputs)
                                                                      or " (inputs: %s)" % (", ".join(sub.inputs)
                                                                                            or "none")))
        for k in sorted(sub.required_inputs - set(spec.args)):
            p.err(at, "include of %s needs argument %r" % (value, k))
        return spec

    def default_name(self, node: TreeNode) -> str:
        spec = node.spec
        if spec.tree is None:
            return self.name
        args = spec.args
        return "%s%s" % (spec.tree.name, "(%s)" % ", ".join("%s=%s" % kv for kv in args.items()) if args else "")

    def reads(self, node: TreeNode) -> Iterable[str]:
        return [r.key for r in refs_in(node.spec.args)]

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        return dict.fromkeys(node.spec.bound())

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        where = node.spec.arg_pos
        for k, v in node.spec.args.items():
            at_value_errors(v, where[k] if k in where else node.pos, types, errors)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        where = node.spec.arg_pos
        return next((p for p in (read_at(v, where[k], key) for k, v in node.spec.args.items() if k in where)
                     if p is not None), None)

    def flow(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> FrozenSet[str]:
        f.need(node, self.reads(node), avail)
        sub = node.spec.tree
        if sub is None:
            return frozenset()
        bound = frozenset(node.spec.bound())
        return bound | f.of(sub.root, bound | avail)

    def expand(self, node: TreeNode) -> List[TreeNode]:
        return [node.spec.tree.root] if node.spec.tree is not None else []

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        sub = node.spec.tree
        values = node.spec.bound()
        kids = []
        if values:
            setter = TreeNode("set", "arguments of %s" % sub.name, node.pos, spec=values)
            kids.append(SetKeys(setter, ctx))
        kids.append(child(sub.root))
        return py_trees.composites.Sequence(name=node.name, memory=True, children=kids)


KINDS = (IncludeKind(),)

