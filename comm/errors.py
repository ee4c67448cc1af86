"""The one exception class of the wire protocol."""
from __future__ import annotations

import difflib
from typing import Any, Iterable

__all__ = ["ProtocolError", "did_you_mean"]


class ProtocolError(ValueError):
    """A payload or value that does not follow the bmtree wire protocol.

    The message always names the problem (the key, the index, the ROS type), so
    that a log line is enough to find the sender's mistake.
    """


def did_you_mean(word: Any, choices: Iterable[Any]) -> str:
    """`` (did you mean 'x'?)`` for the closest choice, or ``''``: every error hint says it the same way."""
    match = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1)
    return " (did you mean %r?)" % match[0] if match else ""
