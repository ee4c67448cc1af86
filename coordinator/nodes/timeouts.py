"""The ``timeout`` option of the leaves that wait for an answer (``call``, ``wait_event``, ``recall``):
seconds, a ``$reference`` or a ``$( … )`` expression, or, where the kind has no limit to give,
``none``. A spelling that looks like "no limit" but is not (a YAML null, ``off``, ``0``, ``None``,
``.inf``) is an error that says how to write it for that kind."""
from __future__ import annotations

from typing import Any, Dict

from coordinator.bounds import beyond_bound, finite_number, shown
from coordinator.nodes.base import TYPES, Option
from coordinator.treeast import TreeNode

__all__ = ["LONG_SECONDS", "NO_TIMEOUT", "long_seconds", "timeout_option", "with_no_timeout"]

NO_TIMEOUT = "none"
"""``timeout: none``, as a spec holds it: no limit (the only text a timeout may be)."""


def timeout_option(p: Any, node: TreeNode, raw: Any, option: Option, kind: str, how: str,
                   unlimited: bool = True) -> Any:
    """The ``timeout`` option of a ``kind`` node: seconds, a reference or an expression (``p.opt``), or
    ``NO_TIMEOUT`` (when ``unlimited``: the kind may wait without limit); None when it is left out or
    wrong (after an error ending with ``how``, the kind's way to write it). A YAML null, a bool, zero,
    infinity, other text (``None``, ``never``, ``5s``) and, for a kind that always has a limit,
    ``none`` are errors."""
    if "timeout" not in raw:
        return None
    v, at = raw["timeout"], raw.val_pos["timeout"]
    label = "timeout of %s" % kind
    expect = TYPES["seconds"].expect
    if isinstance(v, str) and v == NO_TIMEOUT:
        if unlimited:
            return NO_TIMEOUT
        p.err(at, "%s must be %s, got 'none': %s" % (label, expect, how))
    elif v is None:
        p.err(at, "%s is null (written null, ~ or left empty), which is not read as no limit: %s" % (label, how))
    elif isinstance(v, bool):
        p.err(at, "%s is %s (YAML reads an unquoted yes/no/on/off as true or false): %s" % (
            label, str(v).lower(), how))
    elif isinstance(v, (int, float)) and not (finite_number(v) and v > 0):
        p.err(at, "%s must be %s, got %s: %s" % (label, expect, shown(v), how))
    elif isinstance(v, str) and (not v.startswith("$") or v.startswith("$$")):
        p.err(at, "%s must be %s%s, got %r: %s" % (label, expect, " or 'none'" if unlimited else "", v, how))
    else:
        value = p.opt(node, raw, option)
        long_seconds(p, value, at, label)
        return value
    return None


LONG_SECONDS = 1000
"""Durations from this many seconds on are likely milliseconds written as BehaviorTree.CPP's ``msec`` takes
them (a warning), unless a whole number of half hours (1800, 3600: a limit for a whole task)."""


def long_seconds(p: Any, value: Any, at: Any, label: str) -> None:
    """Warn about a duration written in milliseconds by habit: ``timeout: 3000`` is 50 minutes."""
    if not finite_number(value):
        return
    if beyond_bound("seconds", value):
        p.err(at, "%s is %s" % (label, beyond_bound("seconds", value)))
        return
    if value < LONG_SECONDS or value % 1800 == 0:
        return
    minutes = value / 60.0
    shown = "%.0f min" % minutes if minutes < 120 else "%.1f h" % (minutes / 60.0)
    p.warn(at, "%s is %g seconds (%s): durations are in seconds; for %g milliseconds write %g" % (
        label, value, shown, value, value / 1000.0))


def with_no_timeout(schema: Dict[str, Any]) -> Dict[str, Any]:
    """A kind's JSON Schema (``NodeKind.schema``) whose ``timeout`` also takes ``none``."""
    t = schema["properties"]["timeout"]
    t["anyOf"] = list(t["anyOf"]) + [{"const": NO_TIMEOUT}]
    return schema
