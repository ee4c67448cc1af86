"""AST → py_trees: one function per node kind, all through one registry."""
from __future__ import annotations

from typing import Any, Callable, Dict, Optional

import py_trees

from coordinator import behaviours as B
from coordinator.context import RunContext
from coordinator.treeast import REQUIRED, Node, TreeFile

__all__ = ["build", "build_tree"]

Builder = Callable[[Node, RunContext], py_trees.behaviour.Behaviour]


def _children(node: Node, ctx: RunContext) -> list:
    return [build(c, ctx) for c in node.children]


def _include(node: Node, ctx: RunContext) -> py_trees.behaviour.Behaviour:
    sub: TreeFile = node.opts["tree"]
    values: Dict[str, Any] = {k: v for k, v in sub.inputs.items() if v is not REQUIRED}
    values.update(node.opts.get("args", {}))
    kids = []
    if values:
        kids.append(B.SetKeys(Node("set", "arguments of %s" % sub.name, node.pos, opts={"values": values}), ctx))
    kids.append(build(sub.root, ctx))
    seq = py_trees.composites.Sequence(name=node.name, memory=True, children=kids)
    return seq


_BUILDERS: Dict[str, Builder] = {
    "sequence": lambda n, c: py_trees.composites.Sequence(n.name, memory=n.opts["memory"], children=_children(n, c)),
    "selector": lambda n, c: py_trees.composites.Selector(n.name, memory=n.opts["memory"], children=_children(n, c)),
    "parallel": lambda n, c: py_trees.composites.Parallel(
        n.name, policy=(py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=n.opts["synchronise"])
                        if n.opts["policy"] == "all" else
                        py_trees.common.ParallelPolicy.SuccessOnOne()),
        children=_children(n, c)),
    "retry": lambda n, c: B.Retry(n.name, build(n.children[0], c), n.opts["times"], c),
    "repeat": lambda n, c: B.Repeat(n.name, build(n.children[0], c), n.opts["times"], c),
    "timeout": lambda n, c: B.Timeout(n.name, build(n.children[0], c), n.opts["seconds"], c),
    "inverter": lambda n, c: py_trees.decorators.Inverter(n.name, build(n.children[0], c)),
    "force_success": lambda n, c: py_trees.decorators.FailureIsSuccess(n.name, build(n.children[0], c)),
    "force_failure": lambda n, c: py_trees.decorators.SuccessIsFailure(n.name, build(n.children[0], c)),
    "call": B.Call,
    "recall": B.Recall,
    "check": B.Check,
    "wait_event": B.WaitEvent,
    "set": B.SetKeys,
    "wait": B.Wait,
    "include": _include,
}


def build(node: Node, ctx: RunContext) -> py_trees.behaviour.Behaviour:
    """The behaviour for one validated node (and its subtree)."""
    b = _BUILDERS[node.kind](node, ctx)
    b.bmtree_node = node  # type: ignore[attr-defined]
    return b


def build_tree(tree: TreeFile, ctx: RunContext, inputs: Optional[Dict[str, Any]] = None) -> py_trees.behaviour.Behaviour:
    """The root behaviour; the tree's declared inputs are set on the tree blackboard first."""
    missing = [k for k in tree.required_inputs if k not in (inputs or {})]
    if missing:
        raise ValueError("tree input%s %s must be given" % ("s" if len(missing) > 1 else "",
                                                            ", ".join(repr(m) for m in missing)))
    values = {k: v for k, v in tree.inputs.items() if v is not REQUIRED}
    values.update(inputs or {})
    ctx.blackboard.update(ctx.resolve(values))
    return build(tree.root, ctx)
