"""What the views show of a watched run's tree: each node's shown status and name, the calls as shown,
the tree's parts (a ``with_cleanup`` top, its root and cleanup), the pending calls' title.

A mixin of :class:`coordinator.watchstate.WatchState`, which holds the state and its lock: the views call
these on the state, and they only read it, so they are kept apart from the applying of records.
Calls the run's stop from outside halted and those of a tree's cleanup cut short are shown as ``bmtree
run``'s summary and ``bmtree replay`` show them (:mod:`coordinator.watchstops`), and the top node of a
tree with ``cleanup:`` halted so as the run's status.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Dict, List, Set, Tuple

from coordinator.runevents import status_word
from coordinator.watchstops import run_stop_status

if TYPE_CHECKING:   # the mixin's host
    from coordinator.watchstate import WatchState

__all__ = ["WatchLabels"]


class WatchLabels:
    """The display-facing readings of :class:`coordinator.watchstate.WatchState` (see the module's docstring)."""

    def label(self: WatchState, i: int) -> str:
        """A node's shown status: RUNNING, SUCCESS, FAILURE, HALTED (a running node its parent
        stopped), ``was SUCCESS`` / ``was FAILURE`` (it ended so and was reset since: a selector
        clears the children it moved past, a stopped tree its finished nodes) or '' (never ticked).
        The top node of a tree with ``cleanup:`` stands for the run: halted (root was stopped from
        outside, then the cleanup ran), it shows the run's status, INTERRUPTED for a Ctrl-C
        (``bmtree run`` and ``replay`` print it so: :func:`coordinator.runevents.halted_word`)."""
        s = self.status.get(i, "INVALID")
        if s == "INVALID":
            if self.halted.get(i):
                top = self.parts()[0]
                stopped = run_stop_status(self.end, self.blackboard) if top is not None and i == top else ""
                return status_word(stopped) if stopped else "HALTED"
            return "was %s" % self.last[i] if i in self.last else ""
        return s

    def call_label(self: WatchState, c: Dict[str, Any]) -> Tuple[str, str]:
        """A finished call's (status, error) as shown: ``interrupted`` (``halted  stopped after 60 s``)
        for one the stop from outside halted, why the cleanup was cut short for one of its calls halted
        then, as ``bmtree run``'s summary and ``bmtree replay`` say (:mod:`coordinator.watchstops`)."""
        with self.lock:
            return self.stops.label(c, self.end, self.blackboard)

    def call_settled(self: WatchState, c: Dict[str, Any]) -> bool:
        """Whether :meth:`call_label` of a finished call is final (``--plain`` holds its line until then)."""
        with self.lock:
            return self.stops.settled(c, self.end, self.blackboard, self.tick_t)

    def shown_calls(self: WatchState) -> List[Dict[str, Any]]:
        """The finished calls kept, each with the status and error :meth:`call_label` shows."""
        with self.lock:
            out = []
            for c in self.calls:
                status, error = self.call_label(c)
                same = status == str(c.get("status")) and error == str(c.get("error") or "")
                out.append(c if same else dict(c, status=status, error=error))
            return out

    def name(self: WatchState, i: int) -> str:
        """A node's name as shown: an include's with the values its arguments had when it started
        (``fetch_item(item="milk")``, not ``fetch_item(item=$item)``), each value cut to 40 characters."""
        return self.args.name(i, self._node_name(i)) if i in self.args.values else self._node_name(i)

    def _node_name(self: WatchState, i: int) -> str:
        """A node's own name, from its tree record (cached per tree)."""
        names = getattr(self, "_names", None)
        if names is None or names[0] is not self.nodes:
            names = self._names = (self.nodes, {n.get("id"): str(n.get("name", "?")) for n in self.nodes})
        return names[1].get(i, "?")

    def pending_title(self: WatchState) -> str:
        """The pending calls' panel title: during a tree's cleanup, whose calls they are (``pending
        calls of the cleanup (root stopped)``)."""
        with self.lock:
            mine = [c for c in self.pending.values() if c.get("node") in self.cleanup_ids]
            if not mine:
                return "pending calls"
            ended = self.blackboard.get("ended")
            how = " (root %s)" % ended if isinstance(ended, str) and ended else ""
            if len(mine) == len(self.pending):
                return "pending calls of the cleanup%s" % how
            return "pending calls (%d of the cleanup%s)" % (len(mine), how)

    @property
    def cleanup_ids(self: WatchState) -> Set[int]:
        """The ids of the tree's cleanup (the second node under its ``with_cleanup`` top node); none
        without ``cleanup:``."""
        with self.lock:
            if self._cleanup is None:
                under: Set[int] = set()
                todo = [self.parts()[2]] if self.parts()[2] is not None else []
                while todo:
                    i = todo.pop()
                    under.add(i)
                    todo.extend(n.get("id") for n in self.nodes if n.get("parent") == i and n.get("id") not in under)
                self._cleanup = under
            return self._cleanup

    def parts(self: WatchState) -> Tuple[Any, Any, Any]:
        """The ids of a tree's ``with_cleanup`` top node, of its root and of its cleanup's top node;
        (None, None, None) for a tree without ``cleanup:``."""
        with self.lock:
            if self._parts is None:
                top = [n for n in self.nodes if n.get("parent") is None]
                below = [n.get("id") for n in self.nodes if top and n.get("parent") == top[0].get("id")]
                self._parts = ((top[0].get("id"), below[0], below[1]) if top and top[0].get("kind") == "with_cleanup"
                               and len(below) == 2 else (None, None, None))
            return self._parts

    def _top(self: WatchState) -> Any:
        return next((n.get("id") for n in self.nodes if n.get("parent") is None), None)

    def _kinds(self: WatchState) -> Tuple[Dict[int, str], Dict[int, Any]]:
        """Each node's kind and parent (cached per tree)."""
        cached = getattr(self, "_kind_cache", None)
        if cached is None or cached[0] is not self.nodes:
            cached = self._kind_cache = (self.nodes, {n.get("id"): str(n.get("kind") or "") for n in self.nodes},
                                         {n.get("id"): n.get("parent") for n in self.nodes})
        return cached[1], cached[2]
