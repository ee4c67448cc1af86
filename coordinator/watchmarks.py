"""What a watched run's ticks and control answers say of single nodes, besides their statuses: the
steering marks (breakpoints, a node a breakpoint holds, outcomes forced by control) and where a running
loop or wait is (a for_each's element, a retry's attempt counted from its ticks, how long a ``wait`` has
waited), as the views show them on the node (:meth:`WatchMarks.note`, :meth:`WatchMarks.progress`).

A mixin of :class:`coordinator.watchstate.WatchState`, which holds the state and its lock and applies the
records: this bookkeeping reads the statuses it keeps, and is kept apart so that each file stays readable.
"""
from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any, Dict, List, Optional, Set

if TYPE_CHECKING:   # the mixin's host
    from coordinator.watchstate import WatchState

__all__ = ["WatchMarks", "HELD", "FORCED", "OUTCOMES", "WAITING_KINDS", "fill"]

OUTCOMES = ("SUCCESS", "FAILURE")
HELD = "held at breakpoint"   # a node a breakpoint holds: RUNNING, but it has not started
FORCED = "forced"             # an outcome a ``force`` command gave, not the node's own
#: a retry's own words end in "run 2 of 3"; the viewers call its runs attempts, as its reason does
_RETRY_RUN = re.compile(r"\brun (\d+) of (\d+)")
#: the leaves whose running time the views show (how long it has waited so far)
WAITING_KINDS = ("wait", "wait_event")


def fill(progress: Dict[str, Any], now: float) -> str:
    """A node's progress (:meth:`WatchMarks.progress`) in words at the run's time ``now``: its ``{s}``,
    the seconds since ``since`` (or until ``until``), as ``0.4 s``."""
    text = str(progress.get("text") or "")
    if "{s}" not in text:
        return text
    if progress.get("until") is not None:
        left = max(0.0, float(progress["until"]) - now)
    else:
        left = max(0.0, now - float(progress.get("since") or now))
    return text.replace("{s}", "%.1f s" % left)


