"""The C++ protocol's naming, and what a node built with bmtree's C++ library says it provides.

A value of type ``pkg/Type`` of module ``BM`` travels on the data topic ``/BM/type`` (the
original naming, manual §4.3). The library's latched ``/BM/BM_info`` lists its functions and,
per function, the topics of its inputs and the names and topics of its outputs: the bridge
compares them with the definition before it serves anything. Its events come whole, one message
each, on ``/BM/BM_event`` (:func:`cpp_event` reads and checks one).
"""
from __future__ import annotations

import base64
import binascii
import json
from typing import Any, Dict, List, Tuple

from comm.errors import ProtocolError, did_you_mean
from modules.definition import DefinitionError, FunctionDefinition, ModuleDefinition

__all__ = ["cpp_event", "data_topic", "data_topics", "event_topic", "signature_problem", "signature_problems"]


def event_topic(module: str) -> str:
    """``/<module>/BM_event``: where a node built with bmtree's C++ library (API 3) sends its events."""
    return "/%s/BM_event" % module


def data_topic(module: str, rostype: str) -> str:
    """``std_msgs/Float64`` in module ``gripper`` -> ``/gripper/float64`` (the original naming)."""
    return "/%s/%s" % (module, rostype.rsplit("/", 1)[-1].lower())


def data_topics(definition: ModuleDefinition) -> Tuple[Dict[str, str], Dict[str, str]]:
    """(input topics, output topics) of a module, each ``topic -> ROS type``.

    Raises:
        DefinitionError: two types of the module would share one data topic.
    """
    ins: Dict[str, str] = {}
    outs: Dict[str, str] = {}
    problems = []
    every: Dict[str, str] = {}
    for fn in definition.functions.values():
        for kind, params, table in (("Input", fn.inputs, ins), ("Output", fn.outputs, outs)):
            for p in params:
                topic = data_topic(definition.name, p.rostype)
                other = every.setdefault(topic, p.rostype)
                if other != p.rostype:
                    problems.append("%s: %s.%s-params: %s: types %s and %s would share the data topic %s of the "
                                    "C++ protocol" % (definition.source, fn.name, kind, p.name, other, p.rostype,
                                                      topic))
                table[topic] = p.rostype
    if problems:
        raise DefinitionError(sorted(set(problems)))
    return ins, outs


def signature_problem(fn: FunctionDefinition, module: str, info: Dict[str, Any], node: str) -> str:
    """Every way function ``fn`` differs from what the C++ node says, in one text ("" if none)."""
    return "; ".join(signature_problems(fn, module, info, node))


def signature_problems(fn: FunctionDefinition, module: str, info: Dict[str, Any], node: str) -> List[str]:
    """How function ``fn`` of the C++ node ``node`` (per its BM_info ``info``) differs from the
    definition of module ``module``: one text for its inputs, one for its outputs, or none (a node
    of an older library lists no signatures: then only the names are compared)."""
    sig = (info.get("signatures") or {}).get(fn.name) if isinstance(info.get("signatures"), dict) else None
    provided = [f for f in info.get("functions") or [] if isinstance(f, str)]
    if fn.name not in provided:
        return ["function %r is not provided by the C++ node %s (it provides %s): add provide(\"%s\", ...) to "
                "its constructor, or remove the function from the definition" % (
                    fn.name, node, ", ".join(sorted(provided)) or "none", fn.name)]
    if not isinstance(sig, dict):  # a library of before the signatures: nothing more to compare
        return []
    problems = []
    want_in = [data_topic(module, p.rostype) for p in fn.inputs]
    if sig.get("inparam_topics") != want_in:
        problems.append("function %r takes its inputs on %s in the C++ node %s, but the definition's Input-params "
                        "(%s) are sent on %s: the method's parameters must be the definition's inputs, in order" % (
                            fn.name, json.dumps(sig.get("inparam_topics")), node,
                            ", ".join("%s: %s" % (p.name, p.rostype) for p in fn.inputs) or "none",
                            json.dumps(want_in)))
    names, topics = sig.get("outparam_names"), sig.get("outparam_topics")
    got: Dict[str, Any] = {}
    if isinstance(names, list) and isinstance(topics, list) and all(isinstance(x, str) for x in names + topics):
        got = dict(zip(names, topics))
    want_out = {p.name: data_topic(module, p.rostype) for p in fn.outputs}
    if got != want_out:
        problems.append("function %r returns %s in the C++ node %s, but the definition's Output-params are %s%s: "
                        "the output names given to provide() and the tuple's types must match them" % (
                            fn.name, ", ".join("%s on %s" % kv for kv in sorted(got.items())) or "nothing", node,
                            ", ".join("%s on %s" % kv for kv in sorted(want_out.items())) or "none",
                            _output_differences(got, want_out)))
    return problems


