"""Start-up check that a module class's method signatures fit its definition's input names.

The runtime calls ``method(**inputs)`` with the definition's input names, so a parameter
``obj`` where the input is ``object`` would otherwise fail on the first call, on the robot,
as a TypeError; here it is an error at start-up that names both.
"""
from __future__ import annotations

import inspect
from typing import Any, List

from modules.definition import ModuleDefinition

__all__ = ["signature_problems"]


def _not_plain(method: Any) -> str:
    """What kind of function ``method`` is when calling it does not run its body (else "")."""
    if inspect.iscoroutinefunction(method):
        return "an async def"
    if inspect.isasyncgenfunction(method):
        return "an async generator (async def with yield)"
    if inspect.isgeneratorfunction(method):
        return "a generator (it has a yield)"
    return ""


def signature_problems(definition: ModuleDefinition, impl: Any) -> List[str]:
    """One line per function whose method cannot take the function's inputs by name."""
    problems = []
    cls = type(impl).__name__
    where = definition.source or definition.name
    for fn in definition.functions.values():
        method = getattr(impl, fn.name, None)
        if method is None or not callable(method):
            continue
        kind = _not_plain(method)
        if kind:  # it would return a coroutine or a generator, never the outputs: every call would fail
            problems.append("method %s.%s is %s: the runtime calls it in a worker thread and takes what it returns "
                            "as the outputs of function %r of %s; write a plain def that returns them" % (
                                cls, fn.name, kind, fn.name, where))
            continue
        try:
            sig = inspect.signature(method)
        except (TypeError, ValueError):  # builtins and C callables: nothing to check
            continue
        params = sig.parameters.values()
        if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
            named = {p.name for p in params if p.kind is not inspect.Parameter.VAR_POSITIONAL}
            missing_inputs: List[str] = []
        else:
            named = {p.name for p in params if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD,
                                                          inspect.Parameter.KEYWORD_ONLY)}
            missing_inputs = [p.name for p in fn.inputs if p.name not in named]
        inputs = {p.name for p in fn.inputs}
        extra_params = [p.name for p in params
                        if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY,
                                      inspect.Parameter.POSITIONAL_ONLY)
                        and p.default is inspect.Parameter.empty and p.name not in inputs]
        if not missing_inputs and not extra_params:
            continue
        parts = []
        if extra_params:
            parts.append("parameter%s %s %s not an input" % ("s" if len(extra_params) > 1 else "",
                                                             ", ".join(repr(n) for n in extra_params),
                                                             "are" if len(extra_params) > 1 else "is"))
        if missing_inputs:
            parts.append("input%s %s %s no parameter" % ("s" if len(missing_inputs) > 1 else "",
                                                         ", ".join(repr(n) for n in missing_inputs),
                                                         "have" if len(missing_inputs) > 1 else "has"))
        problems.append("method %s.%s%s does not match function %r of %s (inputs: %s): %s" % (
            cls, fn.name, sig, fn.name, where, ", ".join(p.name for p in fn.inputs) or "none", "; ".join(parts)))
    return problems
