"""What a ROS type takes, and why a value does not fit it, in the words of a tree file.

One text for one mistake, wherever it is caught: :func:`comm.rostypes.to_message` raises
:class:`ValueMisfit` with it, and the checker, scenarios, module runtimes and ``bmtree control``
all say it after their own subject (``input 'seconds' ``, ``output 'position' ``, ``weight ``)::

    takes a number (std_msgs/Float64), got 'five'
    (geometry_msgs/Point): field x takes a number (float64), got 'a'
    (geometry_msgs/Point) has no field 'xx' (did you mean 'x'?)

The walk that finds the reason runs only after a conversion failed: it never slows a valid value.
"""
from __future__ import annotations

import base64
import binascii
import math
import sys
from typing import Any, Optional, Tuple

import genpy

from comm.errors import ProtocolError, did_you_mean

__all__ = ["whole_number_text", "ValueMisfit", "misfit_text", "said_of", "type_words"]

_INT_RANGES = {"int8": (-1 << 7, (1 << 7) - 1), "uint8": (0, 255), "int16": (-1 << 15, (1 << 15) - 1),
               "uint16": (0, (1 << 16) - 1), "int32": (-1 << 31, (1 << 31) - 1), "uint32": (0, (1 << 32) - 1),
               "int64": (-1 << 63, (1 << 63) - 1), "uint64": (0, (1 << 64) - 1), "byte": (-1 << 7, (1 << 7) - 1),
               "char": (0, 255)}
_FLOAT32_MAX = 3.4028234663852886e38
_FLOAT64_MAX = sys.float_info.max
_PLAIN = frozenset(list(_INT_RANGES) + ["float32", "float64", "string", "bool", "time", "duration"])
_TIME_FIELDS = {"time": (("secs", "uint32"), ("nsecs", "uint32")),
                "duration": (("secs", "int32"), ("nsecs", "int32"))}


def _resolve(t: str) -> Optional[type]:
    from comm.rostypes import resolve_type  # here: comm.rostypes imports this module

    return resolve_type(t)


class ValueMisfit(ProtocolError):
    """A value that does not fit a ROS type; ``said`` says why after a subject (see :func:`said_of`)."""

    def __init__(self, rostype: str, said: str):
        super().__init__("value " + said)
        self.rostype = rostype
        self.said = said


def said_of(subject: str, exc: Exception) -> str:
    """``subject`` and what is wrong with its value: ``input 'seconds' takes a number (std_msgs/Float64),
    got 'five'`` for a :class:`ValueMisfit`, ``input 'seconds': <the error>`` for any other error."""
    if isinstance(exc, ValueMisfit):
        return "%s %s" % (subject, exc.said)
    return "%s: %s" % (subject, exc)


def type_words(t: str, scalar: bool = True) -> str:
    """What a ROS type (a message or a field type) takes, as a tree file writes it: ``a number``,
    ``text``, ``true or false``, ``a list``, ``a mapping of fields x, y, z``. A one-field message
    takes its field's value where a value may stand for it (``scalar``, a call's input), else a mapping."""
    if t.endswith("]"):
        return "a list"
    if t in _INT_RANGES:
        return "a whole number"
    if t in ("float32", "float64"):
        return "a number"
    if t == "string":
        return "text"
    if t == "bool":
        return "true or false"
    if t in _TIME_FIELDS:
        return "seconds, {secs, nsecs}%s" % (" or now" if t == "time" else "")
    cls = _resolve(t)
    if cls is None:
        return "a %s" % t
    if not cls.__slots__:
        return "an empty mapping"
    if scalar and len(cls.__slots__) == 1:
        return type_words(cls._slot_types[0])
    return "a mapping of fields %s" % ", ".join(cls.__slots__)


def whole_number_text(value: int) -> str:
    """A whole number said by its size, ``a negative whole number of 401 digits``: an error line, not the
    digits (``str`` of one past 4,300 digits raises ValueError in Python 3.11)."""
    digits = "%d digits" % len(str(abs(value))) if value.bit_length() < 14000 else "thousands of digits"
    return "a %swhole number of %s" % ("negative " if value < 0 else "", digits)


def _shown(value: Any) -> str:
    if isinstance(value, genpy.Message):
        return "a %s" % value._type
    if isinstance(value, bool):
        return "%s (a yes/no)" % ("true" if value else "false")   # as the tree wrote it, not Python's True
    if isinstance(value, int) and value.bit_length() > 100:  # not 400 digits
        return whole_number_text(value)
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


_Found = Tuple[str, str]  # (the field path, '' for the value itself; what is wrong there, said after it)


