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
from typing import Any, Callable, Dict, List, Optional, Tuple

import py_trees
from py_trees.common import Status

from coordinator.nodes.decorators import Retry
from coordinator.runevents import Change, RunObserver, include_label
from coordinator.running import running_phrase

__all__ = ["FailureExplainer", "FailureTrail", "Origin", "originates"]


@dataclass
class Origin:
    """One failure where it started: ``behaviour`` is the behaviour (live) or its recorded id (replay)."""

    seq: int
    behaviour: Any
    message: str
    time: float


def originates(kind: Optional[str], leaf: bool, message: str, child_failed: bool) -> bool:
    """True if a node that turned FAILURE failed by itself: a leaf, an ``inverter``, or a decorator or
    composite that failed with its own reason while none of its children failed (a timeout that
    fired, a loop that hit its maximum, a switch without a matching case); ``force_failure`` only
    reports. ``kind`` is the tree language's (the run log's ``kind``): one rule for the live reason
    and the replay, so both name the same failure."""
    if kind == "force_failure":
        return False
    if kind == "inverter" or leaf:
        return True
    return bool(message) and not child_failed


def _kind(b: Any) -> Optional[str]:
    if isinstance(b, py_trees.decorators.SuccessIsFailure):
        return "force_failure"
    if isinstance(b, py_trees.decorators.Inverter):
        return "inverter"
    return None


def _originates(b: Any) -> bool:
    return originates(_kind(b), not b.children, b.feedback_message,
                      any(c.status == Status.FAILURE for c in b.children))


def _ancestors(b: Any) -> List[Any]:
    out = []
    p = b.parent
    while p is not None:
        out.append(p)
        p = p.parent
    return out


class FailureTrail:
    """Where failures started, and which of them an ancestor recovered from (it succeeded later: a
    selector moved on to a child that succeeded, a retry succeeded), over a run's status changes in
    order. The live reason keeps one over behaviours, ``bmtree replay --failure`` one over the
    recorded ids, so the failure the replay shows is the one the run's reason names.

    Args:
        parent: a node's parent (None at the root).
        keep: how many origins to keep (the live run: only recent ones can be the cause).
    """

    def __init__(self, parent: Callable[[Any], Any], keep: Optional[int] = None):
        self.parent = parent
        self.keep = keep
        self.seq = 0
        self.origins: List[Origin] = []
        self.succeeded: Dict[Any, int] = {}  # node -> seq of its latest SUCCESS

    def change(self, node: Any, status: Status, origin: bool, message: str, time: float) -> Optional[Origin]:
        """One status change; the Origin it starts (``origin``: :func:`originates` said so), if any."""
        self.seq += 1
        if status is Status.SUCCESS:
            self.succeeded[node] = self.seq
        elif status is Status.FAILURE and origin:
            o = Origin(self.seq, node, message or "failed", time)
            self.origins.append(o)
            if self.keep:
                del self.origins[:-self.keep]
            return o
        return None

    def ancestors(self, node: Any) -> List[Any]:
        out: List[Any] = []
        node = self.parent(node)
        while node is not None and len(out) < 1000:
            out.append(node)
            node = self.parent(node)
        return out

    def recovered_by(self, o: Origin) -> Any:
        """The nearest ancestor that succeeded after ``o`` (None: nothing recovered from it)."""
        return next((a for a in self.ancestors(o.behaviour) if self.succeeded.get(a, -1) > o.seq), None)

    def root_cause(self) -> Optional[Origin]:
        """The latest failure no ancestor recovered from."""
        for o in reversed(self.origins):
            if self.recovered_by(o) is None:
                return o
        return None


