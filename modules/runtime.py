"""The basic-module runtime: binds an author's class to its definition and serves calls.

This part does not talk to ROS: it turns call/cancel payloads into results and
events through two publish callbacks, and takes how to run work and keep time
(:mod:`modules.execution`), so the ROS node (:mod:`modules.node`, worker threads and
wall time) and the test kit's in-process transport (the run's simulated clock) are the
same runtime: busy, refusals, cancels and ``Concurrent`` answer alike in both.
What the author's class derives from is :mod:`modules.basicmodule`; the answers' error
texts are :mod:`modules.errortext`.
"""
from __future__ import annotations

import logging
import math
import threading
from typing import Any, Callable, Dict, List, Optional

from comm.errors import ProtocolError, TooLarge
from comm.messages import (
    DEFAULT_MAX_BYTES,
    CallStatus,
    CancelRequest,
    Event,
    FunctionCall,
    FunctionResult,
    load_payload,
)
from comm.saylimit import SayLimit
from modules.answers import Answers
from modules.basicmodule import BasicModule, BindingError, CallContext, Failure, Rejected, public_methods
from modules.binding import signature_problems
from modules.definition import FunctionDefinition, ModuleDefinition
from modules.errortext import (
    author_files,
    bounded,
    said,
    salvage_keys,
    which_call,
    wire_text,
)
from modules.execution import Executor, Scheduler, TimerThread, WorkerThreads
from modules.outcome import MAX_DELAY, Outcome, OutcomeKind

__all__ = ["BasicModule", "CallContext", "Failure", "Rejected", "ModuleServer", "BindingError"]

log = logging.getLogger("bmtree.module")


class _Call:
    """One accepted call and where it stands: its code running, answered, holding the module."""

    __slots__ = ("ctx", "fn", "inputs", "exclusive", "running", "answered", "late", "sent", "cancelled_at", "stopping",
                 "cancel_why")

    def __init__(self, ctx: CallContext, fn: FunctionDefinition, inputs: Dict[str, Any], exclusive: bool):
        self.ctx = ctx
        self.fn = fn
        self.inputs = inputs
        self.exclusive = exclusive
        self.running = True       # the author's code runs, or is queued to
        self.answered = False
        self.late = False         # cancelled, and its code still ran when the grace was over
        self.sent = False         # its answer was handed to the publisher
        self.cancelled_at: Optional[float] = None   # on the module's clock
        self.stopping = ""        # why its node's stop cancelled it (modules.nodestop), "" otherwise
        self.cancel_why = ""      # why the module itself cancelled it (its caller cannot be reached), "" otherwise


