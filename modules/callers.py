"""A module node's watch over the nodes that sent its running calls.

A call whose caller's process is gone (the coordinator killed, crashed) is cancelled: nobody waits for its
answer, and running on it would drive the hardware and hold the module. With ``unreachable`` seconds
(``--unreachable-caller``, ``~unreachable_caller``; 0, the default: never), a call whose caller has not
answered for that long is cancelled too: the robot's link to the laptop that runs the tree dropped, or the
coordinator's process is stopped, so nobody supervises what the call drives. Its ``cancelled`` answer says
why, and reaches the coordinator once the link is back.
"""
from __future__ import annotations

import argparse
import logging
from typing import Any, Optional

from comm.liveness import ModuleLost, Watchdog
from comm.nodeopts import seconds
from comm.rpc import MASTER_TIMEOUT, master_api

__all__ = ["CallerWatch", "CALLER_PERIOD", "UNREACHABLE_MIN", "unreachable_seconds"]

log = logging.getLogger("bmtree.module")

CALLER_PERIOD = 0.5  # seconds: a call's caller is watched once the call is this old, then at once on its death
UNREACHABLE_MIN = 1.0  # seconds: a shorter wait would take a caller busy for a moment for one cut off


def unreachable_seconds(value: Any) -> float:
    """``--unreachable-caller``'s value: 0 (never), or at least :data:`UNREACHABLE_MIN` seconds.

    Raises:
        argparse.ArgumentTypeError: what is wrong with it.
    """
    got = seconds("never")(value)
    if 0 < got < UNREACHABLE_MIN:
        raise argparse.ArgumentTypeError("expected 0 (never) or at least %g seconds, got %g: a caller that "
                                         "takes a moment to answer is not one that is cut off" % (
                                             UNREACHABLE_MIN, got))
    return got


def _uri_of(node: str) -> Optional[str]:
    """A node's XML-RPC URI from the master (None once it is no longer registered). Bounded: a
    master that does not answer raises OSError (the caller's liveness is not known now), and never
    holds the watch over the callers, which then cannot cancel the call of a caller that is gone."""
    import rosgraph

    try:
        return master_api("/bmtree_callers", MASTER_TIMEOUT).lookupNode(node)
    except rosgraph.masterapi.MasterError:
        return None


class CallerWatch:
    """Watches the callers of ``server``'s calls (a :class:`~modules.runtime.ModuleServer`) and cancels the
    calls of a caller that is gone, or that has not answered for ``unreachable`` seconds (0: never)."""

    def __init__(self, server: Any, module: str, unreachable: float = 0.0):
        self.server = server
        self.module = module
        self.unreachable = unreachable
        self.watchdog = Watchdog(self.orphaned, lambda node: node, _uri_of, period=CALLER_PERIOD, say=False,
                                 unregistered_lost=False, unanswered=unreachable)

    def start(self) -> CallerWatch:
        self.server.callers = self.watchdog
        self.watchdog.start()
        return self

    def stop(self) -> None:
        self.watchdog.stop()

    def orphaned(self, lost: ModuleLost) -> None:
        """The node that sent these calls is gone, or cut off: cancel them (a call its coordinator
        cancelled already is not cancelled again, nor reported as cancelled here)."""
        why = ""
        if lost.unanswered:
            why = ("its caller %s has not answered for %.0fs (its machine cannot be reached, or its process is "
                   "stopped), and module %s cancels a call when that lasts %gs (unreachable_caller)" % (
                       lost.node, lost.unanswered, self.module, self.unreachable))
        for call_id in lost.call_ids:
            if not self.server.cancel(call_id, why):
                continue
            if why:
                log.warning("cancelled call %s of module %s: its caller %s has not answered for %.0fs (its "
                            "machine cannot be reached, or its process is stopped)", call_id, self.module,
                            lost.node, lost.unanswered)
            else:
                log.warning("cancelled call %s of module %s: its caller %s is gone (%s)", call_id, self.module,
                            lost.module, lost.reason)
