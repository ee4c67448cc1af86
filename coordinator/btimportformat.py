"""``bmtree import``: which BehaviorTree.CPP format a file without ``BTCPP_format`` is written in.

The two formats read one port differently: ``<SubTree ID="Go" place="kitchen"/>`` gives the subtree the
caller's key ``kitchen`` in format 3 and the text "kitchen" in format 4. BehaviorTree.CPP 3 and Groot 1
write no ``BTCPP_format``; BehaviorTree.CPP 4 reads such a file as format 4 (with a warning). So the file's
own nodes decide: a node or attribute that only one format has, else format 3 (what wrote no attribute);
either way the choice is said, so that nothing changes meaning silently.
"""
from __future__ import annotations

from typing import Iterator, Optional, Tuple

from coordinator.btxml import Element

__all__ = ["format_of"]

_WRAPPERS = ("Action", "Condition", "Control", "Decorator")
# nodes and attributes of one format only (BehaviorTree.CPP 3.8's and 4.x's built-in nodes; not Sleep nor RunOnce,
# names a format 3 project often gave its own nodes)
_V4_NODES = frozenset(("Script", "ScriptCondition", "SequenceWithMemory", "Precondition", "UnsetBlackboard",
                       "WaitValueUpdate", "SkipUnlessUpdated", "WasEntryUpdated", "LoopString", "LoopInt", "LoopDouble",
                       "LoopBool", "ParallelAll", "AsyncSequence", "AsyncFallback"))
_V4_ATTRS = frozenset(("_autoremap", "_skipIf", "_successIf", "_failureIf", "_while", "_onSuccess", "_onFailure",
                       "_onHalted", "_post"))
_V3_NODES = frozenset(("SequenceStar", "SubTreePlus", "RetryUntilSuccesful", "ManualSelector", "BlackboardCheckInt",
                       "BlackboardCheckDouble", "BlackboardCheckString"))
_V3_ATTRS = frozenset(("__shared_blackboard", "__autoremap"))
_PARALLEL = {True: ("success_count", "failure_count"), False: ("threshold",)}   # other nodes' ports may be so named


def _nodes(el: Element) -> Iterator[Element]:
    stack = [el]
    while stack:
        e = stack.pop()
        yield e
        stack.extend(reversed(e.children))


def _marker(el: Element, v4: bool) -> Optional[str]:
    """What in ``el`` only format 4 (``v4``) or only format 3 has, said as a reader finds it."""
    kind = el.attrs.get("ID", "") if el.tag in _WRAPPERS else el.tag
    if kind in (_V4_NODES if v4 else _V3_NODES):
        return "<%s>" % kind
    for k, v in el.attrs.items():
        if k in (_V4_ATTRS if v4 else _V3_ATTRS) or (kind == "Parallel" and k in _PARALLEL[v4]):
            return "%s=" % k
        if v4 and (v.strip() == "{=}" or v.strip().startswith("{@")):
            return "%s=\"%s\"" % (k, v.strip())
    return None


def _first(root: Element, v4: bool) -> Optional[Tuple[str, int]]:
    for tree in root.children:
        if tree.tag != "BehaviorTree":   # TreeNodesModel's ports are no nodes
            continue
        for el in _nodes(tree):
            found = _marker(el, v4)
            if found:
                return found, el.pos.line
    return None


def format_of(root: Element) -> Tuple[int, str]:
    """The format of a ``<root>`` without ``BTCPP_format``, and the warning that says why."""
    v4, v3 = _first(root, True), _first(root, False)
    if v4:
        return 4, ("no BTCPP_format on <root>: read as format 4, as BehaviorTree.CPP 4 does (line %d has %s, of format "
                   "4 only%s): add BTCPP_format=\"4\" to <root> to say so" % (
                       v4[1], v4[0], "; line %d has %s, of format 3 only" % v3[::-1] if v3 else ""))
    return 3, ("no BTCPP_format on <root>: read as format 3, which BehaviorTree.CPP 3 and Groot 1 write without it "
               "(%s); BehaviorTree.CPP 4 would read it as format 4, where a SubTree's place=\"kitchen\" is text, not "
               "the caller's key: add BTCPP_format=\"3\" or \"4\" to <root> to say which" % (
                   "line %d has %s, of format 3 only" % v3[::-1] if v3 else "nothing in it is of format 4 only"))
