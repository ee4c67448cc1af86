"""The runs a watch does not show: one master carries one run stream, and a second ``bmtree run``
on it (a forgotten terminal) publishes on the same topics.

A watch stays on the run it shows (the first one seen, or the one ``watch --run`` names): the
records of the others are kept aside here, bounded, so that ``watch --follow`` can show the
next one once the shown one has ended, and the watch can say how to watch them.
"""
from __future__ import annotations

import typing
from collections import OrderedDict
from typing import Any, Dict, List, Optional

__all__ = ["OtherRuns", "run_matches", "short_id", "covered", "Cover", "MAX_RUNS", "MAX_RECORDS"]

MAX_RUNS = 16        # other runs remembered (the oldest forgotten first)
MAX_RECORDS = 2000   # records kept aside per run (more: its latest snapshot and what it does not hold)


def run_matches(run: str, wanted: str) -> bool:
    """``watch --run``: the run's id (``20261122-031500-1a2b3c``, as in the run stream and the
    run log's file name) or its last part (``1a2b3c``)."""
    return bool(wanted) and (run == wanted or run.endswith("-" + wanted))


def short_id(run: str) -> str:
    """The last part of a run's id (``1a2b3c``), which ``--run`` takes too."""
    return run.rsplit("-", 1)[-1] if "-" in run else run


def _same(a: Dict[str, Any], b: Dict[str, Any]) -> bool:
    """The same record (an event, a notice, a control answer), whatever its ``type`` key (a snapshot's
    lists may leave it out)."""
    return {k: v for k, v in a.items() if k not in ("type", "v")} == {k: v for k, v in b.items() if k not in ("type", "v")}


class Cover:
    """What a run's ``snapshot`` holds, to tell whether a live record of the run is already in it, whatever
    order they came in (:meth:`covers`)."""

    def __init__(self, snap: Dict[str, Any]):
        self.snap = snap
        self.n = int(snap.get("n") or 0)
        self.tick_t = float(snap["tick_t"]) if snap.get("tick_t") is not None else float(snap.get("t") or 0.0)
        self.pending = {c.get("call_id") for c in snap.get("pending") or [] if isinstance(c, dict)}
        self.ended = {c.get("call_id") for c in snap.get("calls") or [] if isinstance(c, dict)}

    def covers(self, rec: Dict[str, Any]) -> bool:
        """Whether ``rec`` is in the snapshot.

        Over ROS the snapshot and the other records come on topics of their own, ordered per topic only
        (and the run sends them through queues of their own): a record that came before the snapshot may
        be newer than it (a ``call_end`` taken at the tick after it, its ``t`` the earlier time its answer
        came), one that comes after it may be in it. The snapshot was taken after its tick ``n`` (at
        ``tick_t``), so a record is in it when it is: a tick up to ``n``; a call it lists as ended; a call's
        start it lists (pending or ended), or older than that tick; a call's end it does not list as
        pending whose call began before that tick; a write, an event, a notice or a control answer up to
        that tick, or one its (last) lists hold. A ``call_answer`` never is (a call still pending takes it)."""
        kind = rec.get("type")
        if kind in ("snapshot", "tree"):
            return True
        t = float(rec.get("t") or 0.0)
        if kind == "tick":
            return int(rec.get("n") or 0) <= self.n
        if kind == "end":
            return self.snap.get("end") is not None
        if kind == "call_answer":
            return False
        cid = rec.get("call_id")
        if kind == "call_start":
            return cid in self.pending or cid in self.ended or t <= self.tick_t
        if kind == "call_end":
            return cid in self.ended or (cid not in self.pending and t - float(rec.get("duration") or 0.0) <= self.tick_t)
        if t <= self.tick_t:
            return True
        listed = self.snap.get("control") if kind == "control" else \
            self.snap.get("events") if kind in ("event", "notice") else None
        return any(isinstance(e, dict) and _same(e, rec) for e in listed or [])


def covered(snap: Dict[str, Any], rec: Dict[str, Any]) -> bool:
    """Whether a live record of a run is already in its snapshot ``snap`` (:meth:`Cover.covers`)."""
    return Cover(snap).covers(rec)


class OtherRuns:
    """Per run id: its tree record, whether it ended, and its records (at most :data:`MAX_RECORDS`: then its
    latest snapshot and the records it does not hold)."""

    def __init__(self) -> None:
        self._runs: typing.OrderedDict[str, Dict[str, Any]] = OrderedDict()

    def _entry(self, run: str) -> Dict[str, Any]:
        entry = self._runs.get(run)
        if entry is None:
            entry = self._runs[run] = {"tree": None, "ended": False, "records": []}
            while len(self._runs) > MAX_RUNS:
                self._runs.popitem(last=False)
        return entry

    def tree(self, run: str, rec: Dict[str, Any]) -> bool:
        """Keep a run's tree record; True the first time that run is seen with one."""
        entry = self._entry(run)
        first = entry["tree"] is None
        entry["tree"] = rec
        if entry["ended"]:
            entry["records"] = []  # (its end came first) not shown later: --follow shows a live one
        return first

    def keep(self, run: str, rec: Dict[str, Any]) -> None:
        """Keep another run's record: a snapshot replaces what it covers, an end ends the run."""
        entry = self._entry(run)
        kind = rec.get("type")
        if entry["ended"] and entry["tree"] is not None:
            return  # an ended run seen with its tree is not shown later (--follow shows the next live one)
        records: List[Dict[str, Any]] = entry["records"]
        if kind == "end":  # kept while its tree has not come: once it comes, the run may be the one shown
            entry["ended"] = True
            if entry["tree"] is not None:
                records.clear()
                return
        records.append(rec)  # all of them, in the order they came: shown, the run says each (--plain)
        if len(records) > MAX_RECORDS:  # too many: its latest snapshot and what that one does not hold
            snaps = [r for r in records if r.get("type") == "snapshot"]
            if snaps:
                cover = Cover(snaps[-1])
                records[:] = [snaps[-1]] + [r for r in records if not cover.covers(r)]
            if len(records) > MAX_RECORDS:
                records[:] = records[:1] + records[len(records) - MAX_RECORDS + 1:] if snaps else records[-MAX_RECORDS:]

    def take(self, run: str) -> List[Dict[str, Any]]:
        """The records kept of ``run``, which is shown from now on (forgotten here)."""
        entry = self._runs.pop(run, None)
        return list(entry["records"]) if entry else []

    def next_live(self) -> Optional[Dict[str, Any]]:
        """The tree record of the newest other run that has not ended (to show next), or None."""
        for entry in reversed(self._runs.values()):
            if entry["tree"] is not None and not entry["ended"]:
                return entry["tree"]
        return None

    def notice(self, run: str, shown: str) -> str:
        """The watch's notice that ``run`` started while ``shown`` is shown, and how to watch it."""
        tree = self._runs[run]["tree"] or {}
        return ("another run started: %s (bmtree watch --run %s shows it); this watch stays on %s (the other one: "
                "run %s, pid %s)" % (tree.get("name") or "?", short_id(run), shown, run, tree.get("pid", "?")))

    def summary(self) -> List[Dict[str, Any]]:
        """The other runs seen with a tree: ``run``, ``name``, ``pid``, ``ended`` (oldest first)."""
        return [{"run": run, "name": e["tree"].get("name"), "pid": e["tree"].get("pid"), "ended": e["ended"]}
                for run, e in self._runs.items() if e["tree"] is not None]