def _output_differences(got: Dict[str, Any], want: Dict[str, str]) -> str:
    """" (only in the C++ node: dist; only in the definition: distance; count on /arm/int32 there, /arm/int64 in the
    definition)": each difference of the outputs, named."""
    parts = []
    extra = sorted(set(got) - set(want))
    lacking = sorted(set(want) - set(got))
    if extra:
        parts.append("only in the C++ node: %s" % ", ".join(extra))
    if lacking:
        parts.append("only in the definition: %s" % ", ".join(lacking))
    parts.extend("%s on %s there, %s in the definition" % (n, got[n], want[n])
                 for n in sorted(set(got) & set(want)) if got[n] != want[n])
    return " (%s)" % "; ".join(parts) if parts else ""


def cpp_event(payload: Dict[str, Any], definition: ModuleDefinition) -> Tuple[str, Dict[str, Any]]:
    """The event and its params (ROS messages by name) of a ``BM_event`` payload, checked against the
    definition's Events: ``{"event": name, "params": [{"name", "type", "md5sum", "data"}, ...]}``, where
    ``data`` is the param's ROS serialization (base64) made by ``ros::serialization`` in the C++ node.

    Raises:
        ProtocolError: every problem of the payload in one text (an unknown event or param, a param
            missing, given twice, of another type or of another definition of its type, bytes that
            are not that type's).
    """
    event = payload.get("event")
    if not isinstance(event, str) or not event:
        raise ProtocolError("key 'event' must be an event's name, got %.60r" % (event,))
    ev = definition.events.get(event)
    if ev is None:
        hint = did_you_mean(event, definition.events) or (
            " (its events: %s)" % ", ".join(definition.events) if definition.events else " (it has no events)")
        raise ProtocolError("module %r has no event %r%s: add it to the definition's Events, or emit one of "
                            "those" % (definition.name, event, hint))
    raw = payload.get("params", [])
    if not isinstance(raw, list):
        raise ProtocolError("event %r: key 'params' must be a list, got %s" % (event, type(raw).__name__))
    wanted = {p.name: p for p in ev.params}
    params: Dict[str, Any] = {}
    problems: List[str] = []
    for i, item in enumerate(raw):
        fields = item if isinstance(item, dict) else {}
        name, rostype, md5sum, data = (fields.get(k) for k in ("name", "type", "md5sum", "data"))
        if not all(isinstance(v, str) for v in (name, rostype, md5sum, data)):
            problems.append("params[%d] is not {\"name\", \"type\", \"md5sum\", \"data\"} (strings)" % i)
            continue
        if name not in wanted:
            problems.append("unknown param %r%s" % (name, did_you_mean(name, wanted)))
            continue
        if name in params:
            problems.append("param %r is given twice" % name)
            continue
        p = wanted[name]
        if rostype != p.rostype:
            problems.append("param %r is a %s in the C++ node, but the definition's Event-params say %s" % (
                name, rostype, p.rostype))
            continue
        cls = p.msg_class
        if md5sum != getattr(cls, "_md5sum", md5sum):
            problems.append("param %r: the C++ node was built with another definition of %s (md5sum %s there, %s "
                            "here): rebuild it against the same message package" % (
                                name, rostype, md5sum[:40], getattr(cls, "_md5sum", "?")))
            continue
        try:
            raw_bytes = base64.b64decode(data.encode("ascii"), validate=True)
        except (ValueError, binascii.Error, UnicodeEncodeError) as exc:
            problems.append("param %r: 'data' is not base64 (%s)" % (name, exc))
            continue
        try:
            msg = cls()
            msg.deserialize(raw_bytes)
        except Exception as exc:  # genpy.DeserializationError, struct.error, UnicodeDecodeError, ...
            problems.append("param %r: its %d bytes are not a serialized %s (%s)" % (
                name, len(raw_bytes), rostype, exc))
            continue
        params[name] = msg
    missing = [n for n in wanted if n not in params and not any(
        isinstance(x, dict) and x.get("name") == n for x in raw)]
    if missing:
        problems.append("missing param %s" % ", ".join(repr(m) for m in missing))
    if problems:
        raise ProtocolError("event %r: %s" % (event, "; ".join(problems)))
    return event, params