class ModuleServer:
    """Serves one module: decode, check, dispatch, check outputs, answer.

    A call holds the module (a later non-concurrent call is ``rejected: busy with call …``)
    until it is answered and its code has returned. A call that arrives while the holding call
    is being cancelled (the tree halted it and went on: a retry, the next child) waits for it,
    up to ``cancel_grace`` seconds, instead of being refused; one call waits at a time. A method answers with its outputs, an
    exception, or an :class:`Outcome` that the server carries out on its clock (delays and
    hangs hold no thread).

    Args:
        definition: the module's definition (its name filters the calls served).
        impl: the author's object.
        publish_result: sends an encoded FunctionResult.
        publish_event: sends an encoded Event.
        cancel_grace: seconds a cancelled function may take to return before the
            ``cancelled`` answer is sent anyway.
        executor: where the author's code runs (default: worker threads).
        scheduler: the module's clock (default: a wall-clock timer thread; in tests the
            run's simulated clock, with a :class:`~modules.execution.ClockExecutor`).
    """

    def __init__(self, definition: ModuleDefinition, impl: BasicModule,
                 publish_result: Callable[[str], None], publish_event: Callable[[str], None],
                 max_bytes: int = DEFAULT_MAX_BYTES, cancel_grace: float = 1.0,
                 executor: Optional[Executor] = None, scheduler: Optional[Scheduler] = None):
        self.definition = definition
        self.impl = impl
        self._publish_result = publish_result
        self._publish_event = publish_event
        self.max_bytes = max_bytes
        self.cancel_grace = cancel_grace
        self.scheduler: Scheduler = scheduler if scheduler is not None else TimerThread("%s-timer" % definition.name)
        self.executor: Executor = executor if executor is not None else WorkerThreads("%s-call" % definition.name)
        self._lock = threading.Lock()
        self._sent = threading.Condition(threading.Lock())   # notified once an answer is handed over ...
        self._sent_waited = False                            # ... while someone waits for it (answers_sent)
        self._calls: Dict[str, _Call] = {}
        self._exclusive: Optional[_Call] = None
        self._waiting: Optional[_Call] = None  # the next exclusive call, while the holder is being cancelled
        #: why the node stops (:meth:`stop`), "" while it serves: a call that comes meanwhile is refused
        self.stopping = ""
        #: a :class:`comm.liveness.Watchdog` over the callers (a node sets it): a call whose caller's
        #: process is gone is cancelled, not left running the hardware and holding the module
        self.callers: Optional[Any] = None
        #: told ``(call_ids, reason)`` when a ``die`` outcome ends the module (a node kills its process;
        #: the tests' in-process transport ends those calls ``module_lost``); None: the calls never answer
        self.on_death: Optional[Callable[[List[str], str], None]] = None
        #: function -> an injected fault (``take()``, ``outcome``): it answers instead of the function
        #: (the world's faults of a user's own module under ``bmtree run --sim``)
        self.faults: Dict[str, Any] = {}
        #: the module's log says a repeated problem once, then at most every few seconds
        self.log_limit = SayLimit()
        self.answers = Answers(self)
        self._bind()
        self._authors = author_files(impl)  # where an exception's place is looked for first
        impl._server = self

    def _bind(self) -> None:
        functions = set(self.definition.functions)
        methods = public_methods(self.impl)
        problems = []
        for fn in sorted(functions - methods):
            problems.append("function %r of definition %s has no method in class %s" % (
                fn, self.definition.source or self.definition.name, type(self.impl).__name__))
        for m in sorted(methods - functions):
            problems.append("method %r of class %s is not a function of module %r (definition %s)" % (
                m, type(self.impl).__name__, self.definition.name, self.definition.source or "?"))
        problems.extend(signature_problems(self.definition, self.impl))
        problems.extend(self._concurrent_problems())
        if problems:
            raise BindingError("; ".join(problems))

    def _concurrent_problems(self) -> List[str]:
        """A ``concurrent`` that is neither a bool nor a set of this module's function names: a typo
        there would make a function exclusive without a word, refused ``busy`` on the robot."""
        from comm.errors import did_you_mean

        c = self.impl.concurrent
        cls = type(self.impl).__name__
        if isinstance(c, bool):
            return []
        if not isinstance(c, (set, frozenset, list, tuple)) or not all(isinstance(n, str) for n in c):
            return ["%s.concurrent must be True, False or a set of function names, got %s" % (
                cls, bounded(said(repr(c)) if isinstance(c, str) else type(c).__name__, 80))]
        return ["%s.concurrent names %r, which is not a function of module %r%s" % (
            cls, n, self.definition.name, did_you_mean(n, self.definition.functions)
            or " (functions: %s)" % (", ".join(self.definition.functions) or "none"))
            for n in sorted(set(c) - set(self.definition.functions))]

    def _is_concurrent(self, fn: FunctionDefinition) -> bool:
        c = self.impl.concurrent
        return fn.concurrent or c is True or (isinstance(c, (set, frozenset, list, tuple)) and fn.name in c)

    # -- incoming --------------------------------------------------------------------
    def handle_call(self, text: Any) -> None:
        """Handle one ``/master/output`` payload; never raises."""
        try:
            self._handle_call(text)
        except Exception as exc:
            log.error("could not handle a call (%s: %s)", type(exc).__name__, exc)

    def handle_parsed(self, head: Dict[str, Any], caller: Optional[str] = None) -> None:
        """Handle a call payload already parsed (and its size and depth checked) by
        :func:`~comm.messages.load_payload`, as the node's inbox does, from node ``caller``; never raises."""
        try:
            self._take(head, caller)
        except Exception as exc:
            log.error("could not handle a call (%s: %s)", type(exc).__name__, exc)

    def _handle_call(self, text: Any) -> None:
        try:
            head = load_payload(text, self.max_bytes)
        except ProtocolError as exc:
            keys = salvage_keys(text)
            if keys.get("basic_mod") == self.definition.name and "call_id" in keys:
                self._reject(keys["call_id"], keys.get("function"), "call too large: %s (raise it with --max-bytes N, "
                             "or _max_bytes:=N, on the module's node)" % exc if isinstance(exc, TooLarge)
                             else "malformed call: %s" % exc)
            else:
                log.warning("ignored a malformed call: %s", exc)
            return
        self._take(head)

    def _take(self, head: Dict[str, Any], caller: Optional[str] = None) -> None:
        if head.get("basic_mod") != self.definition.name:
            return
        call_id = head.get("call_id") if isinstance(head.get("call_id"), str) else None
        fname = head.get("function")
        if not isinstance(fname, str):
            self._reject(call_id, fname, "missing or malformed key 'function'")
            return
        try:
            fn = self.definition.function(fname)
        except ProtocolError as exc:
            self._reject(call_id, fname, str(exc))
            return
        try:
            received = FunctionCall.from_obj(head)
        except ProtocolError as exc:  # a value that does not fit its type: the checker's words, after the function
            self._reject(call_id, fname, "bad inputs: %s: %s" % (fn.qualified, exc))
            return
        try:
            inputs = fn.inputs_of(received)
        except ProtocolError as exc:
            self._reject(call_id, fname, "bad inputs: %s" % exc)
            return
        call = _Call(CallContext(call_id, fname), fn, inputs, not self._is_concurrent(fn))
        waits = False
        with self._lock:
            stopping = self.stopping  # under the lock that stop() takes: no call starts after its sweep
            busy = self._exclusive if call.exclusive and not stopping else None
            stuck = busy is not None and self._stuck(busy)
            if busy is not None and busy.ctx.cancelled.is_set() and self._waiting is None and not stuck:
                busy, waits, self._waiting = None, True, call  # its code is stopping: run this one next
            elif busy is not None and self._waiting is not None:
                busy = self._waiting
            if busy is None and not stopping:
                if call.exclusive and not waits:
                    self._exclusive = call
                if call_id is not None:
                    self._calls[call_id] = call
        if busy is not None:
            self._reject(call_id, fname, self._stuck_text(busy) if stuck else "busy with call %s (%s)" % (
                busy.ctx.call_id, busy.ctx.function))
            return
        if stopping:
            self._reject(call_id, fname, "%s: the call was not run" % stopping)
            return
        if self.callers is not None and caller and call_id is not None:
            self.callers.call_sent(call_id, caller)
        if waits:
            holder = self._exclusive
            self.scheduler.call_later(self.cancel_grace, lambda: self._stop_waiting(call, holder))
        else:
            self.executor.submit(self._run, call, None)

    def _stop_waiting(self, call: _Call, holder: Optional[_Call]) -> None:
        """The cancelled holder's code did not return within the grace: refuse the waiting call."""
        with self._lock:
            if self._waiting is not call:
                return
            self._waiting = None
            if call.ctx.call_id is not None and self._calls.get(call.ctx.call_id) is call:
                del self._calls[call.ctx.call_id]
        if self.callers is not None:
            self.callers.call_done(call.ctx.call_id)
        self._reject(call.ctx.call_id, call.ctx.function, self._stuck_text(holder))

    def stuck_note(self) -> str:
        """Why calls to this module's non-concurrent functions are refused now ('' when they are not): a
        ping's answer says it, so a run learns at start that an earlier run left the module stuck."""
        with self._lock:
            holder = self._exclusive
            if holder is None or not self._stuck(holder):
                return ""
        return self._stuck_text(holder)

    def _stuck(self, holder: _Call) -> bool:
        """The holder was cancelled a grace ago or more and its code still runs: a new call need not wait."""
        return holder.cancelled_at is not None and self.scheduler.now() - holder.cancelled_at >= self.cancel_grace

    def _stuck_text(self, holder: Optional[_Call]) -> str:
        """Why a call is refused while a cancelled call's code has not returned (perhaps one of an earlier run)."""
        if holder is None:
            return "busy: a cancelled call's code has not returned within %gs" % self.cancel_grace
        ago = self.scheduler.now() - holder.cancelled_at if holder.cancelled_at is not None else self.cancel_grace
        return ("busy with call %s (%s): it was cancelled %.1f s ago and its code has not returned; %s refuses "
                "calls until it does, or until its node is restarted" % (
                    holder.ctx.call_id, holder.ctx.function, ago, self.definition.name))

    def handle_cancel(self, text: Any) -> None:
        """Handle one ``/master/cancel`` payload; never raises."""
        try:
            self._handle_cancel(text)
        except Exception as exc:
            log.error("could not handle a cancel (%s: %s)", type(exc).__name__, exc)

    def _handle_cancel(self, text: Any) -> None:
        try:
            req = CancelRequest.decode(text, self.max_bytes)
        except ProtocolError as exc:
            log.warning("ignored a malformed cancel: %s", exc)
            return
        if req.basic_mod == self.definition.name:
            self.cancel(req.call_id)

    def stop(self, why: str, grace: Optional[float] = None) -> List[str]:
        """The module's node stops (``why`` says so, in the answers): cancel every call in flight as a
        coordinator's cancel would, wait up to ``grace`` (the cancel grace) for their code to return, answer
        each; the log lines said (:func:`modules.nodestop.stop_calls`)."""
        from modules.nodestop import stop_calls

        return stop_calls(self, why, self.cancel_grace if grace is None else grace)

    def cancel(self, call_id: str, why: str = "") -> bool:
        """Cancel a call as a cancel request would (its caller went away); False if it is not running
        or was cancelled already (so nobody reports a second cancel as the one that stopped it).
        ``why``: the answer's text, when someone may read it (its caller cannot be reached now)."""
        with self._lock:
            call = self._calls.get(call_id)
            if call is None or call.ctx.cancelled.is_set():
                return False
            call.cancel_why = why
            queued = self._waiting is call
            if queued:  # never started: nothing to stop
                self._waiting = None
                call.running = False
        if not call.ctx.cancel():
            return False
        call.cancelled_at = self.scheduler.now()
        if queued:
            self._finish(call, self.answers.cancelled(call))
            return True
        with self._lock:
            running = call.running
        if running:  # its code may still stop the hardware: wait for it, but not forever
            self.scheduler.call_later(self.cancel_grace, lambda: self._grace_over(call))
        else:        # waiting on an outcome's delay, or hanging: nothing to stop
            self._finish(call, self.answers.cancelled(call))
        return True

    def _grace_over(self, call: _Call) -> None:
        """The cancel's grace is over: answer ``cancelled``, and say so in the module's log when the
        call's code still runs: the module refuses calls (busy) until it returns, and only here can
        its author learn that the function does not look at its cancel."""
        with self._lock:
            late = call.late = call.running and not call.answered
        if late:
            log.warning("%s of %s was cancelled but its code has not returned after %g s; %s",
                        which_call(call.ctx.call_id), call.fn.qualified, self.cancel_grace,
                        "%s stays busy until it does" % self.definition.name
                        if call.exclusive else "it goes on running")
        self._finish(call, self.answers.cancelled(call, self.cancel_grace if late else 0.0))

    # -- running ---------------------------------------------------------------------
    def _run(self, call: _Call, work: Optional[Callable[..., Any]]) -> None:
        """Run the author's code for ``call`` (the function if ``work`` is None, else an
        outcome's respond function) and act on what it gave."""
        ctx = call.ctx
        outcome: Optional[Outcome] = None
        result: Optional[FunctionResult] = None
        not_stopped = ""  # a cancelled call's code gave up waiting for what it drives: what may go on
        if not ctx.cancelled.is_set():  # a call cancelled before it started never runs
            self.impl._local.ctx = ctx
            try:
                if work is None:
                    fault = self.faults.get(call.fn.name)
                    out = fault.answer(call.fn.qualified, ctx.call_id) if fault is not None and fault.take() else None
                    if out is None:
                        out = self.impl.before_call(call.fn.name, call.inputs)
                    if out is None:
                        out = getattr(self.impl, call.fn.name)(**call.inputs)
                else:
                    out = work(**call.inputs)
                if isinstance(out, Outcome):
                    outcome = out
                elif not ctx.cancelled.is_set():  # a cancelled call's code may return early, without outputs
                    result = self.answers.outputs(call, out)
            except Failure as exc:
                result = self.answers.result(call, CallStatus.FAILED, said(exc) or "failed")
                not_stopped = str(getattr(exc, "not_stopped", "") or "")
            except Rejected as exc:
                result = self.answers.result(call, CallStatus.REJECTED, said(exc) or "rejected")
            except BaseException as exc:  # noqa: B036 - SystemExit, KeyboardInterrupt, GeneratorExit raised by the
                # author's code end this call, not the worker thread, and leave neither it unanswered nor the module held
                if isinstance(exc, KeyboardInterrupt) and threading.current_thread() is threading.main_thread():
                    raise  # Ctrl-C, on a simulated clock's thread (the test kit runs the module in-process)
                result = self.answers.raised(call, exc)
            finally:
                self.impl._local.ctx = None
        with self._lock:
            call.running = False
            late, call.late = call.late, False
        if late:
            log.info("the code of cancelled %s of %s has returned; %s is free again", which_call(ctx.call_id),
                     call.fn.qualified, self.definition.name)
        if ctx.cancelled.is_set():
            self._finish(call, self.answers.cancelled(call, not_stopped=not_stopped))
        elif outcome is not None:
            self._follow(call, outcome)
        else:
            assert result is not None
            self._finish(call, result)

    def _follow(self, call: _Call, outcome: Outcome) -> None:
        """Carry out ``outcome`` on the module's clock."""
        delay = outcome.delay
        if isinstance(delay, bool) or not isinstance(delay, (int, float)) or not -math.inf < delay <= MAX_DELAY:
            # NaN, inf or 1e300 s would end the clock's thread that waits it out, or answer at once
            shown = bounded(repr(delay), 40) if isinstance(delay, (int, float)) else "a %s" % type(delay).__name__
            self._finish(call, self.answers.invalid(call, "its delay is %s, not a number of seconds up to %d (a day)"
                                                     % (shown, MAX_DELAY), "invalid outcome"))
            return
        if outcome.ignores_cancel:  # busy as if its code ran: a cancel answers after the grace, the module stays held
            with self._lock:
                if call.answered:
                    return
                call.running = True
        if outcome.delay > 0:
            self.scheduler.call_later(outcome.delay, lambda: self.executor.submit(self._effect, call, outcome))
        else:
            self._effect(call, outcome)

    def _effect(self, call: _Call, outcome: Outcome) -> None:
        kind = outcome.kind
        with self._lock:
            late = False
            if outcome.ignores_cancel and kind != OutcomeKind.HANG:
                call.running = False
                late, call.late = call.late, False
            answered = call.answered
            if not answered and kind == OutcomeKind.RESPOND:
                call.running = True
        if late:
            log.info("cancelled %s of %s is over; %s is free again", which_call(call.ctx.call_id), call.fn.qualified,
                     self.definition.name)
        if answered:  # cancelled meanwhile: an outcome that ignored the cancel frees the module only now
            if outcome.ignores_cancel:
                self._finish(call, self.answers.cancelled(call))
            return
        if kind == OutcomeKind.RESPOND:
            self._run(call, outcome.fn or getattr(self.impl, call.fn.name))
        elif kind == OutcomeKind.SUCCEED:
            outputs = outcome.outputs
            self._finish(call, self.answers.built(call, outputs) if isinstance(outputs, dict) else self.answers.invalid(
                call, "its outputs are %s, expected a dict" % type(outputs).__name__, "invalid outcome"))
        elif kind == OutcomeKind.FAIL:
            self._finish(call, self.answers.result(call, CallStatus.FAILED, said(outcome.reason) or "failed"))
        elif kind == OutcomeKind.REJECT:
            self._finish(call, self.answers.result(call, CallStatus.REJECTED, said(outcome.reason) or "rejected"))
        elif kind == OutcomeKind.DIE:
            self.die(said(outcome.reason) or "its process died")
        # HANG: no answer until a cancel

    def die(self, reason: str) -> None:
        """The module dies with every call in flight: none is ever answered, code still running is
        cancelled, the module is free, and :attr:`on_death` is told the calls' ids."""
        with self._lock:
            calls = list(self._calls.values())
            for c in calls:
                c.answered = True
            self._calls.clear()
            self._exclusive = self._waiting = None
        for c in calls:
            c.ctx.cancel()
        if self.on_death is not None:
            self.on_death([c.ctx.call_id for c in calls if c.ctx.call_id is not None], reason)

    def in_flight(self) -> List[Any]:
        """The calls accepted and not yet answered (or whose code still runs), for :meth:`answers_sent`."""
        with self._lock:
            return list(self._calls.values())

    def answers_sent(self, calls: List[Any], timeout: float) -> bool:
        """Wait up to ``timeout`` s until each of ``calls`` (from :meth:`in_flight`) has its answer handed to
        the publisher: a node that stops lets the answers its stop caused go out before rospy closes its
        topics. False if one did not within the time."""
        self._sent_waited = True
        with self._sent:
            return self._sent.wait_for(lambda: all(c.sent for c in calls), timeout)

    def _finish(self, call: _Call, result: FunctionResult) -> None:
        """Answer once; free the module when the call is answered and its code has returned (and
        start the call waiting for it)."""
        nxt = None
        with self._lock:
            first = not call.answered
            call.answered = True
            if not call.running:
                if call.ctx.call_id is not None and self._calls.get(call.ctx.call_id) is call:
                    del self._calls[call.ctx.call_id]
                if self._exclusive is call:
                    self._exclusive = nxt = self._waiting
                    self._waiting = None
        if nxt is not None:
            self.executor.submit(self._run, nxt, None)
        if first:
            if self.callers is not None:
                self.callers.call_done(call.ctx.call_id)
            self._publish_result(self.answers.wire(call, result))
            call.sent = True
            if self._sent_waited:
                with self._sent:
                    self._sent.notify_all()

    def _reject(self, call_id: Optional[str], function: Any, error: str) -> None:
        error = wire_text(bounded(error))
        known = function if isinstance(function, str) and function in self.definition.functions else None
        more = self.log_limit.due(("rejected", known, error.split(":", 1)[0][:60]))
        if more is not None:
            log.warning("rejected call %s of %s.%s: %s%s", call_id, self.definition.name, bounded(said(function), 200),
                        error, more)
        fname = function if isinstance(function, str) else None
        self._publish_result(FunctionResult(call_id=call_id, basic_mod=self.definition.name, function=fname,
                                            status=CallStatus.REJECTED, error=error).encode())

    # -- events ----------------------------------------------------------------------
    def emit(self, event: str, params: Dict[str, Any]) -> None:
        ev = self.definition.events.get(event)
        if ev is None:
            raise ProtocolError("module %r has no event %r" % (self.definition.name, event))
        msgs = ev.build_values(params)
        self._publish_event(Event(self.definition.name, event, [p.name for p in ev.params], msgs).encode())
