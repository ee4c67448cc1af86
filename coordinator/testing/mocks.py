"""Mocked modules built from definitions, and the in-process transport that runs them.

A mock refuses what the real module would refuse (unknown function, missing or
ill-typed input: the same checks as the module runtime) and a scripted output that
breaks the definition (at scripting time). Delays, hangs and events run on the
run's clock, so with a :class:`SimClock` everything is instant and deterministic.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional

from blackboard.service import BlackboardService
from blackboard.store import Store
from comm.errors import ProtocolError
from comm.messages import (
    BlackboardAnswer,
    BlackboardRequest,
    CancelRequest,
    Event,
    FunctionCall,
    FunctionResult,
)
from coordinator.clock import Clock
from coordinator.context import plain
from coordinator.transport import Transport
from modules.definition import FunctionDefinition, ModuleDefinition

__all__ = ["MockError", "Outcome", "FunctionMock", "Mocks", "InProcessTransport", "OUTCOME_KINDS",
           "succeed", "fail", "hang", "reject", "respond", "outcome_from_dict", "outcome_to_dict"]


class MockError(AssertionError):
    """A script that the real module could never follow (fails the test)."""


@dataclass
class Outcome:
    kind: str                                   # succeed | fail | hang | reject | respond
    outputs: Dict[str, Any] = field(default_factory=dict)
    reason: str = ""
    delay: float = 0.0
    fn: Optional[Callable[..., Any]] = None


def succeed(delay: float = 0.0, **outputs: Any) -> Outcome:
    """Answer ``succeeded`` with these outputs (unnamed outputs get their zero value)."""
    return Outcome("succeed", outputs=outputs, delay=delay)


def fail(reason: str = "failed (mock)", delay: float = 0.0) -> Outcome:
    return Outcome("fail", reason=reason, delay=delay)


def reject(reason: str = "rejected (mock)", delay: float = 0.0) -> Outcome:
    return Outcome("reject", reason=reason, delay=delay)


def hang() -> Outcome:
    """Never answer (until cancelled)."""
    return Outcome("hang")


def respond(fn: Callable[..., Any], delay: float = 0.0) -> Outcome:
    """Compute outputs from the inputs: ``fn(**inputs_as_plain_values) -> dict`` or an Outcome."""
    return Outcome("respond", fn=fn, delay=delay)


OUTCOME_KINDS = ("succeed", "fail", "reject", "hang")


def outcome_from_dict(raw: Any) -> Outcome:
    """``{succeed: {outputs}}``, ``{fail: reason}``, ``{reject: reason}`` or ``{hang: true}``,
    with an optional ``delay`` (seconds): the scripts of scenario files and mock nodes."""
    if not isinstance(raw, dict):
        raise MockError("an outcome is a mapping such as {succeed: {...}} or {fail: reason}, got %r" % (raw,))
    kinds = [k for k in raw if k in OUTCOME_KINDS]
    extra = [k for k in raw if k not in OUTCOME_KINDS and k != "delay"]
    if len(kinds) != 1 or extra:
        raise MockError("an outcome has one of %s (and optionally delay), got %s" % (
            ", ".join(OUTCOME_KINDS), ", ".join(map(str, raw))))
    kind = kinds[0]
    try:
        delay = float(raw.get("delay", 0.0))
    except (TypeError, ValueError):
        raise MockError("delay must be a number of seconds, got %r" % (raw.get("delay"),))
    if kind == "succeed":
        outputs = raw["succeed"] or {}
        if not isinstance(outputs, dict):
            raise MockError("succeed takes a mapping of outputs, got %r" % (outputs,))
        return succeed(delay, **dict(outputs))
    if kind == "fail":
        return fail(str(raw["fail"]), delay)
    if kind == "reject":
        return reject(str(raw["reject"]), delay)
    return hang()


def outcome_to_dict(outcome: Outcome) -> Dict[str, Any]:
    if outcome.kind == "respond":
        raise MockError("a respond(...) outcome runs Python and cannot be sent to a mock node process")
    value: Any = {"succeed": dict(outcome.outputs), "fail": outcome.reason, "reject": outcome.reason,
                  "hang": True}[outcome.kind]
    out: Dict[str, Any] = {outcome.kind: value}
    if outcome.delay:
        out["delay"] = outcome.delay
    return out


def _zero(fn: FunctionDefinition) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for p in fn.outputs:
        out[p.name] = True if p.name == "success" and p.rostype == "std_msgs/Bool" else {}
    return out


class FunctionMock:
    """The script of one ``module.function``: outcomes in order, the last one repeats."""

    def __init__(self, fn: FunctionDefinition):
        self.fn = fn
        self.outcomes: List[Outcome] = []
        self.calls: List[Dict[str, Any]] = []

    def _check(self, outcome: Outcome) -> Outcome:
        if outcome.kind == "succeed":
            outputs = dict(_zero(self.fn), **outcome.outputs)
            try:
                self.fn.build_result(outputs)
            except ProtocolError as exc:
                raise MockError("scripted outputs of %s break its definition: %s" % (self.fn.qualified, exc))
            outcome.outputs = outputs
        return outcome

    def script(self, *outcomes: Outcome) -> FunctionMock:
        """Replace the script; the last outcome repeats for further calls."""
        self.outcomes = [self._check(o) for o in outcomes]
        return self

    def then(self, *outcomes: Outcome) -> FunctionMock:
        self.outcomes.extend(self._check(o) for o in outcomes)
        return self

    def succeed(self, delay: float = 0.0, **outputs: Any) -> FunctionMock:
        return self.script(succeed(delay, **outputs))

    def fail(self, reason: str = "failed (mock)", delay: float = 0.0) -> FunctionMock:
        return self.script(fail(reason, delay))

    def hang(self) -> FunctionMock:
        return self.script(hang())

    def respond(self, fn: Callable[..., Any], delay: float = 0.0) -> FunctionMock:
        return self.script(respond(fn, delay))

    def fail_first(self, n: int, reason: str = "failed (mock)", **outputs: Any) -> FunctionMock:
        """Fail the first ``n`` calls, then succeed with ``outputs``."""
        return self.script(*([fail(reason)] * n + [succeed(**outputs)]))

    def next_outcome(self) -> Outcome:
        if not self.outcomes:
            return self._check(succeed())
        index = min(len(self.calls) - 1, len(self.outcomes) - 1)
        return self.outcomes[index]


class Mocks:
    """Every function of every module of the definitions, mocked: ``mocks["speech.say"]``."""

    def __init__(self, definitions: Mapping[str, ModuleDefinition]):
        self.definitions = dict(definitions)
        self._fns: Dict[str, FunctionMock] = {}
        self.scheduled_events: List[tuple] = []

    def __getitem__(self, target: str) -> FunctionMock:
        if target not in self._fns:
            mod, _, fname = target.partition(".")
            if mod not in self.definitions:
                raise MockError("no module %r to mock (known: %s)" % (mod, ", ".join(sorted(self.definitions))))
            try:
                fn = self.definitions[mod].function(fname)
            except ProtocolError as exc:
                raise MockError(str(exc))
            self._fns[target] = FunctionMock(fn)
        return self._fns[target]

    def event(self, at: float, target: str, **params: Any) -> None:
        """Emit ``module.event`` with ``params`` at simulated time ``at`` (seconds from start)."""
        mod, _, name = target.partition(".")
        ev = self.definitions.get(mod) and self.definitions[mod].events.get(name)
        if not ev:
            raise MockError("no event %r in the definitions" % target)
        try:
            msgs = ev.build_values(params)
        except ProtocolError as exc:
            raise MockError(str(exc))
        self.scheduled_events.append((at, Event(mod, name, [p.name for p in ev.params], msgs)))


class InProcessTransport(Transport):
    """Runs mocked modules and an in-memory Blackboard in the coordinator's process."""

    def __init__(self, mocks: Mocks, clock: Clock):
        self.mocks = mocks
        self.clock = clock
        self._deliver: Callable[[Any], None] = lambda item: None
        self._live: Dict[str, FunctionCall] = {}
        self.blackboard = BlackboardService(Store(":memory:"), self._on_answer, threaded=False)
        self.sent: List[Any] = []

    def connect(self, deliver: Callable[[Any], None]) -> None:
        self._deliver = deliver
        start = self.clock.now()
        for at, ev in self.mocks.scheduled_events:
            self.clock.call_later(max(0.0, start + at - self.clock.now()), lambda ev=ev: self._emit(ev))

    def _emit(self, ev: Event) -> None:
        self._deliver(Event.decode(ev.encode()))

    def _on_answer(self, text: str) -> None:
        self._deliver(BlackboardAnswer.decode(text))

    def _answer(self, result: FunctionResult) -> None:
        text = result.encode()
        self.blackboard.on_result(text, stamp=self.clock.now())
        self._deliver(FunctionResult.decode(text))

    def send_call(self, call: FunctionCall) -> None:
        self.sent.append(call)
        call = FunctionCall.decode(call.encode())          # what a real module would receive
        mod = self.mocks.definitions.get(call.basic_mod)
        if mod is None:
            return                                          # nobody is listening, as on a real robot
        base = dict(call_id=call.call_id, basic_mod=call.basic_mod, function=call.function)
        try:
            fn = mod.function(call.function)
            inputs = fn.inputs_of(call)
        except ProtocolError as exc:
            self._answer(FunctionResult(status="rejected", error=str(exc), **base))
            return
        mock = self.mocks["%s.%s" % (call.basic_mod, call.function)]
        plain_inputs = {k: plain(v) for k, v in inputs.items()}
        mock.calls.append(plain_inputs)
        outcome = mock.next_outcome()
        if outcome.kind == "hang":
            self._live[call.call_id or ""] = call
            return
        if outcome.kind == "respond":
            assert outcome.fn is not None
            out = outcome.fn(**plain_inputs)
            outcome = out if isinstance(out, Outcome) else mock._check(succeed(outcome.delay, **(out or {})))
        if outcome.kind == "succeed":
            result = fn.build_result(outcome.outputs, call.call_id)
        elif outcome.kind == "reject":
            result = FunctionResult(status="rejected", error=outcome.reason, **base)
        else:
            result = FunctionResult(status="failed", error=outcome.reason, **base)
        self._live[call.call_id or ""] = call
        self.clock.call_later(outcome.delay, lambda: self._finish(call, result))

    def _finish(self, call: FunctionCall, result: FunctionResult) -> None:
        if self._live.pop(call.call_id or "", None) is not None:
            self._answer(result)

    def send_cancel(self, cancel: CancelRequest) -> None:
        self.sent.append(cancel)
        call = self._live.pop(cancel.call_id, None)
        if call is not None:
            self._answer(FunctionResult(status="cancelled", error="cancelled by the coordinator",
                                        call_id=call.call_id, basic_mod=call.basic_mod, function=call.function))

    def send_request(self, request: BlackboardRequest) -> None:
        self.sent.append(request)
        self.blackboard.on_request(request.encode())
