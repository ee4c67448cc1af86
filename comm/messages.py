"""Typed messages of the bmtree wire protocol (DESIGN §2), version 2.

Every topic carries ``std_msgs/String`` whose ``data`` is a JSON object; ROS values
travel double-encoded (a JSON string per value) as the original ``commBM`` wrote
them. ``decode`` checks everything and raises :class:`ProtocolError` naming the
problem; values come back as type-checked ROS message instances.
"""
from __future__ import annotations

import json
import os
import random
import re
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

from comm.errors import ProtocolError, TooLarge
from comm.limits import MAX_DEPTH, check_depth
from comm.rostypes import from_message, message_from_json, resolve_type, rostype_of, unknown_type_error
from comm.textenum import TextEnum
from comm.typewords import ValueMisfit

__all__ = [
    "DEFAULT_MAX_BYTES",
    "MIN_MAX_BYTES",
    "STATUSES",
    "CallStatus",
    "FunctionCall",
    "FunctionResult",
    "CancelRequest",
    "Event",
    "BlackboardRequest",
    "BlackboardAnswer",
    "new_id",
    "load_payload",
    "check_depth",
    "MAX_DEPTH",
]

DEFAULT_MAX_BYTES = 1 << 20
MIN_MAX_BYTES = 1024  # smaller, and even a ping's answer or a short result would be refused
_SURROGATE = re.compile(r"\\u[dD][89a-fA-F]")


class CallStatus(TextEnum):
    """The status of a call's result; a ``str`` equal to its wire text (:class:`TextEnum`)."""

    SUCCEEDED = "succeeded"
    FAILED = "failed"
    REJECTED = "rejected"
    CANCELLED = "cancelled"


STATUSES = tuple(s.value for s in CallStatus)
_STATUS = {s.value: s for s in CallStatus}


_IDS = random.Random(os.urandom(16))  # os.urandom per id gives the GIL away: 0.2 ms a call under load
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=lambda: _IDS.seed(os.urandom(16)))


def new_id() -> str:
    """A random 64-bit id as 16 hex digits (unique enough for calls and requests in flight)."""
    return "%016x" % _IDS.getrandbits(64)


def load_payload(text: Any, max_bytes: int = DEFAULT_MAX_BYTES) -> Dict[str, Any]:
    """Parse a payload into a JSON object: size limit, then depth limit, then parsing."""
    if isinstance(text, (bytes, bytearray)):
        if len(text) > max_bytes:
            raise TooLarge("payload of %d bytes exceeds the limit of %d bytes" % (len(text), max_bytes))
        try:
            text = bytes(text).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ProtocolError("payload is not UTF-8 text: %s" % exc)
    if not isinstance(text, str):
        raise ProtocolError("payload is not text (got %s)" % type(text).__name__)
    if len(text) > max_bytes or (len(text) * 4 > max_bytes and len(text.encode("utf-8")) > max_bytes):
        raise TooLarge("payload of %d bytes exceeds the limit of %d bytes" % (len(text.encode("utf-8")), max_bytes))
    check_depth(text)
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise ProtocolError("payload is not valid JSON: %s" % exc)
    if not isinstance(data, dict):
        raise ProtocolError("payload is not a JSON object (got %s)" % type(data).__name__)
    if _SURROGATE.search(text):
        _check_unicode(data)
    return data


def _check_unicode(data: Any) -> None:
    """JSON may escape lone surrogates, which no ROS string, log or SQLite row can hold."""
    try:
        json.dumps(data, ensure_ascii=False).encode("utf-8")
    except UnicodeError:
        raise ProtocolError("payload holds a lone surrogate escape (not valid Unicode text)")


def _get_str(d: Dict[str, Any], key: str, required: bool = True) -> Optional[str]:
    if key not in d or d[key] is None:
        if required:
            raise ProtocolError("missing key %r" % key)
        return None
    value = d[key]
    if not isinstance(value, str):
        raise ProtocolError("key %r must be a string, got %s" % (key, type(value).__name__))
    return value


