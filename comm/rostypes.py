"""ROS message types: resolve names, convert to and from plain data, type-check.

Conversion is rospy_message_converter's; it does not type-check values, so every
message built here goes through genpy's ``_check_types`` before anyone sees it.
"""
from __future__ import annotations

import difflib
import importlib
import io
import json
import pkgutil
import struct
from typing import Any, Dict, List, Optional

import genpy
from rospy_message_converter import message_converter

from comm.errors import ProtocolError

__all__ = [
    "resolve_type",
    "suggest_type",
    "rostype_of",
    "to_message",
    "from_message",
    "message_from_json",
    "message_to_json",
    "single_field",
    "known_types",
    "check_message",
]

_CLASS_CACHE: Dict[str, Any] = {}

# What people write when they mean a std_msgs wrapper.
_ALIASES = {
    "float": "std_msgs/Float64", "double": "std_msgs/Float64", "float64": "std_msgs/Float64",
    "float32": "std_msgs/Float32", "int": "std_msgs/Int32", "int32": "std_msgs/Int32",
    "int64": "std_msgs/Int64", "integer": "std_msgs/Int64", "str": "std_msgs/String",
    "string": "std_msgs/String", "bool": "std_msgs/Bool", "boolean": "std_msgs/Bool",
    "point": "geometry_msgs/Point", "pose": "geometry_msgs/Pose",
}


def resolve_type(name: str) -> Optional[type]:
    """The message class for ``pkg/Type``, or None if there is no such message."""
    cls = _CLASS_CACHE.get(name)
    if cls is not None:
        return cls
    if not isinstance(name, str) or name.count("/") != 1:
        return None
    pkg, typ = name.split("/")
    if not pkg.isidentifier() or not typ.isidentifier():
        return None
    try:
        module = importlib.import_module(pkg + ".msg")
    except Exception:
        return None
    cls = getattr(module, typ, None)
    if not (isinstance(cls, type) and issubclass(cls, genpy.Message)):
        return None
    _CLASS_CACHE[name] = cls
    return cls


def known_types() -> List[str]:
    """Message types of the common message packages that are importable here."""
    found: List[str] = []
    for pkg in ("std_msgs", "geometry_msgs", "sensor_msgs", "nav_msgs", "actionlib_msgs"):
        try:
            module = importlib.import_module(pkg + ".msg")
        except Exception:
            continue
        for info in pkgutil.iter_modules(getattr(module, "__path__", [])):
            if info.name.startswith("_"):
                found.append(pkg + "/" + info.name[1:])
    return sorted(found)


def suggest_type(name: str) -> Optional[str]:
    """The closest real message type to a wrong name, for 'did you mean' hints."""
    if not isinstance(name, str):
        return None
    alias = _ALIASES.get(name.strip().lower())
    if alias:
        return alias
    candidates = known_types()
    match = difflib.get_close_matches(name, candidates, n=1, cutoff=0.6)
    if match:
        return match[0]
    by_short = {c.split("/")[1].lower(): c for c in candidates}
    short = name.split("/")[-1].lower()
    match = difflib.get_close_matches(short, list(by_short), n=1, cutoff=0.7)
    return by_short[match[0]] if match else None


def unknown_type_error(name: Any) -> ProtocolError:
    hint = suggest_type(name) if isinstance(name, str) else None
    text = "unknown ROS type %r" % (name,)
    if hint:
        text += " (did you mean %r?)" % hint
    return ProtocolError(text)


def rostype_of(msg: Any) -> str:
    """``pkg/Type`` of a message instance; ProtocolError if it is not one."""
    if isinstance(msg, genpy.Message):
        return msg._type
    raise ProtocolError("%r is not a ROS message" % (type(msg).__name__,))


def single_field(cls: type) -> Optional[str]:
    """The field name of a one-field message (std_msgs/String's 'data'), else None."""
    slots = getattr(cls, "__slots__", ())
    return slots[0] if len(slots) == 1 else None


def to_message(rostype: str, value: Any, allow_scalar: bool = False) -> Any:
    """Build and type-check a message from a dict (or a scalar for one-field types).

    Raises:
        ProtocolError: unknown type, unknown field, or a value of the wrong type.
    """
    cls = resolve_type(rostype)
    if cls is None:
        raise unknown_type_error(rostype)
    if isinstance(value, cls):
        msg = value
    else:
        if not isinstance(value, dict):
            field = single_field(cls)
            if allow_scalar and field is not None:
                value = {field: value}
            else:
                raise ProtocolError("expected a mapping of fields for %s, got %s" % (rostype, _kind(value)))
        try:
            msg = message_converter.convert_dictionary_to_ros_message(rostype, value)
        except ValueError as exc:
            raise ProtocolError("%s: %s" % (rostype, exc))
        except (TypeError, AttributeError, KeyError) as exc:
            raise ProtocolError("%s: malformed value (%s)" % (rostype, exc))
    check_message(msg, rostype)
    return msg


def check_message(msg: Any, rostype: str = "") -> None:
    """Type-check by serializing, as rospy would on publish.

    genpy's ``_check_types`` alone refuses non-ASCII strings, which ROS 1 carries
    fine as UTF-8 (a Spanish-speaking robot needs them); serialization diagnoses
    wrong types through ``_check_types`` only when packing fails.
    """
    try:
        msg.serialize(io.BytesIO())
    except (genpy.SerializationError, struct.error, TypeError, ValueError, AttributeError) as exc:
        raise ProtocolError("%s: %s" % (rostype or getattr(msg, "_type", "?"), exc))


def from_message(msg: Any) -> Dict[str, Any]:
    """Plain dict of a message (the shape that travels in JSON)."""
    return message_converter.convert_ros_message_to_dictionary(msg)


def message_from_json(rostype: str, text: Any) -> Any:
    """Decode one double-encoded value; the error names the type."""
    if not isinstance(text, str):
        raise ProtocolError("is not a JSON string for %s (got %s)" % (rostype, _kind(text)))
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise ProtocolError("is not valid JSON for %s: %s" % (rostype, exc))
    try:
        return to_message(rostype, value)
    except ProtocolError as exc:
        text_ = str(exc)
        if text_.startswith("unknown ROS type"):
            raise
        raise ProtocolError("is not valid JSON for %s: %s" % (rostype, text_.split(": ", 1)[-1]))


def message_to_json(msg: Any) -> str:
    return json.dumps(from_message(msg))


def _kind(value: Any) -> str:
    return type(value).__name__
