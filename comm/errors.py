"""Exception bases shared by every package, and the one exception class of the wire protocol.

``InvalidInput`` (a tree, a definition, an argument, a payload is wrong: exit 2) and
``EnvironmentProblem`` (no master, modules missing, a tool not installed: exit 3) are the two
shapes the command line maps to exit codes; every package derives its errors from one of them.
They live here because ``comm`` is the package every other one may import.
"""
from __future__ import annotations

import difflib
from typing import Any, Iterable

__all__ = ["EnvironmentProblem", "InvalidInput", "ProtocolError", "TooLarge", "did_you_mean"]


class InvalidInput(Exception):
    """Something the user gave is wrong (tree, definition, argument, payload): exit code 2."""


class EnvironmentProblem(OSError):
    """The world around bmtree is not as needed (no master, module missing, tool missing): exit code 3.

    An ``OSError``, so callers that already handle operating-system failures handle these too.
    """


class ProtocolError(InvalidInput, ValueError):
    """A payload or value that does not follow the bmtree wire protocol.

    The message always names the problem (the key, the index, the ROS type), so
    that a log line is enough to find the sender's mistake.
    """


class TooLarge(ProtocolError):
    """A payload over the receiver's size limit: well formed perhaps, but refused unread (what to raise
    is the receiver's ``--max-bytes``)."""


def did_you_mean(word: Any, choices: Iterable[Any]) -> str:
    """`` (did you mean 'x'?)`` for the closest choice, or ``''``: every error hint says it the same way."""
    match = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1)
    return " (did you mean %r?)" % match[0] if match else ""