def _get_str_list(d: Dict[str, Any], key: str, required: bool = True) -> Optional[List[str]]:
    if key not in d or d[key] is None:
        if required:
            raise ProtocolError("missing key %r" % key)
        return None
    value = d[key]
    if not isinstance(value, list):
        raise ProtocolError("key %r must be a list, got %s" % (key, type(value).__name__))
    for i, item in enumerate(value):
        if not isinstance(item, str):
            raise ProtocolError("%s[%d] must be a string, got %s" % (key, i, type(item).__name__))
    return value


def _decode_values(d: Dict[str, Any], names_required: bool, kind: str) -> Tuple[Optional[List[str]], List[Any]]:
    """The (names, msgs) of a payload, every value converted and type-checked. A value that does not
    fit its type is said as the checker says it, of the ``kind`` named (``input 'seconds' takes a
    number (std_msgs/Float64), got 'five' (msgs[0])``), or of ``msgs[0]`` in a payload without names."""
    rostypes = _get_str_list(d, "rostypes")
    raw = d.get("msgs")
    if raw is None:
        raise ProtocolError("missing key 'msgs'")
    if not isinstance(raw, list):
        raise ProtocolError("key 'msgs' must be a list, got %s" % type(raw).__name__)
    names = _get_str_list(d, "names", required=names_required)
    assert rostypes is not None
    if len(raw) != len(rostypes):
        raise ProtocolError("'msgs' has %d items but 'rostypes' has %d" % (len(raw), len(rostypes)))
    if names is not None and len(names) != len(raw):
        raise ProtocolError("'names' has %d items but 'msgs' has %d" % (len(names), len(raw)))
    msgs = []
    for i, (rostype, text) in enumerate(zip(rostypes, raw)):
        if resolve_type(rostype) is None:
            raise ProtocolError("rostypes[%d]: %s" % (i, unknown_type_error(rostype)))
        try:
            msgs.append(message_from_json(rostype, text))
        except ValueMisfit as exc:
            if names is None:
                raise ProtocolError("msgs[%d] %s" % (i, exc.said))
            raise ProtocolError("%s %r %s (msgs[%d])" % (kind, names[i], exc.said, i))
        except ProtocolError as exc:
            raise ProtocolError("msgs[%d] %s" % (i, exc))
    return names, msgs


def _encode_values(out: Dict[str, Any], names: Optional[List[str]], msgs: List[Any]) -> None:
    if names is not None:
        if len(names) != len(msgs):
            raise ProtocolError("%d names for %d values" % (len(names), len(msgs)))
        out["names"] = list(names)
    out["rostypes"] = [rostype_of(m) for m in msgs]
    out["msgs"] = [json.dumps(from_message(m)) for m in msgs]


def _dumps(obj: Dict[str, Any]) -> str:
    return json.dumps(obj, separators=(",", ":"))


class _Values:
    """Mixin for messages that carry named values."""

    names: Optional[List[str]]
    msgs: List[Any]

    @property
    def rostypes(self) -> List[str]:
        return [rostype_of(m) for m in self.msgs]

    @property
    def values(self) -> Dict[str, Any]:
        """Values by name (later duplicates win)."""
        return dict(zip(self.names or [], self.msgs))


@dataclass
class FunctionCall(_Values):
    """Coordinator → modules on ``/master/output``: invoke ``basic_mod.function``."""

    basic_mod: str
    function: str
    msgs: List[Any] = field(default_factory=list)
    names: Optional[List[str]] = None
    call_id: Optional[str] = field(default_factory=new_id)

    def encode(self) -> str:
        out: Dict[str, Any] = {"basic_mod": self.basic_mod, "function": self.function}
        _encode_values(out, self.names, self.msgs)
        if self.call_id is not None:
            out["call_id"] = self.call_id
        return _dumps(out)

    @classmethod
    def decode(cls, text: Any, max_bytes: int = DEFAULT_MAX_BYTES) -> FunctionCall:
        return cls.from_obj(load_payload(text, max_bytes))

    @classmethod
    def from_obj(cls, d: Dict[str, Any]) -> FunctionCall:
        """From an already parsed payload (a reader that looked at its keys first)."""
        basic_mod = _get_str(d, "basic_mod")
        function = _get_str(d, "function")
        call_id = _get_str(d, "call_id", required=False)
        names, msgs = _decode_values(d, names_required=False, kind="input")
        return cls(basic_mod=basic_mod, function=function, msgs=msgs, names=names, call_id=call_id)


