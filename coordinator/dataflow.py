"""Data flow: every key a node reads is written earlier on every path, or is a declared input."""
from __future__ import annotations

from typing import Any, FrozenSet, List, Optional

from coordinator.errors import TreeError
from coordinator.treeast import REQUIRED, Node, TreeFile, refs_in

__all__ = ["check_flow", "flow"]


def flow(node: Node, avail: FrozenSet[str], errors: List[TreeError], tree: TreeFile) -> FrozenSet[str]:
    """Keys surely written when ``node`` succeeds; reports reads of keys not surely written."""

    def need(keys: Any) -> None:
        for k in sorted(keys):
            if k not in avail:
                errors.append(TreeError(node.pos, "reads %r, which is not written on every path before this "
                                                   "node (write it earlier or declare it under 'inputs:')" % k))

    k, o = node.kind, node.opts
    if k == "sequence":
        cur = avail
        for c in node.children:
            cur = cur | flow(c, cur, errors, tree)
        return cur - avail
    if k in ("selector", "parallel"):
        ws = [flow(c, avail, errors, tree) for c in node.children]
        if not ws:
            return frozenset()
        if k == "parallel" and o.get("policy") == "all":
            return frozenset().union(*ws)
        return frozenset.intersection(*ws)
    if k in ("retry", "repeat", "timeout"):
        return flow(node.children[0], avail, errors, tree) if node.children else frozenset()
    if k in ("inverter", "force_success", "force_failure"):
        for c in node.children:
            flow(c, avail, errors, tree)
        return frozenset()
    if k == "call":
        need({r.key for r in refs_in(o.get("inputs", {}))})
        return frozenset(o.get("outputs", {}).values())
    if k == "wait_event":
        return frozenset(o.get("outputs", {}).values())
    if k == "recall":
        return frozenset(o.get("names", {}))
    if k == "set":
        need({r.key for r in refs_in(o.get("values", {}))})
        return frozenset(o.get("values", {}))
    if k == "check":
        need(o["expr"].keys if "expr" in o else ())
        return frozenset()
    if k == "include":
        need({r.key for r in refs_in(o.get("args", {}))})
        sub: Optional[TreeFile] = o.get("tree")
        if sub is None:
            return frozenset()
        bound = frozenset(o.get("args", {})) | frozenset(k2 for k2, v in sub.inputs.items() if v is not REQUIRED)
        return bound | flow(sub.root, bound | avail, errors, sub)
    return frozenset()


def check_flow(tree: TreeFile, given: FrozenSet[str] = frozenset()) -> List[TreeError]:
    """Every read of a key not surely written before it, for a whole tree."""
    errors: List[TreeError] = []
    avail = frozenset(k for k, v in tree.inputs.items() if v is not REQUIRED) | given | tree.required_inputs
    flow(tree.root, avail, errors, tree)
    return errors
