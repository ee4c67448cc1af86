"""How large a number a tree, a scenario or an option may give, and how such a number is said: one
place for the bounds (a loop of more runs, or a wait of more seconds, would never end) and for the
checks that never convert a number (``math.isfinite`` of a whole number past a float's range raises
OverflowError)."""
from __future__ import annotations

import sys
from typing import Any

from comm.typewords import whole_number_text

__all__ = ["MAX_COUNT", "MAX_SECONDS", "finite_number", "shown", "beyond_bound"]

_MAX = sys.float_info.max

MAX_COUNT = 10 ** 9
"""The largest count of ``retry``/``repeat`` (and ``for_each``'s ``max``), and of an option: more runs
would never end (and SQLite takes no whole number past 2**63 - 1)."""
MAX_SECONDS = 365 * 86400.0
"""The longest duration a tree or an option may give, a year: a longer wait never ends (and past some
292 years a wait of Python's threads or clocks raises OverflowError)."""


def finite_number(v: Any) -> bool:
    """A finite number, not a bool (``.inf`` seconds would make a bounded loop or wait endless); compared,
    not converted: ``math.isfinite`` of a whole number beyond a float's range raises OverflowError."""
    return v.__class__ is not bool and isinstance(v, (int, float)) and -_MAX <= v <= _MAX   # NaN: False


def shown(v: Any) -> str:
    """``repr(v)``, but a whole number beyond a float's range by its size (an error line, not 400 digits)."""
    if v.__class__ is bool or not isinstance(v, int) or finite_number(v):
        return repr(v)
    return "%s (numbers go up to 1.8e308)" % whole_number_text(v)


def beyond_bound(type_name: str, v: Any) -> str:
    """Why a count or a duration, of its type otherwise, is too large to mean anything (``1e+300, more
    than …``), '' when it is not (or it is of no such type)."""
    whole = v.__class__ is not bool and isinstance(v, int) or isinstance(v, float) and v % 1 == 0   # (inf, nan: no)
    if type_name == "count" and whole and v > MAX_COUNT:
        said = "%.3g" % v if finite_number(v) and v >= 10 ** 15 else shown(int(v))   # not 300 digits
        return "%s, more than %d: a loop of that many runs would never end (every loop is bounded: give " \
               "the most it may take)" % (said, MAX_COUNT)
    if type_name in ("seconds", "seconds0") and finite_number(v) and v > MAX_SECONDS:
        return "%g seconds, more than a year (%d s): durations are in seconds" % (v, MAX_SECONDS)
    return ""
