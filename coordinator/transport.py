"""How the coordinator reaches modules: an interface, so the engine runs with or without ROS.

A transport sends calls, cancels and Blackboard requests, and hands every decoded
incoming message (FunctionResult, Event, BlackboardAnswer) to ``deliver``, from any
thread; the runner queues them and handles them in its ticking thread. What arrives is
checked first by a :class:`Screen` (one for every transport): malformed answers fail the
call they answer, events that break their definition are refused, both said.
"""
from __future__ import annotations

import abc
import contextlib
import logging
import threading
import typing
from collections import OrderedDict
from typing import Any, Callable, ContextManager, Dict, Iterable, List, Mapping, Optional, Tuple

from comm.errors import ProtocolError, did_you_mean
from comm.messages import (
    DEFAULT_MAX_BYTES,
    BlackboardRequest,
    CallStatus,
    CancelRequest,
    Event,
    FunctionCall,
    FunctionResult,
    load_payload,
)
from comm.rostypes import rostype_of
from comm.saylimit import SayLimit
from coordinator.runevents import Notice
from modules.definition import ModuleDefinition
from modules.errortext import salvage_keys

__all__ = ["Transport", "NullTransport", "Screen", "event_problem", "salvaged", "MALFORMED_ANSWER",
           "REFUSED_EVENT"]

log = logging.getLogger("bmtree.coordinator")


class Transport(abc.ABC):
    @abc.abstractmethod
    def connect(self, deliver: Callable[[Any], None]) -> None:
        """Start receiving; ``deliver`` gets decoded messages."""

    @abc.abstractmethod
    def send_call(self, call: FunctionCall) -> None:
        """Publish a call."""

    @abc.abstractmethod
    def send_cancel(self, cancel: CancelRequest) -> None:
        """Publish a cancel."""

    @abc.abstractmethod
    def send_request(self, request: BlackboardRequest) -> None:
        """Ask the Blackboard node."""

    def hold(self) -> ContextManager[Any]:
        """Sends made inside may wait and leave together at its end (the runner holds each
        tick: the calls a tick makes to one module then cost it one write and one wake-up)."""
        return contextlib.nullcontext()

    def wait_ready(self, modules: Iterable[str], timeout: float) -> None:  # noqa: B027 - optional, no-op default
        """Block until the named modules can be called (raise EnvironmentProblem if not)."""

    def watch_module(self, module: str) -> Optional[str]:
        """Watch ``module``'s node as a call in flight's is watched (a ``wait_event`` waits for one of its
        events): a key, which a ``ModuleLost`` delivered for the module carries as a call id once the node
        is gone; None when this transport has no nodes to lose (in process: mocks do not die)."""
        return None

    def unwatch_module(self, key: str) -> None:  # noqa: B027 - optional, no-op default
        """The wait that :meth:`watch_module` gave ``key`` for has ended."""

    def unsent_note(self, call_id: str) -> str:
        """Why the call ``call_id`` has not been sent yet (its module's node is not connected: gone, restarting),
        for the reason of a call that timed out so; '' when it was sent (or this transport cannot tell)."""
        return ""

    def close(self) -> None:  # noqa: B027 - optional, no-op default
        """Stop receiving and release resources."""


class NullTransport(Transport):
    """For trees built only to be checked or rendered: sending anything is a bug."""

    def connect(self, deliver: Callable[[Any], None]) -> None:
        raise RuntimeError("this tree was built offline (check/render) and cannot run")

    def send_call(self, call: FunctionCall) -> None:
        raise RuntimeError("this tree was built offline (check/render) and cannot run")

    def send_cancel(self, cancel: CancelRequest) -> None:
        raise RuntimeError("this tree was built offline (check/render) and cannot run")

    def send_request(self, request: BlackboardRequest) -> None:
        raise RuntimeError("this tree was built offline (check/render) and cannot run")


MALFORMED_ANSWER = "malformed_answer"
"""The ``what`` of the notice of a malformed answer to a call the run awaits (the call fails with it)."""
REFUSED_EVENT = "refused_event"
"""The ``what`` of the notice of an event of a module of the run that breaks its definition (refused)."""
_MAX_WHY = 1000   # characters of a refusal's reason kept in an answer's error and a notice