class FailureExplainer(RunObserver):
    """Watches status changes; :meth:`reason` explains a FAILURE of the root."""

    def __init__(self) -> None:
        self.trail = FailureTrail(lambda b: b.parent, keep=64)
        self._gave_up: Dict[Any, Tuple[int, int, int]] = {}  # retry -> (seq, runs, times)

    def on_tick(self, root: Any, changes: List[Change], now: float) -> None:
        fired: List[Origin] = []
        for b, old, new in changes:
            o = self.trail.change(b, new, new is Status.FAILURE and _originates(b), b.feedback_message, now)
            if o is not None and b.children:
                fired.append(o)
            if new is Status.FAILURE and isinstance(b, Retry) and isinstance(getattr(b, "times", None), int):
                self._gave_up[b] = (self.trail.seq, b.runs, b.times)
            elif new is Status.INVALID and old is Status.RUNNING and (
                    not b.children or getattr(b, "resume_at", None) is not None):
                for o in fired:  # a timeout halted this leaf (or a retry waiting out its delay): say what ran
                    if o.behaviour in _ancestors(b):
                        o.message += running_phrase([b])

    def root_cause(self) -> Optional[Origin]:
        """The latest failure no ancestor recovered from."""
        return self.trail.root_cause()

    def root_cause_under(self, top: Any) -> Optional[Origin]:
        """The latest failure at or under ``top`` that no node at or under ``top`` recovered from: a
        tree's root, or its cleanup (whose failure a root that succeeded does not recover from)."""
        under = set(top.iterate())
        trail = self.trail
        for o in reversed(trail.origins):
            if o.behaviour in under and not any(a in under and trail.succeeded.get(a, -1) > o.seq
                                                for a in trail.ancestors(o.behaviour)):
                return o
        return None

    def reason(self, root: Any, under: bool = False) -> str:
        """Why ``root`` failed (``under``: only failures at or under it count: the root of a tree with
        ``cleanup:``, or the cleanup)."""
        o = self.root_cause_under(root) if under else self.root_cause()
        if o is None:
            return _deepest_feedback(root)
        b = o.behaviour
        label = b.name
        if o.message.startswith(b.name) and b.parent is not None:
            label = _where(b)  # an unnamed call leaf is named after its target: say where it is
        text = "%s: %s" % (label, o.message) if label and not o.message.startswith(label) else o.message
        for a in _ancestors(b):
            gave = self._gave_up.get(a)
            if gave is not None and gave[0] > o.seq:
                text += " (%d of %d attempts)" % (gave[1], gave[2])
                break
        return text

    def failed_at(self, root: Any, under: bool = False) -> str:
        """Where the failure :meth:`reason` names is written, ``FILE:LINE:COLUMN`` (an editor's jump
        target), and the nearest include it is in with the values of its arguments
        (``in search_room(room="kitchen")``); '' when none is known."""
        o = self.root_cause_under(root) if under else self.root_cause()
        node = getattr(o.behaviour, "bmtree_node", None) if o is not None else None
        pos = getattr(node, "pos", None)
        if o is None or pos is None:
            return ""
        inc = next((a for a in _ancestors(o.behaviour)
                    if getattr(getattr(a, "bmtree_node", None), "kind", None) == "include"), None)
        if inc is None:
            return str(pos)
        setter = inc.children[0] if inc.children else None
        if setter is None or not setter.name.startswith("arguments of "):  # an include without args
            return "%s in %s" % (pos, inc.name)
        values = getattr(setter, "written", None)
        if "(" not in inc.name and values:   # a named include: its name, then the values (which the name hides)
            said = include_label("x(%s)" % ", ".join("%s=$%s" % (k, k) for k in values), values)[1:]
            return "%s in %s %s" % (pos, inc.name, said)
        return "%s in %s" % (pos, include_label(inc.name, values))


def _where(b: Any) -> str:
    """The nearest ancestor's name that says something: not a bare kind (an unnamed ``sequence``)."""
    for a in _ancestors(b):
        node = getattr(a, "bmtree_node", None)
        if node is not None and node.kind == "with_cleanup":   # above root and cleanup: the tree's name
            break
        if node is not None and node.kind == "timeout" and a.name == node.nodekind.default_name(node):
            continue   # "timeout 40s: go_to failed" reads as if the time ran out: that one says itself
        if node is None or a.name != node.kind:
            return a.name
    return ""


def _deepest_feedback(root: Any) -> str:
    """Fallback: the feedback of the deepest failed behaviour."""
    reason = ""
    for b in root.iterate():
        if b.status == Status.FAILURE and b.feedback_message:
            reason = "%s: %s" % (b.name, b.feedback_message)
    return reason
