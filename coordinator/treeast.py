"""The tree language's syntax tree: what the parser produces and the builder consumes."""
from __future__ import annotations

import contextlib
import gc
import operator
from dataclasses import dataclass, field
from typing import Any, Dict, FrozenSet, Iterator, List, Optional, Set, Tuple

from coordinator.errors import Pos, TreeError
from coordinator.yamlsrc import OnDemandPos, settle

__all__ = ["REQUIRED", "TreeFile", "TreeNode", "gc_paused", "kinds_in", "nodes_of", "top_of", "used_modules", "walk"]


class TreeNode(OnDemandPos):
    """One node as written: its kind's typed ``spec`` (see ``coordinator.nodes``) and its children.

    ``nodekind`` is the registry's object for ``kind``: every generic walk (data flow, build,
    used modules) asks it, so no walk knows the kinds. (A plain class with slots: a tree has
    thousands of these.) ``pos`` and ``value_pos`` may be given as the YAML loader stores them,
    with ``file``: they become ``Pos`` when first read (most never are).
    """

    __slots__ = ("kind", "name", "_pos", "children", "spec", "nodekind", "_value_pos", "_file")

    def __init__(self, kind: str, name: str, pos: Pos, children: Optional[List[TreeNode]] = None,
                 spec: Any = None, nodekind: Any = None, value_pos: Optional[Pos] = None,
                 file: Optional[str] = None):
        self.kind = kind
        self.name = name
        self._pos = pos
        self.children: List[TreeNode] = [] if children is None else children
        self.spec = spec
        self.nodekind = nodekind
        self._value_pos = value_pos   # where the kind's value is written
        self._file = file

    @property
    def value_pos(self) -> Optional[Pos]:
        p = self._value_pos
        if self._file is not None and p is not None and p.__class__ is not Pos:
            p = self._value_pos = settle(p, self._file)
        return p

    @value_pos.setter
    def value_pos(self, value: Optional[Pos]) -> None:
        self._settled()
        self._value_pos = value

    def _settle_all(self) -> None:
        self.pos  # noqa: B018 - settles them
        self.value_pos  # noqa: B018

    def __repr__(self) -> str:
        return "TreeNode(%s %r at %s)" % (self.kind, self.name, self.pos)


@dataclass(eq=False)
class TreeFile:
    path: str
    name: str
    description: str
    inputs: Dict[str, Any]            # name -> default (REQUIRED if none)
    root: TreeNode
    required_inputs: FrozenSet[str] = frozenset()
    warnings: List[TreeError] = field(default_factory=list)   # found by the checks; the tree still runs
    cleanup: Optional[TreeNode] = None    # ``cleanup:``: run after the root however it ended (run tree only)
    cleanup_timeout: float = 30.0         # ``cleanup_timeout:``: seconds the cleanup may run
    top: Optional[TreeNode] = None        # with a cleanup: the node above root and cleanup (nodes/task.py)
    reserved_inputs: Dict[str, Pos] = field(default_factory=dict)   # inputs named as cleanup's keys: where


def top_of(tree: TreeFile) -> TreeNode:
    """The node a run of ``tree`` starts from: its root, or with ``cleanup:`` the node above both
    (every whole-tree walk goes from here; an include runs only the root of the file it includes)."""
    return tree.top if tree.top is not None else tree.root


REQUIRED = object()  # an input without a default


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """Loading and building allocate tens of thousands of small objects that live as long as the tree.

    The cycle collector's young-generation passes over them cost a quarter of the load time and
    find nothing; so it waits, and at the end the new objects join the oldest generation directly
    (``gc.freeze`` then ``gc.unfreeze``: two list splices) where they are looked at only by the
    rare full collections.
    """
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if gc.get_freeze_count() == 0:   # nobody else froze objects: we may move everything back to gen 2
            gc.freeze()
            gc.unfreeze()
        if was:
            gc.enable()


def walk(node: TreeNode) -> Iterator[TreeNode]:
    """Every node of a tree, includes expanded, depth first (a stack: no generator per level)."""
    stack = [node]
    while stack:
        n = stack.pop()
        yield n
        nk = n.nodekind
        below = nk.expand(n) if nk.own_expand else n.children
        if below:
            stack.extend(reversed(below))


def nodes_of(node: TreeNode) -> List[TreeNode]:
    """The list of :func:`walk` (in its order), made without a generator."""
    out: List[TreeNode] = []
    stack = [node]
    append, pop = out.append, stack.pop
    while stack:
        n = pop()
        append(n)
        nk = n.nodekind
        below = nk.expand(n) if nk.own_expand else n.children   # the base's expand, without a call
        if below:
            stack.extend(reversed(below))
    return out


def kinds_in(nodes: List[TreeNode]) -> Set[Any]:
    """The kinds (registry objects) of these nodes: a walk asks them whether it has anything to do."""
    return set(map(_NODEKIND, nodes))


_NODEKIND = operator.attrgetter("nodekind")


def used_modules(tree: TreeFile) -> Tuple[Set[str], bool]:
    """The modules a tree calls or waits on, and whether it asks the Blackboard node."""
    mods: Set[str] = set()
    recall = False
    for n in walk(top_of(tree)):
        mods.update(n.nodekind.modules(n))
        recall = recall or n.nodekind.uses_blackboard_node
    return mods, recall
