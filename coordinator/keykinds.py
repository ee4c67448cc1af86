"""The kind of value a tree key holds (number, string, bool, list, message), known before running, for the
expression checks: from the ROS types the definitions give its writers, and from what a ``set`` writes, which
has no ROS type (a literal, a ``{…}`` template, an expression whose kind is known).

:class:`coordinator.values.KeyTypes` keeps ROS types only (a call's inputs are checked, and converted, with
them): what a writer without one gives is in its ``kinds`` — a kind; ``~`` and a kind for a value that may
also be a one-field message standing for it (a copy of a key a call writes too: ``$k.data`` may be read); None
when it is not known (a tree input, whose caller may give any value, a recall of a plain name, an include's
argument). Writers that agree on the kind make it known, whatever their types: ``set: {n: 0}`` and ``set:
{n: 2.5}``, or ``set`` and a ``std_msgs/Int32`` output, hold a number; ``0`` and ``"x"`` nothing known.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Set, Tuple

from coordinator.refs import Ref

__all__ = ["KIND_WORDS", "LOOSE", "NUMBERS", "agreed_kind", "copied_kind", "field_type", "kind_misfit",
           "kind_of_type", "stands_for"]

NUMBERS = {"int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float32", "float64",
           "byte", "char"}
LOOSE = "~"
"""Before a kind in ``KeyTypes.kinds``: the value may be a one-field message standing for a value of that kind."""
KIND_WORDS = {"number": "a number", "string": "text", "bool": "true or false", "list": "a list",
              "message": "a message", "null": "null"}


def kind_of_type(t: str) -> Optional[str]:
    """The kind a value of ROS type ``t`` has in an expression (a one-field message stands for its field)."""
    from comm.rostypes import resolve_type

    if t.endswith("]"):
        return "list"
    if t in NUMBERS:
        return "number"
    if t == "string":
        return "string"
    if t == "bool":
        return "bool"
    cls = resolve_type(t)
    if cls is None:
        return None
    if len(cls.__slots__) == 1:
        return kind_of_type(cls._slot_types[0])
    return "message"


def field_type(t: str, step: Any) -> Optional[str]:
    from comm.rostypes import resolve_type

    if isinstance(step, int):
        return t[:t.rindex("[")] if t.endswith("]") else None
    cls = resolve_type(t)
    if cls is None or step not in cls.__slots__:
        return None
    return cls._slot_types[list(cls.__slots__).index(step)]


def stands_for(t: str) -> str:
    """The type a value of type ``t`` is indexed as: a one-field message stands for its field (as
    :func:`coordinator.refs.unwrap` makes it when running)."""
    from comm.rostypes import resolve_type

    for _ in range(8):
        cls = resolve_type(t)
        if cls is None or len(cls.__slots__) != 1:
            break
        t = cls._slot_types[0]
    return t


def agreed_kind(types: Dict[str, Set[Optional[str]]], key: str) -> Tuple[Optional[str], bool]:
    """The kind every writer of ``key`` gives (None: one gives none, or they disagree), and whether the value
    is surely a plain one, never a message (only ``set`` values: a field or an index of it can be checked)."""
    known = types.get(key)
    if not known:
        return None, False
    kinds = getattr(types, "kinds", {}).get(key, ()) if None in known else ()
    if None in known and (not kinds or None in kinds):
        return None, False
    found = {kind_of_type(t) for t in known if t is not None}
    found.update(k.lstrip(LOOSE) for k in kinds)
    if len(found) != 1 or None in found:
        return None, False
    return found.pop(), known == {None} and not any(k.startswith(LOOSE) for k in kinds)


def copied_kind(types: Dict[str, Set[Optional[str]]], ref: Ref) -> Optional[str]:
    """What a key set to ``ref`` gets in ``KeyTypes.kinds`` when the reference has no ROS type: the kind of
    the key it reads (``~`` before it when that may be a message), None for a field or an element of it."""
    if ref.path:
        return None
    kind, plain = agreed_kind(types, ref.key)
    return None if kind is None else kind if plain else LOOSE + kind


#: values of each kind a call input is tried with: a kind is a misfit only when every one of them is
_SAMPLES = {"number": (0,), "bool": (True,), "list": ([],), "string": ("", "now")}


def kind_misfit(rostype: str, value: Any, types: Dict[str, Set[Optional[str]]]) -> str:
    """Why a call input of ``rostype`` cannot take ``value``, a bare ``$key`` whose writers (``set`` values)
    agree on a plain kind that no value of that type is (text for a ``geometry_msgs/Point``); '' otherwise."""
    from comm.typewords import misfit_text

    if not isinstance(value, Ref) or value.path:
        return ""
    kind, plain = agreed_kind(types, value.key)
    samples = _SAMPLES.get(kind or "") if plain else None
    if not samples or (kind == "list" and kind_of_type(stands_for(rostype)) == "list"):
        return ""   # (a fixed-size list type may take another list)
    if not all(misfit_text(rostype, s) for s in samples):
        return ""
    return misfit_text(rostype, samples[0], "%s, which holds %s" % (value, KIND_WORDS[kind]))
