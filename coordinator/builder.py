"""AST → py_trees: each node's kind builds its behaviour (``coordinator.nodes``)."""
from __future__ import annotations

from typing import Any, Dict, Optional

import py_trees

from coordinator.context import RunContext
from coordinator.errors import UsageError
from coordinator.treeast import REQUIRED, TreeFile, TreeNode, gc_paused, top_of

__all__ = ["build", "build_tree"]


def build(node: TreeNode, ctx: RunContext) -> py_trees.behaviour.Behaviour:
    """The behaviour for one validated node (and its subtree)."""

    def child(n: TreeNode) -> py_trees.behaviour.Behaviour:
        nk = n.nodekind
        leaf = nk.leaf   # a leaf's class made here: one call fewer per leaf
        b = leaf(n, ctx) if leaf is not None else nk.build(n, ctx, child)
        b.bmtree_node = n  # type: ignore[attr-defined]
        return b

    with gc_paused():
        return child(node)


def build_tree(tree: TreeFile, ctx: RunContext, inputs: Optional[Dict[str, Any]] = None) -> py_trees.behaviour.Behaviour:
    """The root behaviour (with ``cleanup:``, the ``WithCleanup`` above root and cleanup); the tree's declared
    inputs are set on the tree blackboard first."""
    missing = [k for k in tree.required_inputs if k not in (inputs or {})]
    if missing:
        raise UsageError("tree input%s %s must be given" % ("s" if len(missing) > 1 else "",
                                                            ", ".join(repr(m) for m in missing)))
    values = {k: v for k, v in tree.inputs.items() if v is not REQUIRED}
    values.update(inputs or {})
    for k, v in ctx.resolve(values).items():
        ctx.write(k, v)
    return build(top_of(tree), ctx)
