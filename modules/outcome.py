"""What a function does with a call, as data: the one outcome type of mocks, mock nodes and sim faults.

A module's method may return an :class:`Outcome` instead of its outputs (and the
``before_call`` hook may return one instead of running the method); the runtime
(:class:`modules.runtime.ModuleServer`) carries it out the same way on worker threads
and on a simulated clock: wait ``delay`` seconds of the module's clock, then answer
``succeeded`` with ``outputs``, ``failed`` or ``rejected`` with ``reason``, never answer
(``hang``, until cancelled), or ``respond``: compute the answer with ``fn``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Optional

from comm.errors import did_you_mean
from comm.textenum import TextEnum
from comm.typewords import whole_number_text

__all__ = ["Outcome", "OutcomeKind", "OutcomeError", "succeed", "fail", "reject", "hang", "die", "respond",
           "outcome_from_dict", "outcome_to_dict"]


class OutcomeKind(TextEnum):
    SUCCEED = "succeed"
    FAIL = "fail"
    REJECT = "reject"
    HANG = "hang"
    RESPOND = "respond"
    DIE = "die"


class OutcomeError(ValueError):
    """An outcome written wrongly (in a scenario, a mock node's script or a world's faults)."""


@dataclass
class Outcome:
    """``kind`` after ``delay`` seconds; ``outputs`` for succeed, ``reason`` for fail and reject.

    ``fn`` for respond: called with the call's inputs (as the method gets them), it returns
    the outputs or another Outcome; without ``fn``, the module's own method answers (a fault
    that only delays).

    ``ignores_cancel``: a cancel does not end the delay (an original module behind the bridge,
    or a function that never looks at its cancel): the call is answered ``cancelled`` after the
    runtime's grace, and the module stays busy until the delay is over.
    """

    kind: OutcomeKind
    outputs: Dict[str, Any] = field(default_factory=dict)
    reason: str = ""
    delay: float = 0.0
    fn: Optional[Callable[..., Any]] = None
    ignores_cancel: bool = False

    def __post_init__(self) -> None:
        self.kind = OutcomeKind(self.kind)


def succeed(delay: float = 0.0, **outputs: Any) -> Outcome:
    """Answer ``succeeded`` with these outputs."""
    return Outcome(OutcomeKind.SUCCEED, outputs=outputs, delay=delay)


def fail(reason: str = "failed (mock)", delay: float = 0.0) -> Outcome:
    """Answer ``failed`` with ``reason``."""
    return Outcome(OutcomeKind.FAIL, reason=reason, delay=delay)


def reject(reason: str = "rejected (mock)", delay: float = 0.0) -> Outcome:
    """Answer ``rejected`` with ``reason`` (the call could not be taken now)."""
    return Outcome(OutcomeKind.REJECT, reason=reason, delay=delay)


def hang() -> Outcome:
    """Never answer (until cancelled)."""
    return Outcome(OutcomeKind.HANG)


def die(reason: str = "its process died (mock)", delay: float = 0.0) -> Outcome:
    """The module's node dies during the call, after ``delay``: this call and every other one it has
    in flight end ``module_lost`` (``module gripper lost: REASON``). A mock tells the run at once; a
    node (a world's fault) kills its own process, and the run's watchdog finds it gone."""
    return Outcome(OutcomeKind.DIE, reason=reason, delay=delay)


def respond(fn: Callable[..., Any], delay: float = 0.0) -> Outcome:
    """After ``delay``, answer what ``fn(**inputs)`` gives: outputs, or an Outcome."""
    return Outcome(OutcomeKind.RESPOND, fn=fn, delay=delay)


_WRITTEN = ("succeed", "fail", "reject", "hang", "die")
_OPTIONS = ("delay", "ignores_cancel")
#: The longest delay an outcome may have: a timer thread waits it out.
MAX_DELAY = 86400


def outcome_from_dict(raw: Any) -> Outcome:
    """``{succeed: {outputs}}``, ``{fail: reason}``, ``{reject: reason}``, ``{hang: true}`` or ``{die: reason}``,
    with an optional ``delay`` (seconds): the written form of scenarios, mock nodes and faults."""
    if not isinstance(raw, dict):
        raise OutcomeError("an outcome is a mapping such as {succeed: {...}} or {fail: reason}, got %r" % (raw,))
    kinds = [k for k in raw if k in _WRITTEN]
    extra = [k for k in raw if k not in _WRITTEN and k not in _OPTIONS]
    if len(kinds) != 1 or extra:
        hints = ["%r is no key of an outcome%s" % (k, did_you_mean(k, _WRITTEN + _OPTIONS)) for k in extra]
        raise OutcomeError("an outcome has one of %s (and optionally delay, ignores_cancel), got %s%s" % (
            ", ".join(_WRITTEN), ", ".join(map(str, raw)), ": " + "; ".join(hints) if hints else ""))
    kind = kinds[0]
    written = raw.get("delay", 0.0)
    try:
        delay = float(written) if not isinstance(written, bool) else float("nan")
    except (TypeError, ValueError, OverflowError):   # OverflowError: a whole number past 1.8e308
        delay = float("nan")
    if not 0 <= delay <= MAX_DELAY:  # NaN fails it; 1e300 s would end the timer thread that waits it out
        shown = whole_number_text(written) if isinstance(written, int) and written.bit_length() > 100 else \
            repr(written) if len(repr(written)) <= 40 else "a %s of %d characters" % (type(written).__name__,
                                                                                     len(repr(written)))
        raise OutcomeError("delay must be a number of seconds from 0 to %d (a day), got %s" % (MAX_DELAY, shown))
    ignores = raw.get("ignores_cancel", False)
    if not isinstance(ignores, bool):
        raise OutcomeError("ignores_cancel is true or false, got %r" % (ignores,))
    if kind == "succeed":
        outputs = raw["succeed"] or {}
        if not isinstance(outputs, dict):
            raise OutcomeError("succeed takes a mapping of outputs, got %r" % (outputs,))
        out = succeed(delay, **{str(k): v for k, v in outputs.items()})
    elif kind == "fail":
        out = fail(str(raw["fail"]), delay)
    elif kind == "reject":
        out = reject(str(raw["reject"]), delay)
    elif kind == "die":
        given = raw["die"]
        out = die(str(given), delay) if given not in (True, None, "") else die(delay=delay)
    else:
        out = hang()
    out.ignores_cancel = ignores
    return out


def outcome_to_dict(outcome: Outcome) -> Dict[str, Any]:
    """The written form of ``outcome`` (respond runs Python and has none)."""
    kind = outcome.kind
    if kind == OutcomeKind.RESPOND:
        raise OutcomeError("a respond(...) outcome runs Python and cannot be written down")
    value: Any = {OutcomeKind.SUCCEED: dict(outcome.outputs), OutcomeKind.FAIL: outcome.reason,
                  OutcomeKind.REJECT: outcome.reason, OutcomeKind.HANG: True, OutcomeKind.DIE: outcome.reason}[kind]
    out: Dict[str, Any] = {kind.value: value}
    if outcome.delay:
        out["delay"] = outcome.delay
    if outcome.ignores_cancel:
        out["ignores_cancel"] = True
    return out
