"""A tree with ``cleanup:``: its root, then its cleanup, whatever way the root ended.

The run tree's file may give, beside ``root:``, a ``cleanup:`` node (SMACH's handling of
"preempted", a ``finally``): it runs once after the root ends, by SUCCESS, FAILURE or a stop
from outside (Ctrl-C, ``--max-duration``, the test kit's limits), the root halted first. The
run's status and reason stay the root's; the cleanup's own ending is reported beside them.

The parser wraps both in one node of the kind :data:`TASK` (not a kind a file can write: it
is not in the registry), so every whole-tree walk (checks, used modules, the builder, the
run stream's node table) sees the cleanup as well. Its behaviour is :class:`WithCleanup`, a
composite ticking the root, then (once the runner said how the root ended:
:meth:`WithCleanup.begin_cleanup`) the cleanup. Without ``cleanup:`` nothing of this exists:
the root is the tree's top node as before.
"""
from __future__ import annotations

from typing import Any, FrozenSet, Iterator, List, Optional, Tuple

import py_trees
from py_trees.common import Status

from coordinator.errors import Pos
from coordinator.nodes.base import NodeKind
from coordinator.treeast import TreeFile, TreeNode

__all__ = ["CLEANUP_KEYS", "DEFAULT_CLEANUP_TIMEOUT", "ENDED", "ENDED_REASON", "ENDINGS", "TASK", "TaskKind",
           "WithCleanup", "task_node"]

ENDED = "ended"
ENDED_REASON = "ended_reason"
#: the read-only tree keys a cleanup reads to learn how the root ended
CLEANUP_KEYS = (ENDED, ENDED_REASON)
#: the values of ``ended``
ENDINGS = ("succeeded", "failed", "stopped")
#: seconds a cleanup may run (top-level ``cleanup_timeout:`` changes it)
DEFAULT_CLEANUP_TIMEOUT = 30.0
TEXT = "std_msgs/String"   # the type of both keys, as the type checks see it


class TaskKind(NodeKind):
    """The node above ``root`` and ``cleanup`` (made by the parser, never written in a file)."""

    name = "with_cleanup"
    family = "composite"
    value = ("children", "root and cleanup")
    summary = "the root, then the cleanup however the root ended"

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> Any:   # never parsed
        raise TypeError("with_cleanup is made by the parser, not written")

    def flow(self, node: TreeNode, avail: FrozenSet[str], f: Any) -> FrozenSet[str]:
        """The root as always; the cleanup with what was surely there before the root (the root may
        have been stopped anywhere: what it writes is only maybe written) and the keys of how it ended."""
        root, cleanup = node.children
        written = f.of(root, avail)
        marked = getattr(f, "cleanup_nodes", None)
        if marked is not None:
            marked.update(_nodes(cleanup))
        f.of(cleanup, avail | frozenset(CLEANUP_KEYS))
        return written

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Any) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        root, cleanup = node.children
        ok, failed = f.outcome(root, avail)
        marked = getattr(f, "cleanup_nodes", None)
        if marked is not None:
            marked.update(_nodes(cleanup))
        f.outcome(cleanup, avail | frozenset(CLEANUP_KEYS))
        return ok, failed

    def writes(self, node: TreeNode) -> Any:
        """``ended`` and ``ended_reason`` (text), set before the cleanup starts."""
        return {k: TEXT for k in CLEANUP_KEYS}

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        root, cleanup = node.children
        return WithCleanup(node.name, child(root), child(cleanup), ctx, node.spec)


def _nodes(node: TreeNode) -> List[TreeNode]:
    from coordinator.treeast import nodes_of

    return nodes_of(node)


TASK = TaskKind()


def task_node(tree: TreeFile, at: Optional[Pos] = None) -> Optional[TreeNode]:
    """The node above the tree's root and cleanup (None without ``cleanup:``), placed at ``at`` (the
    ``cleanup:`` key: not where a node of the file is); its spec is the cleanup's time limit."""
    if tree.cleanup is None:
        return None
    return TreeNode(TASK.name, tree.name, at or tree.root.pos, [tree.root, tree.cleanup], tree.cleanup_timeout, TASK)


