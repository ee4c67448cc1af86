"""Who serves a module now, asked of the ROS master for the run's liveness watchdogs
(:class:`comm.liveness.Watchdog`, :class:`comm.liveness.NodeWatch`): the node of a module
or of the Blackboard, and a node's URI; each question bounded, as a master may not answer.

A module whose node stopped cleanly (Ctrl-C, ``rosnode kill``, a launch file stopped) leaves
no trace on the master: its announcement is removed and its node unregistered. Asked only
the master, the watchdog found no node for it and left its calls to their timeout, and a call
with ``timeout: none`` waited for ever, then ran on the node started next.
:class:`Whereabouts` remembers where each module was seen, so such a module is asked at its
last address (refused: gone) instead of being taken for one not started yet.
"""
from __future__ import annotations

import threading
from typing import Callable, Dict, Optional

from blackboard.node import TOPIC_STORED
from comm import TOPIC_BB_ANSWER
from comm.liveness import BLACKBOARD
from comm.rpc import master_api
from coordinator.preflight import legacy_nodes
from modules.discovery import PARAM_ROOT, node_alive

__all__ = ["LIVENESS_QUESTION", "GONE", "Whereabouts", "node_of", "uri_of"]

LIVENESS_QUESTION = 2.0  # s a liveness lookup may wait for the master (then: not known now)
GONE = "(its process is gone)"  # what a lost node's reason says of its process when nothing more is known


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


class Whereabouts:
    """:func:`node_of` and :func:`uri_of` for a run's watchdog, falling back on where a module's node
    was last seen when the master no longer knows it.

    ``run_node(module)`` gives the node the run found for a module before it started (its
    preflight), for a module whose node this has never seen itself. A node the master no longer
    knows is asked at its last address: a dead process refuses (the watchdog says it stopped), a
    live one answers (a restarted master it has not registered with again yet: not lost).

    ``ended(node)``, when set, says why ``node``'s process ended ("" when it cannot tell): the
    simulated robot's graph started it and knows (``bmtree run --sim``, :mod:`coordinator.simprocess`);
    :meth:`explain` puts that in a lost node's reason instead of :data:`GONE`.
    """

    def __init__(self, run_node: Callable[[str], Optional[str]] = lambda module: None):
        self.run_node = run_node
        self.ended: Optional[Callable[[str], str]] = None
        self._nodes: Dict[str, str] = {}  # module -> its node, when last seen
        self._uris: Dict[str, str] = {}  # node -> its XML-RPC URI, when last seen
        self._lock = threading.Lock()

    def seen(self, module: str, node: str, uri: Optional[str] = None) -> None:
        """Remember that ``node`` (at ``uri``) served ``module`` (an announcement the run read)."""
        with self._lock:
            self._nodes[module] = node
            if uri:
                self._uris[node] = uri

    def known(self, module: str) -> Optional[str]:
        """The node last seen serving ``module``, without asking the master (None if never known)."""
        with self._lock:
            node = self._nodes.get(module)
        return node if node is not None else self.run_node(module)

    def node_of(self, module: str) -> Optional[str]:
        """The node serving ``module`` now, else the one that served it last (None if never known)."""
        node = node_of(module)
        if module == BLACKBOARD:
            return node
        with self._lock:
            if node is not None:
                self._nodes[module] = node
                return node
            node = self._nodes.get(module)
        return node if node is not None else self.run_node(module)

    def uri_of(self, node: str) -> Optional[str]:
        """``node``'s URI from the master, else its last known one (None if never known)."""
        uri = uri_of(node)
        with self._lock:
            if uri:
                self._uris[node] = uri
                return uri
            return self._uris.get(node)

    def explain(self, node: str, reason: str) -> str:
        """``reason`` (``node /bm_gripper stopped (its process is gone)``) with what :attr:`ended` says of
        ``node`` instead of :data:`GONE` (``… stopped (its process exited with code 7)``); as it is otherwise."""
        if self.ended is None or GONE not in reason:
            return reason
        try:
            why = self.ended(node)
        except Exception:  # a reason is never lost for want of a better one
            return reason
        return reason.replace(GONE, "(%s)" % why, 1) if why else reason

    @staticmethod
    def registered(node: str) -> bool:
        """Whether ``node`` still has topics or services registered with the master: a process killed
        outright keeps them (a crash, which a respawn follows), one stopped cleanly removed them (the
        master's ``lookupNode`` still answers for it). False when the master cannot be asked."""
        try:
            state = master_api("/bmtree_liveness", LIVENESS_QUESTION).getSystemState()
        except Exception:  # the master is away: no grace, as before it
            return False
        return any(node in nodes for part in state for _, nodes in part)
