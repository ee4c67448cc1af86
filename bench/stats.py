"""Small statistics helpers and the result row."""
from __future__ import annotations

import statistics
from dataclasses import asdict, dataclass, field
from typing import Any, Dict, List, Optional, Sequence

__all__ = ["Row", "summary"]


def _pct(sorted_xs: Sequence[float], p: float) -> float:
    i = min(len(sorted_xs) - 1, max(0, int(round(p / 100.0 * (len(sorted_xs) - 1)))))
    return sorted_xs[i]


def summary(xs: Sequence[float]) -> Dict[str, float]:
    s = sorted(xs)
    return {"median": statistics.median(s), "p90": _pct(s, 90), "p99": _pct(s, 99), "n": len(s)}


@dataclass
class Row:
    measure: str
    value: float
    unit: str
    baseline: Optional[float] = None
    target: str = ""
    ok: Optional[bool] = None
    extra: Dict[str, Any] = field(default_factory=dict)

    @property
    def ratio(self) -> Optional[float]:
        if self.baseline in (None, 0):
            return None
        return self.value / self.baseline

    def as_dict(self) -> Dict[str, Any]:
        d = asdict(self)
        d["ratio"] = self.ratio
        return d


def table(rows: List[Row]) -> str:
    head = ("measure", "value", "baseline", "ratio", "target", "")
    lines = []
    cells = []
    for r in rows:
        v = "%.3f %s" % (r.value, r.unit) if r.unit != "/s" else "%.0f /s" % r.value
        b = "" if r.baseline is None else ("%.3f %s" % (r.baseline, r.unit))
        ratio = "" if r.ratio is None else "%.2fx" % r.ratio
        verdict = "" if r.ok is None else ("ok" if r.ok else "MISSED")
        cells.append((r.measure, v, b, ratio, r.target, verdict))
    widths = [max(len(str(c[i])) for c in cells + [head]) for i in range(len(head))]
    fmt = "  ".join("%%-%ds" % w for w in widths)
    lines.append(fmt % head)
    lines.append("  ".join("-" * w for w in widths))
    lines.extend(fmt % c for c in cells)
    return "\n".join(lines)
