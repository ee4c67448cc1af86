"""A subtree that reads its caller's keys: the reads that pass only because the caller wrote the key.

The blackboard is shared, so a subtree may read a key its caller holds without declaring it in ``inputs:``;
checked alone it is refused, checked through its caller it passes, and a second caller without that key
breaks it. The include walks its subtree a second time with only what the subtree is given (its inputs,
set by the include): a read missed there but not in the real walk reads the caller's key (a warning).
"""
from __future__ import annotations

import os
import weakref
from typing import Dict, FrozenSet, List, Set, Tuple

from coordinator.errors import Pos, TreeError
from coordinator.nodes.base import Flow, where
from coordinator.nodes.task import CLEANUP_KEYS
from coordinator.treeast import TreeFile, TreeNode, nodes_of

__all__ = ["Alone", "caller_key_reads"]

_CLEANUP_KEYS = frozenset(CLEANUP_KEYS)
Missed = List[Tuple[TreeNode, str, FrozenSet[str]]]
_walked: weakref.WeakKeyDictionary[Flow, Dict[Tuple[Tuple[int, ...], FrozenSet[str]], Missed]] = \
    weakref.WeakKeyDictionary()


class Alone(Flow):
    """The walk of a subtree with only its own keys, beside the real one (``main``): it shares the real
    walk's view of the whole tree (the writers of a key, the files being walked) and reports nothing;
    an include met in it does not look for clashes or reads of its caller's keys (the real walk does)."""

    def __init__(self, main: Flow, sub: TreeFile):
        super().__init__([], main.tree)
        self.main = main
        self.files = list(main.files) + [sub]
        self.cleanup_nodes = main.cleanup_nodes

    def writers(self, key: str) -> List[TreeNode]:
        return self.main.writers(key)

    def file_writes(self, tree: TreeFile) -> Dict[str, TreeNode]:
        return self.main.file_writes(tree)


def caller_key_reads(node: TreeNode, sub: TreeFile, own: FrozenSet[str], avail: FrozenSet[str], seen: Missed,
                     f: Flow) -> List[TreeError]:
    """A warning at the include ``node`` for each key a node of ``sub``'s own file reads that only the
    caller's keys (``avail``) give it: missed by a walk of ``sub`` with ``own`` (its inputs, as the include
    sets them; and in a cleanup, bmtree's keys of how root ended), not by the real walk (``seen``: what that
    one missed inside ``sub``, reported as errors already)."""
    given = own | (avail & _CLEANUP_KEYS)
    walks = _walked.setdefault(f, {})   # a file included N times with the same keys is walked alone once
    key = (tuple(id(t) for t in f.files) + (id(sub),), given)   # (the files up: their inputs count)
    missed = walks.get(key)
    if missed is None:
        alone = Alone(f, sub)
        alone.outcome(sub.root, given)
        missed = walks[key] = alone.missed
    if not missed:
        return []
    already: Set[Tuple[int, str]] = {(id(n), k) for n, k, _ in seen}
    here = sub.root.pos.file
    first: Dict[str, Pos] = {}
    for n, k, _ in missed:
        if n.pos.file != here or (id(n), k) in already:   # (a nested file's reads: its own include says so)
            continue
        at = n.nodekind.read_pos(n, k) or n.pos
        if k not in first or (at.line, at.column) < (first[k].line, first[k].column):
            first[k] = at
    name = os.path.basename(sub.path)
    out = []
    inside = {id(n) for n in nodes_of(sub.root)} if first else set()
    for k, at in sorted(first.items()):
        writer = next((w for w in f.writers(k) if id(w) in inside), None)
        said = ("which it neither declares in inputs: nor writes" if writer is None else
                "which it neither declares in inputs: nor writes on every path before it (it writes it at %s)"
                % where(writer.pos, at))
        out.append(TreeError(node.pos, "warning: %s reads %r (line %d), %s: it reads the caller's key; declare it "
                                       "under its inputs: and pass it in args: {%s: $%s}" % (
                                           name, k, at.line, said, k, k)))
    return out
