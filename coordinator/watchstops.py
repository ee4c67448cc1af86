"""The calls a stop from outside halted, as a watcher tells them from the run stream.

A call the tree halts ends ``halted`` ("halted by the tree"). When the run is stopped from outside
(Ctrl-C, ``--max-duration``) root is halted and so are its calls; when a tree's cleanup is cut
short (its time limit, a second Ctrl-C) its calls are. ``bmtree run``'s summary and ``bmtree
replay`` show those as :func:`coordinator.runner.stop_label` and
:func:`~coordinator.runner.cleanup_stop_label` say (``interrupted``; ``halted  stopped after 60 s``;
``halted  did not end within 30 s (cleanup_timeout)``), and so does the watch, from here.

The stop's calls are those that ended halted since the tick record before the one in which root
(for a tree without ``cleanup:``, its top node) went INVALID — the tick ``bmtree replay`` calls the
stop's — and likewise the cleanup's top for a cut cleanup. Over ROS the records of calls and of ticks
come on different topics, not ordered among them: a halted call that comes after that tick record
is one of them when it ended between the two tick records' times.
"""
from __future__ import annotations

from typing import Any, Collection, Dict, List, Optional, Set, Tuple

from coordinator.runevents import stop_status
from coordinator.runner import cleanup_stop_label, stop_label

__all__ = ["StopCalls", "run_stop_status"]


def run_stop_status(end: Optional[Dict[str, Any]], blackboard: Dict[str, Any]) -> str:
    """The status of a run stopped from outside (INVALID for a Ctrl-C, FAILURE for a time limit): its
    ``end`` record's; before it, for a tree with ``cleanup:``, what the reason its cleanup reads says
    (``ended`` is ``stopped``); '' when not known (or the run was not stopped so)."""
    if end is not None:
        return "" if end.get("gone") else str(end.get("status") or "")
    reason = blackboard.get("ended_reason")
    if blackboard.get("ended") == "stopped" and isinstance(reason, str):
        return stop_status(reason)
    return ""


class StopCalls:
    """The ids of the calls the stop from outside halted (``stopped``) and of the cleanup's calls
    halted when it was cut short (``cut``), fed by :class:`coordinator.watchstate.WatchState`."""

    def __init__(self, stopped: Collection[str] = (), cut: Collection[str] = ()) -> None:
        self.stopped: Set[str] = {str(k) for k in stopped}
        self.cut: Set[str] = {str(k) for k in cut}
        self._since: List[Tuple[str, bool]] = []  # (id, of the cleanup) of calls ended halted since the last tick
        self._spans: Dict[bool, Tuple[float, float]] = {}  # of the cleanup -> (t of the tick before, t of the tick)

    def halted(self, call_id: str, of_cleanup: bool, t: float) -> None:
        """A call that ended halted at ``t`` (``of_cleanup``: a call of the tree's cleanup)."""
        span = self._spans.get(of_cleanup)
        if span is None:
            self._since.append((call_id, of_cleanup))
        elif span[0] < t:  # come after the tick record that halted it: once root (the cleanup) was halted,
            # nothing but that stop halts a call of it, whether its record's time is before that tick's or
            # just after (the halt's cancels are sent as the tick ends: 2 of 6 Ctrl-C were "halted by the tree")
            (self.cut if of_cleanup else self.stopped).add(call_id)

    def tick(self, invalid: Collection[Any], root: Any, cleanup: Any, before: float, t: float) -> None:
        """A tick record at ``t`` (the one before it at ``before``) in which the nodes ``invalid`` went
        INVALID; ``root``: the id of root (of the top node without ``cleanup:``), ``cleanup``: of the
        cleanup's top node (None without one)."""
        for of_cleanup, node in ((False, root), (True, cleanup)):
            if node is not None and node in invalid and of_cleanup not in self._spans:
                self._spans[of_cleanup] = (before, t)
                (self.cut if of_cleanup else self.stopped).update(c for c, mine in self._since if mine == of_cleanup)
        self._since = []

    def waiting(self, call_id: str) -> bool:
        """Whether a halted call came after the last tick record (the one that halted it may be next)."""
        return any(c == call_id for c, _mine in self._since)

    def label(self, c: Dict[str, Any], end: Optional[Dict[str, Any]], blackboard: Dict[str, Any]) -> Tuple[str, str]:
        """A finished call's (status, error) as ``bmtree run``'s summary and ``bmtree replay`` show it;
        as it ended for any other call, and for these before the run says how it was stopped."""
        cid = str(c.get("call_id"))
        if cid in self.stopped:
            status = run_stop_status(end, blackboard)
            if status:
                reason = end.get("reason") if end is not None else blackboard.get("ended_reason")
                return stop_label(status == "INVALID", str(reason or ""))
        elif cid in self.cut and end is not None:
            said = end.get("cleanup")
            if isinstance(said, dict) and said.get("status") not in (None, "SUCCESS"):
                return cleanup_stop_label(str(said.get("reason") or ""))
        return str(c.get("status")), str(c.get("error") or "")

    def settled(self, c: Dict[str, Any], end: Optional[Dict[str, Any]], blackboard: Dict[str, Any],
                tick_t: float) -> bool:
        """Whether :meth:`label` of a finished call is final: a call that ended halted is known to be
        one of the stop's only at the tick record that halted it (``tick_t``: the last one's time), and
        how the run was stopped at its end (a line printer holds its line until then)."""
        cid = str(c.get("call_id"))
        if c.get("status") != "halted":
            return True
        if cid in self.stopped:
            return end is not None or bool(run_stop_status(end, blackboard))
        if cid in self.cut:
            return end is not None
        if end is not None:   # the tick record that halted it may come after the end (another topic)
            return not self.waiting(cid)
        return not self.waiting(cid) or tick_t > float(c.get("t") or 0.0)
