"""Input limits checked before parsing: a hostile text must not reach a recursive parser."""
from __future__ import annotations

import re

from comm.errors import ProtocolError

__all__ = ["MAX_DEPTH", "check_depth"]

# ROS messages nest a few levels; anything deeper than this is an attack or a bug, and
# Python's JSON decoder and the message converter recurse (RecursionError, or worse).
MAX_DEPTH = 100
_STRINGS = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"')
_BRACKETS = re.compile(r"[\[\]{}]")


def check_depth(text: str, limit: int = MAX_DEPTH) -> None:
    """Refuse JSON text nested deeper than ``limit``, scanning the text before any parsing.

    Cheap: texts with fewer brackets than the limit (nearly all) are not scanned at all.
    """
    if text.count("[") + text.count("{") <= limit:
        return
    depth = 0
    for m in _BRACKETS.finditer(_STRINGS.sub("", text)):
        if m.group() in "[{":
            depth += 1
            if depth > limit:
                raise ProtocolError("JSON nested deeper than %d levels" % limit)
        else:
            depth -= 1
