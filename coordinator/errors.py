"""Errors of the coordinator: the two shapes (invalid input, environment) and tree-file errors.

Every tree error is ``file:line:column: message``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, NamedTuple, Sequence

from comm.errors import EnvironmentProblem, InvalidInput

__all__ = ["EnvironmentProblem", "InvalidInput", "Pos", "TreeError", "TreeErrors", "UsageError"]


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
    module: str = ""  # an unknown module with no close known name: perhaps one not started yet

    def __str__(self) -> str:
        return "%s: %s" % (self.pos, self.message)


class TreeErrors(InvalidInput):
    """All the problems found in a tree (and its includes), in file order."""

    def __init__(self, errors: Sequence[TreeError]):
        self.errors: List[TreeError] = sorted(set(errors), key=lambda e: (e.pos.file, e.pos.line, e.pos.column))
        super().__init__("\n".join(str(e) for e in self.errors))


class UsageError(InvalidInput):
    """A wrong command-line argument or API argument (a tree input not given, a bad option value)."""
