"""Errors of tree files: every one is ``file:line:column: message``."""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, NamedTuple, Sequence

__all__ = ["TreeError", "TreeErrors", "Pos"]


class Pos(NamedTuple):
    """Where something is written (a tuple: cheap, since every key and value gets one)."""

    file: str
    line: int
    column: int

    def __str__(self) -> str:
        return "%s:%d:%d" % (self.file, self.line, self.column)


@dataclass(frozen=True)
class TreeError:
    pos: Pos
    message: str

    def __str__(self) -> str:
        return "%s: %s" % (self.pos, self.message)


class TreeErrors(Exception):
    """All the problems found in a tree (and its includes), in file order."""

    def __init__(self, errors: Sequence[TreeError]):
        self.errors: List[TreeError] = sorted(set(errors), key=lambda e: (e.pos.file, e.pos.line, e.pos.column))
        super().__init__("\n".join(str(e) for e in self.errors))
