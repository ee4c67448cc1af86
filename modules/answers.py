"""The answers of a module's calls (:class:`modules.runtime.ModuleServer`): what the author's code
returned or raised turned into a result that fits the definition and the wire's size limit, with what
is wrong said once in the module's log (the author's bug, matched to the call in the run log)."""
from __future__ import annotations

import logging
from typing import Any, Dict

from comm.errors import ProtocolError
from comm.messages import CallStatus, FunctionResult
from modules.basicmodule import Failure
from modules.errortext import bounded, place_of, raised_text, said, which_call, wire_text

__all__ = ["Answers", "CANCELLED_TEXT", "NOT_RETURNED", "NOT_STOPPED", "stopped_text"]

log = logging.getLogger("bmtree.module")

CANCELLED_TEXT = "cancelled by the coordinator"
#: in the ``cancelled`` answer of a call whose code did not return within the cancel's grace: the coordinator
#: tells its user that the call may go on moving the robot
NOT_RETURNED = "its code has not returned"
#: in the ``cancelled`` answer of a call whose code returned but said what it drives may go on
#: (:class:`~modules.basicmodule.Failure`'s ``not_stopped``): the coordinator tells its user the same
NOT_STOPPED = "it may not have stopped"


def stopped_text(why: str, still_running: float = 0.0, returned: bool = False) -> str:
    """The ``cancelled`` answer of a call in flight when its module's node stops (``why``: ``the module's
    node /bm_arm is stopping (SIGINT)``): its code ``returned`` after the cancel, or ``still_running``
    after that grace (the node stops without it: what it drives may not have stopped)."""
    if still_running:
        return "%s, but %s %gs after the cancel: the node stops without it, and what it drives may not have " \
               "stopped" % (why, NOT_RETURNED, still_running)
    return "%s; its code returned after the cancel" % why if returned else why


def _size(text: str) -> int:
    return len(text) if text.isascii() else len(text.encode("utf-8"))