@dataclass
class FunctionResult(_Values):
    """Module → coordinator and blackboard on ``/function/output``.

    Legacy modules send only ``names``/``rostypes``/``msgs``: such a result decodes
    with ``status='succeeded'`` and no ``call_id``, ``basic_mod`` or ``function``.
    """

    names: List[str] = field(default_factory=list)
    msgs: List[Any] = field(default_factory=list)
    call_id: Optional[str] = None
    basic_mod: Optional[str] = None
    function: Optional[str] = None
    status: CallStatus = CallStatus.SUCCEEDED
    error: str = ""
    #: The node that published it (ROS connection header ``callerid``), set by the receiver;
    #: never encoded. It identifies the module of a legacy result (DESIGN §2).
    publisher: Optional[str] = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        self.status = _STATUS.get(self.status, self.status)  # type: ignore[call-overload]

    @property
    def legacy(self) -> bool:
        return self.call_id is None

    def encode(self) -> str:
        if self.status not in _STATUS:
            raise ProtocolError("status %r is not one of %s" % (str(self.status), ", ".join(STATUSES)))
        out: Dict[str, Any] = {}
        _encode_values(out, self.names, self.msgs)
        for key in ("call_id", "basic_mod", "function"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        out["status"] = self.status
        out["error"] = self.error
        return _dumps(out)

    @classmethod
    def decode(cls, text: Any, max_bytes: int = DEFAULT_MAX_BYTES) -> FunctionResult:
        return cls.from_obj(load_payload(text, max_bytes))

    @classmethod
    def from_obj(cls, d: Dict[str, Any]) -> FunctionResult:
        """From an already parsed payload (the Blackboard keeps its raw value texts)."""
        names, msgs = _decode_values(d, names_required=True, kind="output")
        text = _get_str(d, "status", required=False) or "succeeded"
        status = _STATUS.get(text)
        if status is None:
            raise ProtocolError("status %r is not one of %s" % (text, ", ".join(STATUSES)))
        return cls(
            names=names or [],
            msgs=msgs,
            call_id=_get_str(d, "call_id", required=False),
            basic_mod=_get_str(d, "basic_mod", required=False),
            function=_get_str(d, "function", required=False),
            status=status,
            error=_get_str(d, "error", required=False) or "",
        )


@dataclass
class CancelRequest:
    """Coordinator → modules on ``/master/cancel``: stop the running call ``call_id``."""

    call_id: str
    basic_mod: str
    function: str

    def encode(self) -> str:
        return _dumps({"call_id": self.call_id, "basic_mod": self.basic_mod, "function": self.function})

    @classmethod
    def decode(cls, text: Any, max_bytes: int = DEFAULT_MAX_BYTES) -> CancelRequest:
        d = load_payload(text, max_bytes)
        return cls(call_id=_get_str(d, "call_id"), basic_mod=_get_str(d, "basic_mod"),
                   function=_get_str(d, "function"))


@dataclass
class Event(_Values):
    """Module → coordinator on ``/event/output``: something happened (``lostPerson``)."""

    basic_mod: str
    event: str
    names: List[str] = field(default_factory=list)
    msgs: List[Any] = field(default_factory=list)
    #: The node that published it (ROS connection header ``callerid``), set by the receiver; never encoded.
    publisher: Optional[str] = field(default=None, compare=False, repr=False)

    def encode(self) -> str:
        out: Dict[str, Any] = {"basic_mod": self.basic_mod, "event": self.event}
        _encode_values(out, self.names, self.msgs)
        return _dumps(out)

    @classmethod
    def decode(cls, text: Any, max_bytes: int = DEFAULT_MAX_BYTES) -> Event:
        d = load_payload(text, max_bytes)
        basic_mod = _get_str(d, "basic_mod")
        event = _get_str(d, "event")
        names, msgs = _decode_values(d, names_required=True, kind="event param")
        return cls(basic_mod=basic_mod, event=event, names=names or [], msgs=msgs)


@dataclass
class BlackboardRequest:
    """Coordinator → blackboard on ``/blackboard/input``.

    ``var_names`` holds plain names (``success``) or qualified ones
    (``module/function/name``). ``history`` asks for the last N values of each
    name; ``call_id`` asks for everything one call produced (``var_names`` may
    then be empty). ``after`` lists calls whose results the answer must include: the
    Blackboard answers once they are committed (or after a bounded wait).
    """

    var_names: List[str] = field(default_factory=list)
    request_id: Optional[str] = field(default_factory=new_id)
    history: int = 1
    call_id: Optional[str] = None
    after: List[str] = field(default_factory=list)

    def encode(self) -> str:
        out: Dict[str, Any] = {"var_names": list(self.var_names)}
        if self.request_id is not None:
            out["request_id"] = self.request_id
        if self.history != 1:
            out["history"] = self.history
        if self.call_id is not None:
            out["call_id"] = self.call_id
        if self.after:
            out["after"] = list(self.after)
        return _dumps(out)

    @classmethod
    def decode(cls, text: Any, max_bytes: int = DEFAULT_MAX_BYTES) -> BlackboardRequest:
        d = load_payload(text, max_bytes)
        call_id = _get_str(d, "call_id", required=False)
        names = _get_str_list(d, "var_names", required=call_id is None) or []
        history = d.get("history", 1)
        if isinstance(history, bool) or not isinstance(history, int) or not 1 <= history <= 1000000:
            raise ProtocolError("key 'history' must be an integer from 1 to 1000000, got %.40r" % (history,))
        after = _get_str_list(d, "after", required=False) or []
        if len(after) > 10000:
            raise ProtocolError("key 'after' lists %d calls (at most 10000)" % len(after))
        return cls(var_names=names, request_id=_get_str(d, "request_id", required=False),
                   history=history, call_id=call_id, after=after)


@dataclass
class BlackboardAnswer(_Values):
    """Blackboard → coordinator on ``/blackboard/output``.

    Values are listed as in a result (``names``/``rostypes``/``msgs``), newest
    first when a history was asked for; ``sources`` says, per value, which
    module, function and call produced it and when (``stamp``, seconds). ``unstored`` lists
    the calls of the request's ``after`` whose results the Blackboard still had not stored when
    it answered (a Blackboard restarted or disconnected while they ran): values they would have
    written are older ones. Only sent when not empty.
    """

    names: List[str] = field(default_factory=list)
    msgs: List[Any] = field(default_factory=list)
    request_id: Optional[str] = None
    missing: List[str] = field(default_factory=list)
    error: str = ""
    sources: List[Dict[str, Any]] = field(default_factory=list)
    unstored: List[str] = field(default_factory=list)

    def encode(self) -> str:
        return self.encode_raw(self.names, self.rostypes, [json.dumps(from_message(m)) for m in self.msgs],
                               self.request_id, self.missing, self.error, self.sources, self.unstored)

    @staticmethod
    def encode_raw(names: List[str], rostypes: List[str], texts: List[str], request_id: Optional[str],
                   missing: List[str], error: str = "", sources: Optional[List[Dict[str, Any]]] = None,
                   unstored: Optional[List[str]] = None) -> str:
        """The answer from values already encoded as JSON (the Blackboard stores them so)."""
        out = {"names": list(names), "rostypes": list(rostypes), "msgs": list(texts),
               "request_id": request_id, "missing": list(missing), "error": error, "sources": list(sources or [])}
        if unstored:
            out["unstored"] = list(unstored)
        return _dumps(out)

    @classmethod
    def decode(cls, text: Any, max_bytes: int = DEFAULT_MAX_BYTES) -> BlackboardAnswer:
        d = load_payload(text, max_bytes)
        names, msgs = _decode_values(d, names_required=True, kind="key")
        sources = d.get("sources") or []
        if not isinstance(sources, list) or not all(isinstance(s, dict) for s in sources):
            raise ProtocolError("key 'sources' must be a list of objects")
        return cls(names=names or [], msgs=msgs, request_id=_get_str(d, "request_id", required=False),
                   missing=_get_str_list(d, "missing", required=False) or [],
                   error=_get_str(d, "error", required=False) or "", sources=sources,
                   unstored=_get_str_list(d, "unstored", required=False) or [])