class WatchMarks:
    """The per-node marks of :class:`coordinator.watchstate.WatchState` (see the module's docstring)."""

    def _reset_marks(self: WatchState) -> None:
        """No marks yet (:meth:`WatchState._reset`: a run shown anew); the attributes are the state's own."""
        #: each running ``retry``'s attempt, from the ticks: id -> [attempt (from 1), the run's time its
        #: last attempt failed while it waits to start the next one, else None]
        self.attempts: Dict[int, List[Any]] = {}
        #: a running retry's next attempt time, when the run says it (a tick's ``waits``: [[id, t]])
        self.waits: Dict[int, float] = {}
        #: when each running node went RUNNING (the run's time of that tick)
        self.since: Dict[int, float] = {}
        self.changed_t: Dict[int, float] = {}  # the run's time of each node's last change
        #: steering, from the control answers: the nodes with a breakpoint, those a breakpoint holds
        #: (id -> [its time, when the run was let go on or None]), forces to come (id -> [outcome, time])
        #: and outcomes forced (id -> outcome; until the node runs again)
        self.breaks: Set[int] = set()
        self.held: Dict[int, List[Any]] = {}
        self.forcing: Dict[int, List[Any]] = {}
        self.forced: Dict[int, str] = {}

    def _marks_snapshot(self: WatchState) -> Dict[str, Any]:
        """The marks' fields of a ``snapshot`` record (newer fields: an older bmtree's has none)."""
        return {"since": {str(k): v for k, v in self.since.items() if self.status.get(k) == "RUNNING"},
                "changed_t": {str(k): v for k, v in self.changed_t.items() if k in self.forcing},
                "attempts": {str(k): v for k, v in self.attempts.items()},
                "waits": {str(k): v for k, v in self.waits.items()},
                "breaks": sorted(self.breaks), "held": {str(k): v for k, v in self.held.items()},
                "forcing": {str(k): v for k, v in self.forcing.items()},
                "forced": {str(k): v for k, v in self.forced.items()}}

    @property
    def steerable(self: WatchState) -> bool:
        """Whether the viewers offer control commands now: a run is shown, it has not ended, and its
        ``tree`` record said it takes them (``--control``; a run of an older bmtree does not say: it may).
        False while no run is shown: nothing would take them."""
        return bool(self.nodes) and self.end is None and self.tree.get("control") is not False

    def no_steering(self: WatchState) -> str:
        """Why the viewers offer no control commands now ('' when they do)."""
        if not self.nodes:
            return "no run is shown yet: the keys steer a run started with --control once one is shown"
        if self.tree.get("control") is False:
            return "this run takes no commands: it was started without --control"
        if self.end is not None:
            return "the run has ended: it takes no more commands"
        return ""

    def note(self: WatchState, i: int) -> str:
        """What the run's steering says of a node's shown status: held at a breakpoint (RUNNING, not
        started), or an outcome forced by control (also once reset: ``was SUCCESS``), else ''."""
        with self.lock:
            status = self.status.get(i, "INVALID")
            if i in self.held and status == "RUNNING":
                return HELD
            if i in self.forced and self.label(i) in (self.forced[i], "was " + self.forced[i]):
                return FORCED
            return ""

    def progress(self: WatchState, i: int) -> Optional[Dict[str, Any]]:
        """Where a running loop or wait is, for the views (``text``, with ``{s}`` the seconds since ``since``
        or until ``until``: :func:`fill`): a for_each's ``item 2 of 3``, a retry's ``attempt 2 of 3`` (or,
        between attempts, ``waiting {s} before attempt 2``, ``next attempt in {s} (2 of 3)``), a repeat's
        ``run 2 of 3`` (when the run says it), a ``wait``/``wait_event``'s ``waited {s}``; None else."""
        with self.lock:
            if self.status.get(i) != "RUNNING" or self.note(i):
                return None
            kind = self._kinds()[0].get(i, "")
            at = self.loops.get(i)
            if kind == "retry" and (at is not None or i in self.attempts):
                n, waiting = (int(at[0]), None) if at is not None else (int(self.attempts[i][0]), self.attempts[i][1])
                of = " of %d" % int(at[1]) if at is not None else ""
                if i in self.waits:
                    return {"text": "next attempt in {s} (%d%s)" % (n, of), "until": self.waits[i]}
                if waiting is not None:
                    return {"text": "waiting {s} before attempt %d%s" % (n, of), "since": waiting}
                return {"text": "attempt %d%s" % (n, of)}
            if at is not None:
                return {"text": "%s %d of %d" % ("run" if kind == "repeat" else "item", at[0], at[1])}
            if kind in WAITING_KINDS and i in self.since:
                return {"text": "waited {s}", "since": self.since[i]}
            return None

    def named(self: WatchState, name: Any, every: bool = False) -> List[int]:
        """The ids a control command's ``node`` names, as the run reads it: the nodes so named, else
        ``NAME@ID`` (``@ID``) the node of that id. Several so named: all of them with ``every`` (a clear),
        else the one that is not the top of a tree with ``cleanup:`` (never steered), if one."""
        if not isinstance(name, str):
            return []
        ids = [n.get("id") for n in self.nodes if n.get("name") == name]
        if not ids:
            head, at, num = name.rpartition("@")
            if at and num.isdecimal() and num.isascii() and len(num) <= 9:
                i = int(num)
                if any(n.get("id") == i for n in self.nodes) and (not head or self._node_name(i) == head):
                    return [i]
            return []
        if len(ids) > 1 and not every:
            top = self.parts()[0]
            ids = [i for i in ids if i != top]
            return ids if len(ids) == 1 else []
        return ids

    def _said(self: WatchState, i: int, text: str) -> str:
        """A node's failure as the viewers say it: a retry's ``failed in run 2 of 2`` is its attempt 2 of 2."""
        if text and self._kinds()[0].get(i) == "retry":
            return _RETRY_RUN.sub(r"attempt \1 of \2", text)
        return text

    def _changed(self: WatchState, i: int, old: str, new: str, failed_under: List[int]) -> None:
        """One change of a tick (at ``tick_t``): since when a node runs, a retry's attempt, a forced outcome,
        a held node that ended (halted) without starting."""
        kinds, parents = self._kinds()
        self.changed_t[i] = self.tick_t
        if new == "RUNNING":
            if old != "RUNNING":
                self.since[i] = self.tick_t
                self.forced.pop(i, None)   # it runs again: its next outcome is its own
                if kinds.get(i) == "retry":
                    self.attempts[i] = [1, None]
                    self.waits.pop(i, None)
        else:
            self.since.pop(i, None)
            if kinds.get(i) == "retry":
                self.attempts.pop(i, None)
                self.waits.pop(i, None)
            if i in self.held and self.tick_t > float(self.held[i][0]):  # halted or forced while held
                del self.held[i]
        if new in OUTCOMES:
            force = self.forcing.get(i)
            if force is not None and force[0] == new and self.tick_t >= float(force[1]):
                self.forced[i] = new
                del self.forcing[i]
        up = parents.get(i)
        if up is not None and kinds.get(up) == "retry":
            if new == "FAILURE":
                failed_under.append(up)
            elif new == "RUNNING" and up in self.attempts:   # the next attempt started
                self.attempts[up][1] = None
                self.waits.pop(up, None)

    def _attempted(self: WatchState, failed_under: List[int]) -> None:
        """Retries whose child failed in this tick and that still run: their next attempt, now or after
        their delay (the child does not run meanwhile)."""
        _kinds, parents = self._kinds()
        for r in dict.fromkeys(failed_under):
            if self.status.get(r) != "RUNNING" or r not in self.attempts:
                continue
            running = any(self.status.get(c) == "RUNNING" for c, up in parents.items() if up == r)
            self.attempts[r] = [int(self.attempts[r][0]) + 1, None if running else self.tick_t]

    def _let_go(self: WatchState) -> None:
        """Held nodes whose run went on (resumed, stepped) before the tick just applied: they start now."""
        for i, (_at, gone_on) in list(self.held.items()):
            if gone_on is not None and self.tick_t > float(gone_on):
                del self.held[i]
                if self.status.get(i) == "RUNNING":
                    self.since[i] = self.tick_t

    def _steered(self: WatchState, rec: Dict[str, Any]) -> None:
        """What a control answer says of single nodes: a breakpoint set or cleared, one that holds a node
        (until the run goes on: a resume, a step, a stop), an outcome to force the next time it is ticked."""
        if not rec.get("ok"):
            return
        what = rec.get("command")
        args = rec.get("args") if isinstance(rec.get("args"), dict) else {}
        t = float(rec.get("t") or 0.0)
        if what in ("break", "breakpoint"):
            for i in self.named(args.get("node")):
                self.breaks.add(i)
                if what == "breakpoint":  # it holds the node (RUNNING: its parent waits) until the run goes on
                    self.held[i] = [t, None]
        elif what == "clear":
            self.breaks.difference_update(self.named(args.get("node"), every=True))
        elif what == "force" and str(args.get("outcome", "")).upper() in OUTCOMES:
            outcome = str(args.get("outcome")).upper()
            for i in self.named(args.get("node")):
                if self.status.get(i) == outcome and self.changed_t.get(i, -1.0) >= t:  # its tick came first
                    self.forced[i] = outcome
                    self.forcing.pop(i, None)
                else:
                    self.forcing[i] = [outcome, t]
        if rec.get("paused") is False or what == "step":  # the run goes on: a held node starts at its next tick
            for held in self.held.values():
                if held[1] is None and t > float(held[0]):
                    held[1] = t
            self._let_go()

    def _load_marks(self: WatchState, rec: Dict[str, Any]) -> None:
        """A snapshot's per-node extras (a newer run's; an older one's steering marks from its control answers)."""
        known = {n.get("id") for n in self.nodes}

        def ids(value: Any) -> Dict[int, Any]:
            items = value.items() if isinstance(value, dict) else ((k, True) for k in value or [])
            return {int(k): v for k, v in items if str(k).lstrip("-").isdigit() and int(k) in known}

        self.since = {k: float(v) for k, v in ids(rec.get("since")).items()}
        self.attempts = {k: [int(v[0]), None if v[1] is None else float(v[1])] for k, v in ids(rec.get("attempts")).items()}
        self.waits = {k: float(v) for k, v in ids(rec.get("waits")).items()}
        self.changed_t = {k: float(v) for k, v in ids(rec.get("changed_t")).items()}
        if "breaks" in rec:
            self.breaks = set(ids(rec.get("breaks")))
            self.held = {k: [float(v[0]), None if v[1] is None else float(v[1])] for k, v in ids(rec.get("held")).items()}
            self.forcing = {k: [str(v[0]), float(v[1])] for k, v in ids(rec.get("forcing")).items()}
            self.forced = {k: str(v) for k, v in ids(rec.get("forced")).items() if v in OUTCOMES}
        else:  # a snapshot of an older bmtree: what its control answers say
            self.breaks, self.held, self.forcing, self.forced = set(), {}, {}, {}
            for c in self.control:
                self._steered(c)
            for i in list(self.forcing):  # forced since (a FAILURE says so)
                if self.feedback.get(i, "").startswith("forced to "):
                    self.forced[i] = self.forcing.pop(i)[0]