class Answers:
    """The answers of ``server``'s calls (its definition, ``max_bytes``, log limit and author files are read
    from it at each answer: a node may change its limit after it made the server)."""

    def __init__(self, server: Any):
        self.server = server

    def raised(self, call: Any, exc: BaseException) -> FunctionResult:
        """The ``failed`` answer to a call whose code raised ``exc``, logged with its traceback (once for
        repeats of one exception at one place, then at most every few seconds)."""
        text = raised_text(exc, self.server._authors)
        more = self.server.log_limit.due(("raised", call.fn.name, type(exc), place_of(exc, self.server._authors)))
        if more is not None:
            try:
                log.error("%s raised (%s)%s", call.fn.qualified, which_call(call.ctx.call_id), more, exc_info=exc)
            except BaseException:  # noqa: B036 - a traceback that cannot be shown (its __str__ raises SystemExit)
                log.error("%s raised (%s): %s%s", call.fn.qualified, which_call(call.ctx.call_id), text, more)
        return self.result(call, CallStatus.FAILED, text)

    def outputs(self, call: Any, out: Any) -> FunctionResult:
        if isinstance(out, Failure):
            raise out
        if out is None:
            if call.fn.outputs:
                return self.invalid(call, "returned None, expected a dict of outputs %s" % ", ".join(
                    repr(p.name) for p in call.fn.outputs))
            out = {}
        if not isinstance(out, dict):
            return self.invalid(call, "returned %s, expected a dict of outputs" % type(out).__name__)
        return self.built(call, out)

    def built(self, call: Any, out: Dict[Any, Any]) -> FunctionResult:
        """The result of outputs ``out``, or ``failed: invalid outputs: …`` saying which output and why;
        checking a value may run the author's code (its ``__repr__``, ``__float__``, ``__eq__``), which
        may raise anything."""
        try:
            return call.fn.build_result(out, call.ctx.call_id)
        except ProtocolError as exc:
            return self.invalid(call, said(exc))
        except BaseException as exc:  # noqa: B036 - see _run
            for p in call.fn.outputs:  # which one: the author fixes that value
                try:
                    if p.name in out:
                        p.convert(out[p.name])
                except ProtocolError:
                    continue
                except BaseException as one:  # noqa: B036
                    return self.invalid(call, "output %r: checking its value raised %s" % (
                        p.name, raised_text(one, self.server._authors)))
            return self.invalid(call, "checking them raised %s" % raised_text(exc, self.server._authors))

    def invalid(self, call: Any, problem: str, what: str = "invalid outputs") -> FunctionResult:
        """Outputs that break the definition: the module author's bug, so logged here (with the call to
        match the run log) as well as answered; the answer does not name the target again (the
        coordinator says ``arm.pick failed: …`` already)."""
        prefix = call.fn.qualified + ": "
        problem = problem[len(prefix):] if problem.startswith(prefix) else problem
        more = self.server.log_limit.due((what, call.fn.name, problem[:40]))  # the same problem, other values
        if more is not None:
            log.warning("%s: %s (%s): %s%s", call.fn.qualified, what, which_call(call.ctx.call_id), bounded(problem),
                        more)
        return self.result(call, CallStatus.FAILED, "%s: %s" % (what, problem))

    def wire(self, call: Any, result: FunctionResult) -> str:
        """``result`` encoded, within the limit a coordinator accepts (an answer it drops would end the call
        as a timeout): outputs too big answer ``failed`` with their size, an error text too long is cut."""
        try:
            text = result.encode()
        except Exception as exc:  # the definition checked the outputs: never, but an answer must go out
            log.error("%s: the answer to call %s cannot be encoded (%s)", call.fn.qualified, call.ctx.call_id,
                      raised_text(exc))
            result = self.result(call, CallStatus.FAILED, "the answer cannot be encoded: %s" % raised_text(exc))
            text = result.encode()
        size = _size(text)
        if size > self.server.max_bytes and result.status == CallStatus.SUCCEEDED:
            more = self.server.log_limit.due(("too big", call.fn.name))
            if more is not None:
                log.error("%s: the answer to call %s is %d bytes, over the limit of %d; it fails instead%s",
                          call.fn.qualified, call.ctx.call_id, size, self.server.max_bytes, more)
            result = self.result(call, CallStatus.FAILED, "the outputs are %d bytes encoded, over the limit of %d "
                                  "bytes (max_bytes) that a coordinator accepts" % (size, self.server.max_bytes))
            text = result.encode()
            size = _size(text)
        error = result.error or ""
        head, tail = error, error[-60:]  # the end: where in the author's code, ``(arm.py:10 in pick)``
        while size > self.server.max_bytes and head:  # a long error text (escaped, not ASCII) under a small --max-bytes
            head = head[:len(head) // 2]
            tail = tail if len(head) > len(tail) else tail[len(tail) // 2:]
            result.error = head + "..." + tail
            text = result.encode()
            size = _size(text)
        return text

    def cancelled(self, call: Any, still_running: float = 0.0, not_stopped: str = "") -> FunctionResult:
        """``still_running``: the grace after which the call's code still runs (it does not look at its cancel).
        ``not_stopped``: what its code, which returned, said may go on (an action server's goal).
        A call its node's stop cancelled (``call.stopping``), or the module because its caller could not be
        reached (``call.cancel_why``), says so instead of naming the coordinator."""
        goes_on = ", but %s: %s" % (not_stopped, NOT_STOPPED) if not_stopped and not still_running else ""
        why = getattr(call, "stopping", "")
        if why:
            return self.result(call, CallStatus.CANCELLED, stopped_text(why, still_running, returned=True) + goes_on)
        why = getattr(call, "cancel_why", "")
        if why:
            return self.result(call, CallStatus.CANCELLED, "%s, but %s %gs after the cancel: it goes on running" % (
                why, NOT_RETURNED, still_running) if still_running else why + goes_on)
        return self.result(call, CallStatus.CANCELLED, "%s, but %s after %gs: it goes on running" % (
            CANCELLED_TEXT, NOT_RETURNED, still_running) if still_running else CANCELLED_TEXT + goes_on)

    def result(self, call: Any, status: CallStatus, error: str) -> FunctionResult:
        return FunctionResult(call_id=call.ctx.call_id, basic_mod=self.server.definition.name, function=call.ctx.function,
                              status=status, error=wire_text(bounded(error)))
