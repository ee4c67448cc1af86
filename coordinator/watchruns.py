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

__all__ = ["OtherRuns", "run_matches", "short_id", "MAX_RUNS", "MAX_RECORDS"]

MAX_RUNS = 16        # other runs remembered (the oldest forgotten first)
MAX_RECORDS = 2000   # records kept aside per run (after its latest snapshot)


def run_matches(run: str, wanted: str) -> bool:
    """``watch --run``: the run's id (``20261122-031500-1a2b3c``, as in the run stream and the
    run log's file name) or its last part (``1a2b3c``)."""
    return bool(wanted) and (run == wanted or run.endswith("-" + wanted))


def short_id(run: str) -> str:
    """The last part of a run's id (``1a2b3c``), which ``--run`` takes too."""
    return run.rsplit("-", 1)[-1] if "-" in run else run


class OtherRuns:
    """Per run id: its tree record, whether it ended, and its records since its latest snapshot."""

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
        return first

    def keep(self, run: str, rec: Dict[str, Any]) -> None:
        """Keep another run's record: a snapshot replaces what it covers, an end ends the run."""
        entry = self._entry(run)
        if entry["ended"]:
            return
        kind = rec.get("type")
        if kind == "end":
            entry["ended"], entry["records"] = True, []
            return
        records: List[Dict[str, Any]] = entry["records"]
        if kind == "snapshot":
            t, n = float(rec.get("t") or 0.0), int(rec.get("n") or 0)
            later = [r for r in records if float(r.get("t") or 0.0) > t or (
                r.get("type") == "tick" and int(r.get("n") or 0) > n)]
            records[:] = [rec] + later
        else:
            records.append(rec)
            del records[:-MAX_RECORDS]

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
