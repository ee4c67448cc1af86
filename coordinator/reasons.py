"""Why a run failed: the root cause, not the decorator that passed the failure up.

A failure *originates* in a leaf (a call's status and error, a false check), a
``timeout`` that fired or an ``inverter`` whose child succeeded. ``force_failure``
only reports a failure decided elsewhere, and a failure that an ancestor later
recovered from (a selector moved on to a child that succeeded, a retry succeeded)
is not the cause. The reason names the latest unrecovered origin, and how many
attempts a ``retry`` above it made before giving up:
``go to the room: navigation.go_to failed: blocked (3 of 3 attempts)``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

import py_trees
from py_trees.common import Status

from coordinator.nodes.decorators import Retry
from coordinator.runevents import Change, RunObserver

__all__ = ["FailureExplainer", "Origin"]


@dataclass
class Origin:
    """One failure where it started."""

    seq: int
    behaviour: Any
    message: str
    time: float


def _originates(b: Any) -> bool:
    """True if ``b`` failed by itself: a leaf, or a decorator or composite that failed with its own
    reason while none of its children failed (a timeout that fired, a loop that hit its maximum,
    a switch without a matching case); ``force_failure`` only reports."""
    if isinstance(b, py_trees.decorators.SuccessIsFailure):
        return False
    if isinstance(b, py_trees.decorators.Inverter):
        return True
    if not b.children:
        return True
    return bool(b.feedback_message) and all(c.status != Status.FAILURE for c in b.children)


def _ancestors(b: Any) -> List[Any]:
    out = []
    p = b.parent
    while p is not None:
        out.append(p)
        p = p.parent
    return out


class FailureExplainer(RunObserver):
    """Watches status changes; :meth:`reason` explains a FAILURE of the root."""

    def __init__(self) -> None:
        self._seq = 0
        self._succeeded: Dict[Any, int] = {}
        self._origins: List[Origin] = []
        self._gave_up: Dict[Any, Tuple[int, int, int]] = {}  # retry -> (seq, runs, times)

    def on_tick(self, root: Any, changes: List[Change], now: float) -> None:
        fired: List[Origin] = []
        for b, old, new in changes:
            self._seq += 1
            if new is Status.SUCCESS:
                self._succeeded[b] = self._seq
            elif new is Status.FAILURE:
                if _originates(b):
                    self._origins.append(Origin(self._seq, b, b.feedback_message or "failed", now))
                    del self._origins[:-64]  # only recent ones can be the cause
                    if b.children:
                        fired.append(self._origins[-1])
                if isinstance(b, Retry) and isinstance(getattr(b, "times", None), int):
                    self._gave_up[b] = (self._seq, b.runs, b.times)
            elif new is Status.INVALID and old is Status.RUNNING and (
                    not b.children or getattr(b, "resume_at", None) is not None):
                for o in fired:  # a timeout halted this leaf (or a retry waiting out its delay): say what ran
                    if o.behaviour in _ancestors(b):
                        said = " (%s)" % b.feedback_message if b.children and b.feedback_message else ""
                        o.message += " while '%s'%s was running" % (b.name, said)

    def root_cause(self) -> Optional[Origin]:
        """The latest failure no ancestor recovered from."""
        for o in reversed(self._origins):
            if all(self._succeeded.get(a, -1) < o.seq for a in _ancestors(o.behaviour)):
                return o
        return None

    def reason(self, root: Any) -> str:
        o = self.root_cause()
        if o is None:
            return _deepest_feedback(root)
        b = o.behaviour
        label = b.name
        if o.message.startswith(b.name) and b.parent is not None:
            label = b.parent.name  # an unnamed call leaf is named after its target: say where it is
        text = "%s: %s" % (label, o.message) if label and not o.message.startswith(label) else o.message
        for a in _ancestors(b):
            gave = self._gave_up.get(a)
            if gave is not None and gave[0] > o.seq:
                text += " (%d of %d attempts)" % (gave[1], gave[2])
                break
        return text


def _deepest_feedback(root: Any) -> str:
    """Fallback: the feedback of the deepest failed behaviour."""
    reason = ""
    for b in root.iterate():
        if b.status == Status.FAILURE and b.feedback_message:
            reason = "%s: %s" % (b.name, b.feedback_message)
    return reason
