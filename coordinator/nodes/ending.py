"""The leaf that ends a branch in FAILURE on purpose: ``fail: "text with {templates}"``.

A tree says "fail here, for this reason" (SMACH's outcome ``aborted``, BehaviorTree.CPP's
``AlwaysFailure`` with a message) without a ``check: 'false'`` whose reason would be ``false is false``.
The text is the failure's reason, so the run's reason names it: ``give up: the arm has a problem (code 2)``.
"""
from __future__ import annotations

from typing import Any, Dict, FrozenSet, Iterable, List, Tuple

from py_trees.common import Status

from coordinator.errors import Pos, TreeError
from coordinator.expr import text_of
from coordinator.nodes.base import NEVER, Flow, NodeKind
from coordinator.nodes.leafbase import Leaf
from coordinator.refs import RefError, refs_in, resolve
from coordinator.treeast import TreeNode
from coordinator.values import value_type_errors

__all__ = ["Fail", "FailKind", "KINDS"]


class Fail(Leaf):
    """FAILURE, its reason the node's text with its ``{…}`` holes filled now (or why they could not be)."""

    def update(self) -> Status:
        try:
            text = text_of(resolve(self.node.spec, self.ctx.lookup))
        except (KeyError, RefError) as exc:
            return self._fail("%s (its text could not be made: %s)" % (self.node.spec, exc.args[0] if exc.args
                                                                       else exc))
        return self._fail(text)


class FailKind(NodeKind):
    name = "fail"
    family = "leaf"
    value = ("value", "the reason: text with `{…}`, `$key` or `$( … )`")
    summary = ("FAILURE with that reason, its `{…}` filled from tree keys: fail here, on purpose (SMACH's "
               "outcome `aborted`)")

    def value_schema(self) -> Dict[str, Any]:
        return {"type": "string", "minLength": 1}

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> Any:
        text = p.literal_at(raw, self.name, at)   # (first: it knows text YAML read as a mapping, {code})
        if not isinstance(value, str) or not value.strip():
            p.err(at, "fail takes text (why the branch fails), got %s" % (
                "nothing" if value is None or value == "" else repr(value)))
            return "failed"
        return "failed" if text is None else text

    def default_name(self, node: TreeNode) -> str:
        return "fail"

    def reads(self, node: TreeNode) -> Iterable[str]:
        return [r.key for r in refs_in(node.spec)]

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Never succeeds; fails writing nothing. Its text's keys must be written before it."""
        f.need(node, self.reads(node), avail)
        nothing: FrozenSet[str] = frozenset()
        return NEVER, nothing

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        found = value_type_errors(node.spec, types)
        at = node.value_pos if found else None
        for off, msg in found if at is not None else ():
            errors.append(TreeError(Pos(at.file, at.line, at.column + off), msg))

    leaf = Fail


KINDS = (FailKind(),)
