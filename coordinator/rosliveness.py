"""Who serves a module now, asked of the ROS master for the run's liveness watchdogs
(:class:`comm.liveness.Watchdog`, :class:`comm.liveness.NodeWatch`): the node of a module
or of the Blackboard, and a node's URI; each question bounded, as a master may not answer.
"""
from __future__ import annotations

from typing import Optional

from blackboard.node import TOPIC_STORED
from comm import TOPIC_BB_ANSWER
from comm.liveness import BLACKBOARD
from comm.rpc import master_api
from coordinator.preflight import legacy_nodes
from modules.discovery import PARAM_ROOT, node_alive

__all__ = ["LIVENESS_QUESTION", "node_of", "uri_of"]

LIVENESS_QUESTION = 2.0  # s a liveness lookup may wait for the master (then: not known now)


def node_of(module: str) -> Optional[str]:
    """The node serving ``module`` (announced, else a legacy node named after it), or the Blackboard's."""
    import rosgraph

    master = master_api("/bmtree_liveness", LIVENESS_QUESTION)  # a master that does not answer: OSError
    if module == BLACKBOARD:  # the live node publishing answers and acknowledgements
        pubs, _, _ = master.getSystemState()
        pubs_of = {t: list(n) for t, n in pubs}
        answering = pubs_of.get(TOPIC_BB_ANSWER, [])
        nodes = [n for n in answering if n in pubs_of.get(TOPIC_STORED, [])] or answering
        for node in nodes:
            try:
                if node_alive(master.lookupNode(node), 0.5):
                    return node
            except rosgraph.masterapi.MasterError:
                continue
        return nodes[0] if nodes else None
    try:
        entry = master.getParam("%s/%s" % (PARAM_ROOT, module))
        if isinstance(entry, dict) and isinstance(entry.get("node"), str):
            return entry["node"]
    except rosgraph.masterapi.MasterError:
        pass
    found = legacy_nodes([module]).get(module)
    return found[0] if found else None


def uri_of(node: str) -> Optional[str]:
    """The XML-RPC URI of ``node`` (None when the master no longer knows it)."""
    import rosgraph

    try:
        return master_api("/bmtree_liveness", LIVENESS_QUESTION).lookupNode(node)
    except rosgraph.masterapi.MasterError:
        return None
