"""Warnings for what a tree author meant that an expression does not do: ``{key}`` or ``$key`` inside a
quoted text is that text, not the key's value (``check: 'g == "{host}"'`` compares ``g`` with the eight
characters ``{host}``; a ``wait_event``'s ``where:``, which reads only the event's params, skipped every
event that way)."""
from __future__ import annotations

import re
from typing import Collection, List, Optional

from coordinator.errors import Pos, TreeError
from coordinator.expr import Expr

__all__ = ["quoted_key_warnings"]

_QUOTED = re.compile(r'"(?:[^"\\]|\\.)*"|\'(?:[^\'\\]|\\.)*\'')
_KEY = re.compile(r"\{\s*([^\W\d]\w*)\s*\}|\$([^\W\d]\w*)")


def quoted_key_warnings(expr: Optional[Expr], at: Optional[Pos], keys: Collection[str]) -> List[TreeError]:
    """A warning at each ``{key}``/``$key`` inside a quoted text of ``expr`` whose ``key`` is one of the tree's
    ``keys``."""
    if expr is None or at is None or ("{" not in expr.text and "$" not in expr.text):
        return []
    out = []
    for quoted in _QUOTED.finditer(expr.text):
        for m in _KEY.finditer(quoted.group(0)):
            key = m.group(1) or m.group(2)
            if key not in keys:
                continue
            fix = "an expression reads a key by its name, unquoted (%s)" % key
            off = quoted.start() + m.start()
            out.append(TreeError(Pos(at.file, at.line, at.column + off), "warning: %s inside a quoted text is that text, "
                                 "not the value of %s: %s" % (m.group(0), key, fix)))
    return out
