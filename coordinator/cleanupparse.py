"""The top-level ``cleanup:`` and ``cleanup_timeout:`` of a tree file, and the keys bmtree sets for it.

``cleanup:`` is one node (any kind, parsed as ``root:`` is), run once after the root ended however
it ended (``coordinator.nodes.task``); ``cleanup_timeout:`` bounds it (seconds, default 30). The
keys ``ended`` and ``ended_reason`` are bmtree's: set before the cleanup starts, read-only. A node
that writes them, or an input that declares them, is an error in a tree with a cleanup and a
warning in one without (the key would be replaced the day a cleanup is added).
"""
from __future__ import annotations

import os
from typing import Any, List, Tuple

from coordinator.bounds import finite_number, shown
from coordinator.errors import TreeError
from coordinator.nodes.task import CLEANUP_KEYS, DEFAULT_CLEANUP_TIMEOUT, ENDINGS, TASK, task_node
from coordinator.nodes.timeouts import long_seconds
from coordinator.treeast import TreeFile, TreeNode

__all__ = ["CLEANUP_TOP_KEYS", "included_cleanup_warning", "parse_cleanup", "reserved_key_problems"]

CLEANUP_TOP_KEYS = ("cleanup", "cleanup_timeout")


def parse_cleanup(p: Any, data: Any, tree: TreeFile) -> None:
    """Parse ``cleanup:`` and ``cleanup_timeout:`` of ``data`` (a file's top mapping) into ``tree``
    (called while the file is on the parser's stack: an include in the cleanup is relative to it)."""
    declared = data.get("inputs")
    if hasattr(declared, "key_pos"):
        tree.reserved_inputs = {k: declared.key_pos[k] for k in CLEANUP_KEYS if k in declared}
    if "cleanup_timeout" in data:
        value, at = data["cleanup_timeout"], data.val_pos["cleanup_timeout"]
        if not finite_number(value) or value <= 0:
            p.err(at, "cleanup_timeout must be a positive number of seconds (the cleanup's time limit, "
                      "default %g), got %s" % (DEFAULT_CLEANUP_TIMEOUT, shown(value)))
        else:
            tree.cleanup_timeout = float(value)
            long_seconds(p, value, at, "cleanup_timeout")   # 3000: milliseconds by habit, as timeout: says
        if "cleanup" not in data:
            p.warn(data.key_pos["cleanup_timeout"], "cleanup_timeout without cleanup: there is no cleanup to limit")
    if "cleanup" not in data:
        return
    raw = data["cleanup"]
    node = p.node(raw, data.val_pos["cleanup"])
    if node is None:
        return
    if node.nodekind.family != "leaf" and not (hasattr(raw, "get") and raw.get("name")):
        node.name = "cleanup"   # an unnamed sequence shows as what it is for
    tree.cleanup = node
    tree.top = task_node(tree, data.key_pos["cleanup"]) if tree.root is not None else None


def included_cleanup_warning(sub: TreeFile) -> str:
    """The warning at an include of a file that has a cleanup (it runs only for the run's own tree)."""
    return ("%s has a cleanup: (line %d), which does not run when the file is included: only the cleanup "
            "of the tree that is run runs (move it there, or run %s by itself)"
            % (os.path.basename(sub.path), sub.cleanup.pos.line if sub.cleanup is not None else 0,
               os.path.basename(sub.path)))


def _message(key: str, what: str, error: bool) -> str:
    role = ("how root ended: one of %s" % ", ".join(ENDINGS) if key == "ended"
            else "why root ended, as the run's reason says it")
    if error:
        return "%s %r, a key bmtree sets for the tree's cleanup (%s), read-only: use another key" % (what, key, role)
    return ("%s %r, a key bmtree sets for a tree's cleanup (%s): in a tree with cleanup: this is an error; use "
            "another key" % (what, key, role))


def reserved_key_problems(tree: TreeFile, files: List[TreeFile], nodes: List[TreeNode]) -> Tuple[
        List[TreeError], List[TreeError]]:
    """(errors, warnings): nodes of the tree that write ``ended``/``ended_reason``, and files that declare
    them as inputs; errors when the tree has a cleanup, warnings otherwise."""
    error = tree.cleanup is not None
    found: List[TreeError] = []
    for n in nodes:
        nk = n.nodekind
        if not nk.own_writes or nk is TASK:
            continue
        written = nk.writes(n) or {}
        for key in CLEANUP_KEYS:
            if key in written:
                found.append(TreeError(n.pos, ("" if error else "warning: ") + _message(key, "writes", error)))
    for f in files:
        for key, at in sorted(f.reserved_inputs.items()):
            found.append(TreeError(at, ("" if error else "warning: ") + _message(key, "declares the input", error)))
    return (found, []) if error else ([], found)
