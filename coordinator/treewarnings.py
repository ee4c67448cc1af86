"""A tree's warnings: what the node kinds' checks warn about, and the errors that carry them along.

A tree with warnings runs (``load_tree`` keeps them on the tree); one with errors too raises
:class:`TreeErrorsWithWarnings`, whose text lists both, so the author fixes everything in one round.
"""
from __future__ import annotations

from typing import Any, List, Set

from coordinator.errors import TreeError, TreeErrors
from coordinator.treeast import TreeNode, kinds_in

__all__ = ["TreeErrorsWithWarnings", "warnings"]


class TreeErrorsWithWarnings(TreeErrors):
    """A tree's errors (``errors``), and its warnings (``warnings``) too in its text: fixing the errors
    first and only then learning of a warning takes one more round."""

    def __init__(self, errors: List[TreeError], warned: List[TreeError]):
        super().__init__(list(errors) + list(warned))   # the text: both, in file order
        said = set(warned)
        self.warnings = [e for e in self.errors if e in said]
        self.errors = [e for e in self.errors if e not in said]


def warnings(nodes: List[TreeNode]) -> List[TreeError]:
    """What the kinds' checks warn about (the tree runs, but likely not as meant)."""
    seen: Set[Any] = set()
    out: List[TreeError] = []
    if not any(nk.own_warnings for nk in kinds_in(nodes)):
        return out
    for n in nodes:
        nk = n.nodekind
        if not nk.own_warnings:   # the base warns about nothing
            continue
        found = nk.warnings(n)
        for w in found if found else ():
            if w not in seen:
                seen.add(w)
                out.append(w)
    return sorted(out, key=lambda e: (e.pos.file, e.pos.line, e.pos.column))
