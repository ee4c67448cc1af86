"""``set``: write values to tree keys (literals, ``$references``, ``$( … )`` expressions, ``{…}`` templates);
what it writes gives the checks its keys' types or kinds (see :mod:`coordinator.keykinds`). Its kind is
registered with the other leaves (``coordinator.nodes.leaves.KINDS``)."""
from __future__ import annotations

import re
from typing import Any, Dict, FrozenSet, Iterable, List, Optional, Tuple

from py_trees.common import Status

from coordinator.errors import Pos, TreeError
from coordinator.expr import Expr, ExprError
from coordinator.nodes.base import NEVER, Flow, NodeKind
from coordinator.nodes.leafbase import Leaf
from coordinator.refs import RefError, refs_in, resolve
from coordinator.treeast import TreeNode
from coordinator.values import read_at, value_type_errors

__all__ = ["SetKeys", "SetKind"]


class SetKeys(Leaf):
    written: Optional[Dict[str, Any]] = None  # the values of its last success

    def update(self) -> Status:
        try:
            values: Dict[str, Any] = resolve(self.node.spec, self.ctx.lookup)
        except (KeyError, RefError) as exc:
            return self._fail(str(exc.args[0] if exc.args else exc))
        for k, v in values.items():
            self.ctx.write(k, v)
        self.written = values  # an include's arguments: a failure under it names them (search_room(room="kitchen"))
        return Status.SUCCESS


class SetSpec(dict):
    """Tree key -> value, with where each value is written (``pos``)."""

    pos: Dict[str, Pos] = {}


class SetKind(NodeKind):
    name = "set"
    family = "leaf"
    value = ("values", "tree key → value")
    summary = "write values (literals, `$references`, `$( … )` expressions, `{…}` templates) to tree keys"

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> Dict[str, Any]:
        m = p.keys(node, value, at, "tree key: value")
        keys = [k for k in (m or {}) if isinstance(k, str)]   # others are errors already (an unquoted on: true)
        spec = SetSpec((k, p.literal_at(m, k, at)) for k in keys)
        spec.pos = {k: m.val_pos[k] for k in keys}
        return spec

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        for k, v in node.spec.items():
            at = getattr(node.spec, "pos", {}).get(k, node.pos)
            for off, msg in value_type_errors(v, types):
                errors.append(TreeError(Pos(at.file, at.line, at.column + off), msg))
            meant = _expression_text(v, types)
            if meant:
                errors.append(TreeError(at, "warning: %s: %r is stored as that text, not worked out: did you mean "
                                            "\"$(%s)\"?" % (k, v, meant)))

    def default_name(self, node: TreeNode) -> str:
        return "set %s" % ", ".join(node.spec)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        where = getattr(node.spec, "pos", {})
        return next((p for p in (read_at(v, where[k], key) for k, v in node.spec.items() if k in where)
                     if p is not None), None)

    def reads(self, node: TreeNode) -> Iterable[str]:
        return [r.key for r in refs_in(node.spec)]

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        return dict.fromkeys(node.spec)

    own_outcome = True

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Its keys when it succeeds; it fails only when a value it reads cannot be worked out, so a ``set`` of
        literals never fails (the keys it wrote before a later step failed are there in a selector's next child)."""
        read = list(self.reads(node))
        if read:
            f.need(node, read, avail)
        return frozenset(self.writes(node)), (frozenset() if read else NEVER)

    def copies(self, node: TreeNode) -> Dict[str, Any]:
        """Every value it writes: a key set to ``$pose`` or ``$g.position`` holds what it holds; one set to a
        literal, a ``{…}`` template or an expression, a value of its kind (a number, text...)."""
        return dict(node.spec)

    leaf = SetKeys


_OPERATOR = re.compile(r"[-+*/<>]|==|!=|\w\(")   # (not the words and, or, not, in: ordinary text has them)
_NAME = re.compile(r"[^\W\d]\w*(\.[^\W\d]\w*)*$")


def _expression_text(value: Any, keys: Dict[str, set]) -> str:
    """The expression a ``set`` value of plain text reads as, when it surely is one (``counter + 1`` with
    ``counter`` a key of the tree: it is stored as text); '' for ordinary text: words (also joined by and,
    or, not, in), a name alone, text that does not parse, or that reads a name no node writes and no
    input declares."""
    if not isinstance(value, str) or not _OPERATOR.search(value) or _NAME.match(value.strip()):
        return ""
    try:
        expr = Expr.parse(value)
    except ExprError:
        return ""
    if not expr.refs or not all(r.key in keys for r in expr.refs):
        return ""
    return value.strip()