class WithCleanup(py_trees.composites.Composite):
    """Ticks its first child (the root) until it ends, then its second (the cleanup) until it ends.

    Its status is RUNNING until the cleanup ended, then the root's (after a stop from outside:
    INVALID, as a stopped root is). Between the two the runner is told (``phase == "between"``)
    and calls :meth:`begin_cleanup` with how the root ended (its reason is the run's); a stop
    from outside calls :meth:`stop_root` then :meth:`begin_cleanup`. ``cleanup_status`` and
    ``cleanup_reason`` say how the cleanup ended (``cleanup_status`` stays None until then).
    """

    def __init__(self, name: str, root: py_trees.behaviour.Behaviour, cleanup: py_trees.behaviour.Behaviour,
                 ctx: Any, limit: float = DEFAULT_CLEANUP_TIMEOUT):
        super().__init__(name=name, children=[root, cleanup])
        self.ctx = ctx
        self.limit = limit
        self.phase = "root"             # root -> between -> cleanup -> done
        self.root_status = Status.INVALID
        self.ended = ""
        self.ended_reason = ""
        self.cleanup_started: Optional[float] = None
        self.cleanup_status: Optional[Status] = None
        self.cleanup_reason = ""
        self.cleanup_ended: Optional[float] = None
        self.cleanup_cut = False    # ended from outside (its time limit, a stop): not by itself
        self.cleanup_told = False   # the runner reported its failure
        self.cut_calls: List[Any] = []   # the calls the cut (its time limit, a stop) halted: CallRecords

    @property
    def root(self) -> py_trees.behaviour.Behaviour:
        return self.children[0]

    @property
    def cleanup(self) -> py_trees.behaviour.Behaviour:
        return self.children[1]

    @property
    def done(self) -> bool:
        return self.phase == "done"

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        if self.phase == "root":
            self.current_child = self.root
            yield from self.root.tick()
            if self.root.status in (Status.SUCCESS, Status.FAILURE):
                self.root_status = self.root.status
                self.phase = "between"   # the runner says how it ended (its reason) before the cleanup starts
            self.status = Status.RUNNING
            yield self
            return
        if self.phase == "between":   # nobody said how the root ended: its own feedback says it
            self.begin_cleanup("succeeded" if self.root_status == Status.SUCCESS else "failed",
                               self.root.feedback_message)
        if self.phase == "cleanup":
            self.current_child = self.cleanup
            yield from self.cleanup.tick()
            status = self.cleanup.status
            if status in (Status.SUCCESS, Status.FAILURE):
                self.end_cleanup(status, self.cleanup.feedback_message if status == Status.FAILURE else "")
            else:
                self.status = Status.RUNNING
        yield self

    def stop_root(self) -> None:
        """A stop from outside: the root is halted (its calls cancelled); the cleanup comes next."""
        if self.phase == "root":
            if self.root.status != Status.INVALID:
                self.root.stop(Status.INVALID)
            self.root_status = Status.INVALID
            self.phase = "between"

    def begin_cleanup(self, ended: str, reason: str) -> None:
        """``ended`` (succeeded, failed, stopped) and ``reason`` written to the read-only keys; the
        cleanup runs from the next tick on."""
        if self.phase not in ("root", "between"):
            return
        self.ended, self.ended_reason = ended, reason or ""
        self.ctx.write(ENDED, ended)
        self.ctx.write(ENDED_REASON, self.ended_reason)
        self.cleanup_started = self.ctx.clock.now()
        self.phase = "cleanup"
        self.status = Status.RUNNING

    def end_cleanup(self, status: Status, reason: str = "") -> None:
        """The cleanup ended (``status``: SUCCESS, FAILURE, or INVALID when it was cut short: its time
        limit, a second stop); a running cleanup is halted (its calls cancelled)."""
        if self.phase == "done":
            return
        self.cleanup_ended = self.ctx.clock.now()   # first: the calls the halt ends end at or after it
        if self.cleanup.status == Status.RUNNING:
            running = [c for c in self.ctx.calls if c.ended is None]
            self.cleanup.stop(Status.INVALID)
            self.cut_calls = [c for c in running if c.ended is not None and str(c.status) == "halted"]
        self.cleanup_status, self.cleanup_reason = status, reason
        self.phase = "done"
        self.current_child = None
        self.status = self.root_status if self.root_status in (Status.SUCCESS, Status.FAILURE) else Status.INVALID

    def stop(self, new_status: Status = Status.INVALID) -> None:
        """Halting the whole (the runner's last resort) halts whichever child runs; it does not start
        the cleanup (a stop from outside goes through :meth:`stop_root`)."""
        if new_status == Status.INVALID and self.phase == "cleanup" and self.cleanup_status is None:
            self.cleanup_status, self.cleanup_reason = Status.INVALID, "halted"
        if new_status == Status.INVALID:
            self.phase = "done"
        super().stop(new_status)

    def tip(self) -> Optional[py_trees.behaviour.Behaviour]:
        return self.current_child.tip() if self.current_child is not None else super().tip()
