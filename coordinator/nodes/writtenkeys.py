"""The keys a node surely writes (the data-flow hooks' answers), and ``NEVER`` for an ending it cannot have.

Alternative paths ``meet`` (what every possible one writes), paths one after the other ``join``; a path
that cannot happen is ``NEVER`` and takes no part in either, so it cannot shrink what the others give.
"""
from __future__ import annotations

from typing import FrozenSet, Iterable

__all__ = ["NEVER", "join", "meet"]


class _Never(frozenset):  # type: ignore[type-arg]
    """The keys written when a node ends in a way it never can: all of them, vacuously (see ``NEVER``)."""

    __slots__ = ()


NEVER: FrozenSet[str] = _Never()
"""What the data-flow hooks say a node writes on an ending it cannot have (a ``force_failure`` never
succeeds): told apart by identity, it takes no part in a ``meet``. Code that does not know it reads it
as an empty set, nothing written, which is the cautious reading."""


def meet(sets: Iterable[FrozenSet[str]]) -> FrozenSet[str]:
    """The keys written whichever of these alternative paths was taken: what every possible one writes
    (``NEVER`` when none is possible). A path that cannot happen must not shrink what the others give."""
    out = NEVER
    for s in sets:
        if s is not NEVER:
            out = s if out is NEVER else out & s
    return out


def join(a: FrozenSet[str], b: FrozenSet[str]) -> FrozenSet[str]:
    """The keys written when both happened, one after the other (``NEVER`` when either cannot)."""
    if a is NEVER or b is NEVER:
        return NEVER
    return a | b if b else a
