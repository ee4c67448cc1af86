"""Checks over a whole tree, asked of each node's kind (``coordinator.nodes``).

Data flow: every key a node reads is written earlier on every path by which the nodes before it
succeed, or is a declared input (a branch that never succeeds is no such path); a read is reported
at its reference, with where the key is written, and a key that no node writes is told apart (likely
misspelt: a close name is suggested).
Types: a ``$reference`` whose value's ROS type (known from the definitions of the nodes that
write the key) cannot be converted to the input it is passed to, or whose path names a field that
type does not have (``coordinator.values.follow``); a count, duration or ``for_each`` list of a type
that cannot be one (``coordinator.nodes.base.param_type_errors``). A key is typed only when all its
writers give one type (a ``set``, a tree input or an include argument gives none).
"""
from __future__ import annotations

from typing import Dict, FrozenSet, List, Optional, Sequence, Set

from coordinator.errors import TreeError
from coordinator.nodes.base import Flow
from coordinator.treeast import REQUIRED, TreeFile, TreeNode, kinds_in, nodes_of

__all__ = ["check_flow", "check_types", "key_types"]


def check_flow(tree: TreeFile, given: FrozenSet[str] = frozenset()) -> List[TreeError]:
    """Every read of a key not surely written before it, for a whole tree."""
    errors: List[TreeError] = []
    avail = frozenset(k for k, v in tree.inputs.items() if v is not REQUIRED) | given | tree.required_inputs
    flow = Flow(errors, tree)
    flow.of(tree.root, avail)
    if flow.missed:   # the keys written anywhere tell a misspelt key from one written too late
        flow.report(set(key_types(tree)) | avail)
    return errors


def key_types(tree: TreeFile, nodes: Optional[Sequence[TreeNode]] = None) -> Dict[str, Set[Optional[str]]]:
    """For each tree key, the ROS types written to it (None: not known statically)."""
    types: Dict[str, Set[Optional[str]]] = {k: {None} for k in tree.inputs}
    nodes = nodes_of(tree.root) if nodes is None else nodes
    if not any(nk.own_writes for nk in kinds_in(nodes)):
        return types
    for n in nodes:
        nk = n.nodekind
        written = nk.writes(n) if nk.own_writes else None   # the base writes nothing
        for key, rostype in written.items() if written else ():
            types.setdefault(key, set()).add(rostype)
    return types


def check_types(tree: TreeFile, nodes: Optional[Sequence[TreeNode]] = None) -> List[TreeError]:
    """References that cannot fit the input they are passed to."""
    errors: List[TreeError] = []
    nodes = nodes_of(tree.root) if nodes is None else nodes
    types = key_types(tree, nodes)
    for n in nodes:
        nk = n.nodekind
        if nk.own_check_types:   # the base checks nothing
            nk.check_types(n, types, errors)
    return errors
