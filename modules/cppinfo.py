"""The C++ protocol's naming, and what a node built with bmtree's C++ library says it provides.

A value of type ``pkg/Type`` of module ``BM`` travels on the data topic ``/BM/type`` (the
original naming, manual §4.3). The library's latched ``/BM/BM_info`` lists its functions and,
per function, the topics of its inputs and the names and topics of its outputs: the bridge
compares them with the definition before it serves anything.
"""
from __future__ import annotations

import json
from typing import Any, Dict, List, Tuple

from modules.definition import DefinitionError, FunctionDefinition, ModuleDefinition

__all__ = ["data_topic", "data_topics", "signature_problem", "signature_problems"]


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