def _cut(text: str) -> str:
    return text if len(text) <= _MAX_WHY else text[:_MAX_WHY] + "..."


def _why(exc: BaseException) -> str:
    return _cut(str(exc) if isinstance(exc, ProtocolError) else "%s: %s" % (type(exc).__name__, exc))


def _sender(node: Optional[str], module: Optional[str]) -> str:
    """Who sent a message: ``node /bm_probe (module probe)``, or the module in process."""
    if node:
        return "node %s%s" % (node, " (module %s)" % module if module else "")
    return "module %s" % module if module else "an unknown sender"


def salvaged(text: Any, max_bytes: int) -> Dict[str, str]:
    """The plain text keys (``call_id``, ``basic_mod``, ``function``, ``event``) of a payload that did not
    decode: read from its JSON object when it parses, else from its text (broken JSON, too deep, too big)."""
    try:
        d = load_payload(text, max_bytes)
    except ProtocolError:
        return salvage_keys(text)
    except Exception:  # whatever the text is, nothing is recovered from it
        return {}
    return {k: d[k] for k in ("call_id", "basic_mod", "function", "event") if isinstance(d.get(k), str)}


def event_problem(event: Event, definitions: Mapping[str, ModuleDefinition]) -> str:
    """Why ``event`` breaks its module's definition ('' when it does not, or its module is not known)."""
    module = definitions.get(event.basic_mod)
    if module is None:
        return ""
    ev_def = module.events.get(event.event)
    if ev_def is None:
        return "module %s has no event %r%s" % (module.name, event.event, did_you_mean(event.event, module.events)
                                                or " (events: %s)" % (", ".join(module.events) or "none"))
    params = {p.name: p for p in ev_def.params}
    problems, seen = [], set()
    for name, msg in zip(event.names, event.msgs):
        p = params.get(name)
        if name in seen:
            problems.append("param %r given twice" % name)
        elif p is None:
            problems.append("unknown param %r%s" % (name, did_you_mean(name, params)))
        elif rostype_of(msg) != p.rostype:
            problems.append("param %r is %s, the definition says %s" % (name, rostype_of(msg), p.rostype))
        seen.add(name)
    missing = [p.name for p in ev_def.params if p.name not in seen]
    if missing:
        problems.append("missing param %s" % ", ".join(repr(m) for m in missing))
    return "; ".join(problems)


