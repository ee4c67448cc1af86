"""The tree language's syntax tree: what the parser produces and the builder consumes."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, FrozenSet, List, Set, Tuple

from coordinator.errors import Pos

__all__ = ["REQUIRED", "Node", "Ref", "TreeFile", "refs_in", "used_modules", "walk"]


@dataclass(frozen=True)
class Ref:
    """``$key.field[0]`` in a YAML value: read from the tree blackboard when the node starts."""

    key: str
    path: Tuple[Any, ...] = ()

    def __str__(self) -> str:
        return "$" + self.key + "".join("[%d]" % p if isinstance(p, int) else "." + p for p in self.path)


@dataclass
class Node:
    kind: str
    name: str
    pos: Pos
    children: List[Node] = field(default_factory=list)
    opts: Dict[str, Any] = field(default_factory=dict)


@dataclass
class TreeFile:
    path: str
    name: str
    description: str
    inputs: Dict[str, Any]            # name -> default (REQUIRED if none)
    root: Node
    required_inputs: FrozenSet[str] = frozenset()


REQUIRED = object()  # an input without a default


def refs_in(value: Any) -> List[Ref]:
    if isinstance(value, Ref):
        return [value]
    if isinstance(value, dict):
        return [r for v in value.values() for r in refs_in(v)]
    if isinstance(value, list):
        return [r for v in value for r in refs_in(v)]
    return []


def walk(node: Node) -> Any:
    """Every node of a tree, includes expanded, depth first."""
    yield node
    for c in node.children:
        yield from walk(c)
    sub = node.opts.get("tree")
    if sub is not None:
        yield from walk(sub.root)


def used_modules(tree: TreeFile) -> Tuple[Set[str], bool]:
    """The modules a tree calls or waits on, and whether it recalls from the Blackboard node."""
    mods: Set[str] = set()
    recall = False
    for n in walk(tree.root):
        if n.kind in ("call", "wait_event") and isinstance(n.opts.get("target"), str):
            mods.add(n.opts["target"].split(".")[0])
        recall = recall or n.kind == "recall"
    return mods, recall