def _misfit(t: str, value: Any, field: str, named: str, scalar: bool, got: str = "") -> Optional[_Found]:
    """The first place where ``value`` does not fit the ROS type ``t`` (named ``named`` in the text), or
    None. ``scalar``: the value may stand for the one field of a one-field message; ``got``: the value
    itself in other words (a reference), said when the value as a whole is of the wrong kind."""

    def wrong_kind(words: str = "") -> _Found:
        return field, "takes %s (%s), got %s" % (words or type_words(t, scalar), named, got or _shown(value))

    if t.endswith("]"):
        inner, size = t[:t.rindex("[")], t[t.rindex("[") + 1:-1]
        if inner in ("uint8", "char") and isinstance(value, (bytes, bytearray)):
            return None
        if inner in ("uint8", "char") and isinstance(value, str):  # bytes as base64 text (JSON's form)
            try:
                base64.b64decode(value, validate=True)
                return None
            except (ValueError, binascii.Error):
                return wrong_kind("a list of numbers 0-255, or base64 text")
        if not isinstance(value, (list, tuple)):
            return wrong_kind()
        if size and len(value) != int(size):
            return field, "takes a list of %s items (%s), got %d" % (size, named, len(value))
        for i, item in enumerate(value):
            found = _misfit(inner, item, "%s[%d]" % (field, i), inner, False)
            if found is not None:
                return found
        return None
    if t in _INT_RANGES:   # genpy would pack true and false as 1 and 0: a mistyped flag must not drive a motor
        if not isinstance(value, int) or isinstance(value, bool):
            return wrong_kind()
        low, high = _INT_RANGES[t]
        if not low <= value <= high:
            return field, "takes a whole number from %d to %d (%s), got %s" % (low, high, named, _shown(value))
        return None
    if t in ("float32", "float64"):
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            return wrong_kind()
        # compared, never converted: math.isfinite of a whole number past a float's range overflows
        if t == "float32" and not (isinstance(value, float) and math.isinf(value)) and abs(value) > _FLOAT32_MAX:
            return field, "takes a number from -3.4e38 to 3.4e38 (%s), got %s" % (named, _shown(value))
        if isinstance(value, int) and not -_FLOAT64_MAX <= value <= _FLOAT64_MAX:
            return field, "takes a number from -1.8e308 to 1.8e308 (%s), got %s" % (named, _shown(value))
        return None
    if t == "string":
        return None if isinstance(value, str) else wrong_kind()
    if t == "bool":
        return None if isinstance(value, int) else wrong_kind()
    if t in _TIME_FIELDS:
        if isinstance(value, genpy.TVal) or (t == "time" and isinstance(value, str) and value == "now"):
            return None
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if not math.isfinite(value) or (t == "time" and value < 0):
                return field, "takes %s (%s), got %s" % ("a time from 0 seconds" if t == "time" else
                                                         "finite seconds", named, _shown(value))
            return None
        if not isinstance(value, dict):
            return wrong_kind()
        names = [k for k, _kt in _TIME_FIELDS[t]]
        for k in value:
            if k not in names:  # the converter would drop it: {sec: 5} would be time 0
                return field, "(%s) has no field %r%s" % (t, k, did_you_mean(str(k), names) or " (its fields: secs, "
                                                                                              "nsecs)")
        for k, kt in _TIME_FIELDS[t]:
            if k in value:
                found = _misfit(kt, value[k], "%s.%s" % (field, k) if field else k, kt, False)
                if found is not None:
                    return found
        return None
    cls = _resolve(t)
    if cls is None:
        return None
    if isinstance(value, genpy.Message):
        return None if value._type == t else wrong_kind()
    slots, slot_types = list(cls.__slots__), list(cls._slot_types)
    if len(slots) == 1 and not field and slot_types[0] in _PLAIN:
        # a one-field message of a number, text...: its value is its field's, said in the message's name
        if scalar and not isinstance(value, dict):
            return _misfit(slot_types[0], value, "", named, False, got)
        if scalar and slots[0] not in value and not any(did_you_mean(k, slots) for k in value):
            return _misfit(slot_types[0], value, "", named, False, got)   # {a: 1} for text: no misspelt field
        if isinstance(value, dict) and list(value) == slots:              # {data: five} says what five says
            return _misfit(slot_types[0], value[slots[0]], "", named, False, got)
    elif len(slots) == 1 and not field and scalar and not isinstance(value, dict):
        return _misfit(slot_types[0], value, slots[0], slot_types[0], False)   # a list standing for its one field
    if not isinstance(value, dict):
        return wrong_kind()
    for k, v in value.items():
        if k not in slots:
            return field, "(%s) has no field %r%s" % (t, k, did_you_mean(k, slots) or " (its fields: %s)" % (
                ", ".join(slots) or "none"))
        kt = slot_types[slots.index(k)]
        found = _misfit(kt, v, "%s.%s" % (field, k) if field else str(k), kt, False)
        if found is not None:
            return found
    return None


def misfit_text(rostype: str, value: Any, got: str = "", scalar: bool = True) -> str:
    """Why ``value`` cannot be a ``rostype`` message, said after a subject (``input 'name' ``): ``takes
    a number (std_msgs/Float64), got 'five'``, ``(geometry_msgs/Point): field x takes a number (float64),
    got 'a'``; '' when no reason is found here. ``got`` says the value itself in other words (a
    reference); ``scalar``: the value may stand for the one field of a one-field message (a call's input)."""
    found = _misfit(rostype, value, "", rostype, scalar, got)
    if found is None:
        return ""
    field, said = found
    return said if not field else "(%s): field %s %s" % (rostype, field, said)
