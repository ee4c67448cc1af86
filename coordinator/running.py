"""What a tree is doing right now, in words: for the reason of a run stopped from outside, or of
a ``timeout`` that fired. The reason reaches a cleanup as ``ended_reason``, which may say it
aloud, so it must read as a sentence: ``… while 'pick' was running (between attempts: attempt 1
of 2 failed)``, not the node's own progress note (``attempt 1 of 2 failed (why); the next in 10s``)."""
from __future__ import annotations

from typing import Any, List

import py_trees
from py_trees.common import Status

__all__ = ["while_running", "running_phrase", "between"]


def between(b: Any) -> str:
    """What a loop running without a running child (between two runs of it) is at, in words; '' for a
    node that is not so (a leaf, or a node whose child runs)."""
    from coordinator.nodes.decorators import Retry
    from coordinator.nodes.loops import ForEach, Repeat

    if not b.children or any(c.status == Status.RUNNING for c in b.children):
        return ""
    if isinstance(b, Retry) and isinstance(getattr(b, "times", None), int) and getattr(b, "runs", 0):
        failed = "attempt %d of %d failed" % (b.runs, b.times)
        if b.resume_at is None:  # the next attempt starts at the next tick
            return "between attempts: %s" % failed
        said = b.feedback_message  # Retry's own: "attempt 1 of 5 failed (why); the next in 10s"
        head, tail = "%s (" % failed, "); the next in %gs" % b.delay
        why = said[len(head):-len(tail)] if said.startswith(head) and said.endswith(tail) else ""
        return "waiting %g s between attempts: %s%s" % (b.delay, failed, ": %s" % why if why else "")
    if isinstance(b, Repeat) and b.feedback_message:
        return "between runs: %s" % b.feedback_message
    if isinstance(b, ForEach) and b.feedback_message:
        return "about to start %s" % b.feedback_message
    return b.feedback_message


def running_phrase(nodes: List[Any]) -> str:
    """`` while 'drive' was running``, `` while 'pick' was running (between attempts: …)``, or for several
    `` while 'a', 'b' (…) were running`` (at most three named)."""
    if not nodes:
        return ""
    said = [between(b) for b in nodes]
    if len(nodes) == 1:
        return " while '%s' was running%s" % (nodes[0].name, " (%s)" % said[0] if said[0] else "")
    names = ["'%s'%s" % (b.name, " (%s)" % s if s else "") for b, s in zip(nodes, said)]
    more = " and %d more" % (len(names) - 3) if len(names) > 3 else ""
    return " while %s%s were running" % (", ".join(names[:3]), more)


def while_running(root: py_trees.behaviour.Behaviour) -> str:
    """`` while 'go to the kitchen' was running``: the deepest running nodes under ``root`` (the
    leaves a stop will halt, or a decorator running without a running child: a ``retry`` waiting
    out its delay, said with what it waits for)."""
    return running_phrase([b for b in root.iterate()
                           if b.status == Status.RUNNING and not any(c.status == Status.RUNNING for c in b.children)])
