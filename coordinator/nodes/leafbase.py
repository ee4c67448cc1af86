"""The base of bmtree's leaves: built from a tree node, failing with a reason."""
from __future__ import annotations

from typing import Any

import py_trees
from py_trees.common import Status

from coordinator.treeast import TreeNode

__all__ = ["Leaf"]


class Leaf(py_trees.behaviour.Behaviour):
    """A leaf built from a YAML node (``node.pos`` says where it was written).

    Leaves never block: they send, return RUNNING, and look at what the runner has
    dispatched into the run context on later ticks.
    """

    reason = ""   # why it failed (set on failure)

    def __init__(self, node: TreeNode, ctx: Any):
        py_trees.behaviour.Behaviour.__init__(self, node.name)   # (not super(): no proxy per leaf)
        self.node = node
        self.ctx = ctx

    def _fail(self, reason: str) -> Status:
        self.reason = reason
        self.feedback_message = reason
        return Status.FAILURE
