"""Reactive composites: a ``sequence`` or ``selector`` with ``memory: false`` ticks its children again
from the first on every tick. A child that can be RUNNING (a call waiting for its answer, a wait, a
loop between its runs) is then started again on the next tick, and halts a later child that runs:
that one is restarted every other tick (a drive cancelled and sent again thousands of times). This is
a check error (BehaviorTree.CPP 4 throws at run time: "only a single child can return RUNNING").

Whether a node can be RUNNING after the tick it starts in comes from its kind (``NodeKind.lasts`` /
``lasting``: a call, recall, wait_event, wait, and retry/repeat/for_each between runs), or from a node
below it (its children, an include's subtree). See trees/README.md, "Reacting while an action runs".
"""
from __future__ import annotations

from typing import List, Optional, Tuple

from coordinator.errors import Pos
from coordinator.treeast import TreeNode, walk

__all__ = ["SECTION", "running_part", "restart_problems"]

SECTION = "'Reacting while an action runs' in trees/README.md"


def running_part(node: TreeNode) -> Optional[Tuple[TreeNode, str]]:
    """The first node at or below ``node`` (includes expanded) that can be RUNNING after the tick it
    starts in, and why; None when ``node`` always ends in the tick it starts (checks, sets, fails, and
    composites or decorators made only of those)."""
    for n in walk(node):
        why = n.nodekind.lasting(n)
        if why:
            return n, why
    return None


def _guarded(child: TreeNode) -> bool:
    """A selector's child that fails at once while its condition is false: a sequence whose children before
    its first that can run hold a ``check`` (ReactiveFallback's higher priority: when the check becomes
    true it takes over, halting the later child on purpose)."""
    if child.kind != "sequence":
        return False
    for c in child.children:
        if running_part(c) is not None:
            return False
        if c.kind == "check":
            return True
    return False


def _never_fails(node: TreeNode) -> str:
    """Why ``node`` surely never ends in FAILURE (``no timeout``), or '' when it may (or bmtree cannot
    tell: an include, a loop, a call). A selector's later children run only after one failed."""
    kind, spec = node.kind, node.spec
    if kind == "wait_event":
        return "no timeout: it waits until the event comes" if getattr(spec, "timeout", 0) is None else ""
    if kind == "wait":
        fixed = isinstance(spec, (int, float)) and not isinstance(spec, bool)
        return "a wait of fixed seconds always succeeds" if fixed else ""
    if kind == "force_success":
        return "force_success always succeeds"
    whys = [_never_fails(c) for c in node.children]
    if kind == "sequence" and whys and all(whys):
        return whys[0]
    if kind == "selector":
        return next((w for w in whys if w), "")
    return ""


def _named(n: TreeNode, seen_from: Pos) -> str:
    """``the call 'drive' at line 8``; ``the sequence at line 5`` for one without a name of its own."""
    from coordinator.nodes.base import where

    shown = "" if n.name in ("", n.kind) else " %r" % n.name
    return "the %s%s at %s" % (n.kind, shown, where(n.pos, seen_from))


def restart_problems(node: TreeNode) -> List[Tuple[Pos, str]]:
    """The errors of a ``memory: false`` sequence or selector (``node``): each child that can be RUNNING
    while a later child can be too, at the earlier child, naming both and what to write instead."""
    runs = [(c, running_part(c)) for c in node.children]
    out: List[Tuple[Pos, str]] = []
    for i, (child, found) in enumerate(runs):
        if found is None or (node.kind == "selector" and _guarded(child)):
            continue
        later = next((c for c, f in runs[i + 1:] if f is not None), None)
        if later is None:
            break
        at = child.pos
        part, why = found
        said = "%s can be RUNNING (%s)" % (_named(child, at), why) if part is child else \
            "%s can be RUNNING (%s: %s)" % (_named(child, at), _named(part, at), why)
        never = _never_fails(child) if node.kind == "selector" else ""
        out.append((at, _unreached(node, child, said, never, _named(later, at)) if never
                    else _message(node, said, _named(later, at))))
    return out


def _message(node: TreeNode, said: str, later: str) -> str:
    head = "%s with memory: false (line %d) ticks its children again from the first on every tick: %s" % (
        node.kind, node.pos.line, said)
    if node.kind == "sequence":
        what = ("so on the tick after it succeeds it starts again and halts %s, which can be RUNNING too: that "
                "one is restarted on every other tick and never finishes" % later)
        fix = ("a memory: false sequence may hold one child that takes more than one tick, after all the others: "
               "before it, write only nodes that end in the tick they start (check, set, fail); make the call "
               "before this sequence (a sequence with memory: true, the default), or poll it beside the action "
               "in a parallel (see %s)" % SECTION)
    else:
        what = ("so once it has failed and %s runs, it starts again and halts that one, which is restarted on "
                "every other tick and never finishes" % later)
        fix = ("a memory: false selector may hold one child that takes more than one tick, after all the others: "
               "before it, write only nodes that end in the tick they start (check, set, fail), or a sequence "
               "that starts with a check (a higher priority that takes over while its condition holds); for "
               "fallbacks that take time, use memory: true (the default), or see %s" % SECTION)
    return "%s, %s. %s" % (head, what, fix[0].upper() + fix[1:])


def _unreached(node: TreeNode, child: TreeNode, said: str, never: str, later: str) -> str:
    """A selector's child that can be RUNNING and never fails: the later children never run at all."""
    limit = "; to give up waiting after a while, give the wait_event a timeout:" if child.kind == "wait_event" else ""
    return ("selector with memory: false (line %d) tries its next child only after one failed: %s and cannot fail "
            "(%s), so %s never runs. To run both at once and stop at the first that ends, write a parallel with "
            "policy: one%s (see %s)" % (node.pos.line, said, never, later, limit, SECTION))
