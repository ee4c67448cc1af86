"""What a tree is doing right now, in words: for the reason of a run stopped from outside, or of
a ``timeout`` that fired."""
from __future__ import annotations

import py_trees
from py_trees.common import Status

__all__ = ["while_running"]


def while_running(root: py_trees.behaviour.Behaviour) -> str:
    """`` while 'go to the kitchen' was running``: the deepest running nodes under ``root`` (the
    leaves a stop will halt, or a decorator running without a running child: a ``retry`` waiting
    out its delay, said with what it waits for)."""
    names = []
    for b in root.iterate():
        if b.status != Status.RUNNING or any(c.status == Status.RUNNING for c in b.children):
            continue
        said = b.feedback_message if b.children else ""
        names.append("'%s'%s" % (b.name, " (%s)" % said if said else ""))
    if not names:
        return ""
    more = " and %d more" % (len(names) - 3) if len(names) > 3 else ""
    return " while %s%s %s running" % (", ".join(names[:3]), more, "was" if len(names) == 1 else "were")