class Screen:
    """What arrives at the coordinator, checked at the boundary (both transports use one): results against
    the definition of the call they answer, events against their module's definition.

    A malformed answer (broken JSON, a field of the wrong type, outputs its function's definition does not
    have) to a call the run awaits (sent, not cancelled, not answered) becomes a ``failed`` answer to that
    call saying what was wrong and who sent it, with a ``malformed_answer`` notice: the call fails at once
    instead of waiting out its timeout (for ever with ``timeout: none``). One whose call cannot be told is
    said in a rate-limited warning. An event that does not decode or breaks its module's definition is
    refused (a ``wait_event`` goes on waiting for a good one), said in a rate-limited warning and, for a
    module of the run, a ``refused_event`` notice. Nothing here raises."""

    def __init__(self, definitions: Optional[Mapping[str, ModuleDefinition]] = None,
                 refusals: Optional[SayLimit] = None):
        self.definitions: Dict[str, ModuleDefinition] = dict(definitions or {})
        self.refusals = refusals or SayLimit()
        self._awaited: typing.OrderedDict[str, Tuple[str, str]] = OrderedDict()  # call_id -> (module, function)
        self._lock = threading.Lock()

    def know(self, definitions: Mapping[str, ModuleDefinition], replace: bool = True) -> None:
        """The definitions the run's modules follow (``replace=False``: only for modules not known yet)."""
        for name, definition in list(definitions.items()):
            if replace or name not in self.definitions:
                self.definitions[name] = definition

    def sent(self, call: FunctionCall) -> None:
        """A call went out: its answer is awaited."""
        if call.call_id:
            with self._lock:
                self._awaited[call.call_id] = (call.basic_mod, call.function)
                while len(self._awaited) > 100000:  # answers that never came (nor a cancel): the oldest go
                    self._awaited.popitem(last=False)

    def ended(self, call_ids: Iterable[Optional[str]]) -> None:
        """Calls the run no longer awaits (cancelled, given up as lost)."""
        with self._lock:
            for call_id in call_ids:
                self._awaited.pop(call_id or "", None)

    def result(self, text: Any, max_bytes: int = DEFAULT_MAX_BYTES, node: Optional[str] = None) -> List[Any]:
        """What to deliver of a ``/function/output`` payload from ``node``: the result (its ``publisher``
        set), or a failed answer and a notice for a malformed answer to an awaited call, or nothing."""
        try:
            result = FunctionResult.decode(text, max_bytes)
        except Exception as exc:  # nothing a sender writes may stop a subscriber
            return self._malformed(salvaged(text, max_bytes).get("call_id"), node, _why(exc))
        result.publisher = node
        with self._lock:
            call = self._awaited.get(result.call_id or "")
        if call is None:  # not a call of this run awaited now: the run correlates it (late, legacy, other runs')
            return [result]
        why = self._breaks(result, *call)
        if why:
            return self._malformed(result.call_id, node, why)
        self.ended([result.call_id])
        return [result]

    def _breaks(self, result: FunctionResult, module: str, function: str) -> str:
        """Why ``result`` cannot answer the call to ``module.function`` ('' when it can)."""
        if result.basic_mod not in (None, module) or result.function not in (None, function):
            return "it answers %s.%s, not %s.%s" % (result.basic_mod, result.function, module, function)
        definition = self.definitions.get(module)
        fn = definition.functions.get(function) if definition is not None else None
        if fn is None:
            return ""
        try:
            fn.check_result(result)
        except ProtocolError as exc:
            return "outputs that break its definition: %s" % _cut(str(exc))
        return ""

    def _malformed(self, call_id: Optional[str], node: Optional[str], why: str) -> List[Any]:
        with self._lock:
            call = self._awaited.pop(call_id, None) if call_id else None
        if call is None:
            more = self.refusals.due(("result", node))
            if more is not None:
                log.warning("ignored a malformed answer%s from %s: %s%s", " (call %s, not one this run awaits)"
                            % call_id if call_id else "", _sender(node, None), why, more)
            return []
        module, function = call
        error = "malformed answer from %s: %s" % (_sender(node, module), why)
        text = "%s.%s (call %s): %s; the call fails" % (module, function, call_id, error)
        log.warning("%s", text)
        return [Notice(MALFORMED_ANSWER, text, call_id or ""),
                FunctionResult(call_id=call_id, basic_mod=module, function=function, status=CallStatus.FAILED,
                               error=error, publisher=node)]

    def event(self, text: Any, max_bytes: int = DEFAULT_MAX_BYTES, node: Optional[str] = None) -> List[Any]:
        """What to deliver of an ``/event/output`` payload from ``node``: the event, or a notice of its
        refusal, or nothing."""
        try:
            event = Event.decode(text, max_bytes)
        except Exception as exc:  # nothing a sender writes may stop a subscriber
            keys = salvaged(text, max_bytes)
            return self._refused(keys.get("basic_mod"), keys.get("event"), node, _why(exc))
        event.publisher = node
        return self.take_event(event)

    def take_event(self, event: Event) -> List[Any]:
        """``event`` (decoded) checked against its module's definition: itself, or a notice of its refusal."""
        try:
            why = event_problem(event, self.definitions)
        except Exception as exc:  # an odd value must not stop a subscriber
            why = _why(exc)
        if why:
            return self._refused(event.basic_mod, event.event, event.publisher, "it breaks the definition: " + why)
        return [event]

    def _refused(self, module: Optional[str], name: Optional[str], node: Optional[str], why: str) -> List[Any]:
        more = self.refusals.due(("event", module, name, node))
        if more is None:
            return []
        what = "%s.%s" % (module, name) if module and name else "%s event" % module if module else "an event"
        text = "refused %s from %s: %s%s" % (what, _sender(node, None if node else module), why, more)
        log.warning("%s", text)
        return [Notice(REFUSED_EVENT, text)] if module in self.definitions else []
