"""What a call's ``status`` key tells the data flow: where ``$status`` can only be ``succeeded``, the call
that wrote it succeeded, so its ``outputs`` are on the blackboard.

SMACH ports route on a call's outcome (``force_success`` of the call, then ``switch: $found``) and read its
outputs in the ``succeeded`` case; without this the check refuses that read, as the call may have failed.
It holds only when the key says nothing but how that call ended: every node that writes the key writes it
as a call's ``status`` (a ``set``, a recall, an include's argument, a tree input could give it any value).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, FrozenSet, Iterable

from coordinator.nodes.writtenkeys import meet
from coordinator.treeast import TreeNode

if TYPE_CHECKING:  # pragma: no cover
    from coordinator.nodes.base import Flow

__all__ = ["SUCCEEDED", "sure_when_status"]

SUCCEEDED = "succeeded"
_NOTHING: FrozenSet[str] = frozenset()


def sure_when_status(f: Flow, key: str, statuses: Iterable[str]) -> FrozenSet[str]:
    """The keys surely written when ``$key`` holds one of ``statuses`` (texts of how a call ended): when
    that is only ``succeeded``, what every call whose ``status`` is ``key`` writes when it succeeds (its
    outputs, its status and error keys: the one that wrote the status last succeeded); else nothing.
    Nothing either when another node may write the key, or a file being walked takes it as an input."""
    if set(statuses) != {SUCCEEDED} or any(key in t.inputs for t in f.files):
        return _NOTHING
    writers = f.writers(key)
    if not writers or not all(_status_only(w, key) for w in writers):
        return _NOTHING
    return meet(frozenset(w.nodekind.writes(w)) for w in writers)


def _status_only(node: TreeNode, key: str) -> bool:
    """Whether ``node`` is a call that writes ``key`` as its ``status`` and in no other way."""
    spec: Any = node.spec
    return (node.kind == "call" and getattr(spec, "status", None) == key and spec.error != key
            and key not in spec.outputs.values())
