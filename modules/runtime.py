"""The basic-module runtime: binds an author's class to its definition and serves calls.

This part does not talk to ROS: it turns call/cancel payloads into results and
events through two publish callbacks, so the ROS node (:mod:`modules.node`), the
tests and the mocked modules all share it.
"""
from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any, Callable, Dict, Iterable, List, Optional, Set, Union

from comm.errors import ProtocolError
from comm.messages import DEFAULT_MAX_BYTES, CancelRequest, Event, FunctionCall, FunctionResult, load_payload
from modules.definition import FunctionDefinition, ModuleDefinition

__all__ = ["BasicModule", "CallContext", "Failure", "Rejected", "ModuleServer", "BindingError"]

log = logging.getLogger("bmtree.module")


class _Workers:
    """Reusable threads for calls: a call never waits for a thread, and no thread is started
    per call while one is idle."""

    def __init__(self, name: str, idle_seconds: float = 30.0):
        self._jobs: queue.Queue = queue.Queue()
        self._idle = 0
        self._lock = threading.Lock()
        self._name = name
        self._idle_seconds = idle_seconds

    def submit(self, fn: Callable[..., None], *args: Any) -> None:
        with self._lock:
            start = self._idle == 0
            if not start:
                self._idle -= 1
        self._jobs.put((fn, args))
        if start:
            threading.Thread(target=self._loop, name=self._name, daemon=True).start()

    def _loop(self) -> None:
        while True:
            try:
                fn, args = self._jobs.get(timeout=self._idle_seconds)
            except queue.Empty:
                with self._lock:
                    if self._idle > 0 and self._jobs.empty():
                        self._idle -= 1
                        return
                continue
            fn(*args)
            with self._lock:
                self._idle += 1


class Failure(Exception):
    """Raise (or return) this from a function to answer ``failed`` with a reason."""


class Rejected(Exception):
    """Raise this to answer ``rejected``: the call cannot be taken now (its Exec-condition
    does not hold), as opposed to a call that was tried and failed."""


class BindingError(Exception):
    """The class and the definition do not match (named in the message)."""


class CallContext:
    """What a running function knows about its call: id, and whether it was cancelled."""

    def __init__(self, call_id: Optional[str], function: str):
        self.call_id = call_id
        self.function = function
        self.cancelled = threading.Event()
        self.answered = False
        self._callbacks: List[Callable[[], None]] = []
        self._lock = threading.Lock()

    def on_cancel(self, callback: Callable[[], None]) -> None:
        """Run ``callback`` (once, from the cancelling thread) when the call is cancelled."""
        with self._lock:
            if not self.cancelled.is_set():
                self._callbacks.append(callback)
                return
        callback()

    def cancel(self) -> None:
        with self._lock:
            if self.cancelled.is_set():
                return
            self.cancelled.set()
            callbacks, self._callbacks = self._callbacks, []
        for cb in callbacks:
            try:
                cb()
            except Exception:
                log.exception("cancel callback of %s failed", self.function)

    def sleep(self, seconds: float) -> bool:
        """Sleep unless cancelled first; True if the full time passed."""
        return not self.cancelled.wait(max(0.0, seconds))


class BasicModule:
    """Base class for module authors: one method per function of the definition.

    A method receives its inputs as keyword arguments (ROS messages, by name) and
    returns a dict of outputs (ROS messages or YAML-like values such as ``True`` for
    ``std_msgs/Bool``). Raise or return :class:`Failure` to answer ``failed``.
    Long functions should watch ``self.context.cancelled`` or use
    ``self.context.sleep``.

    Attributes:
        concurrent: True, or a set of function names that may run while others run.
            Non-concurrent functions exclude each other (they share the hardware).
    """

    concurrent: Union[bool, Set[str]] = False

    def __init__(self) -> None:
        self._server: Optional[ModuleServer] = None
        self._local = threading.local()

    @property
    def context(self) -> CallContext:
        ctx = getattr(self._local, "ctx", None)
        if ctx is None:
            raise RuntimeError("no call is running in this thread")
        return ctx

    @property
    def definition(self) -> ModuleDefinition:
        assert self._server is not None, "module not bound to a server"
        return self._server.definition

    def emit(self, event: str, **params: Any) -> None:
        """Publish an event of this module, checked against the definition's Events."""
        assert self._server is not None, "module not bound to a server"
        self._server.emit(event, params)

    def before_call(self, function: str, inputs: Dict[str, Any]) -> None:
        """Hook run in the call's thread before the function (fault injection, logging)."""

    def setup(self, node: Any) -> None:
        """Hook run once by the ROS node after it connected (extra topics, parameters)."""

    def shutdown(self) -> None:
        """Hook run once when the node stops."""


_RESERVED = set(dir(BasicModule))


def _public_methods(obj: Any) -> Set[str]:
    return {n for n in dir(type(obj)) if not n.startswith("_") and n not in _RESERVED
            and callable(getattr(type(obj), n, None))}


class ModuleServer:
    """Serves one module: decode, check, dispatch off-thread, check outputs, answer.

    Args:
        definition: the module's definition (its name filters the calls served).
        impl: the author's object.
        publish_result: sends an encoded FunctionResult.
        publish_event: sends an encoded Event.
        cancel_grace: seconds a cancelled function may take to return before the
            ``cancelled`` answer is sent anyway.
    """

    def __init__(self, definition: ModuleDefinition, impl: BasicModule,
                 publish_result: Callable[[str], None], publish_event: Callable[[str], None],
                 max_bytes: int = DEFAULT_MAX_BYTES, cancel_grace: float = 1.0):
        self.definition = definition
        self.impl = impl
        self._publish_result = publish_result
        self._publish_event = publish_event
        self.max_bytes = max_bytes
        self.cancel_grace = cancel_grace
        self._lock = threading.Lock()
        self._running: Dict[str, CallContext] = {}
        self._exclusive: Optional[CallContext] = None
        self._workers = _Workers("%s-call" % definition.name)
        self._bind()
        impl._server = self

    def _bind(self) -> None:
        functions = set(self.definition.functions)
        methods = _public_methods(self.impl)
        problems = []
        for fn in sorted(functions - methods):
            problems.append("function %r of definition %s has no method in class %s" % (
                fn, self.definition.source or self.definition.name, type(self.impl).__name__))
        for m in sorted(methods - functions):
            problems.append("method %r of class %s is not a function of module %r (definition %s)" % (
                m, type(self.impl).__name__, self.definition.name, self.definition.source or "?"))
        if problems:
            raise BindingError("; ".join(problems))

    def _is_concurrent(self, fn: FunctionDefinition) -> bool:
        c = self.impl.concurrent
        return fn.concurrent or c is True or (isinstance(c, (set, frozenset, list, tuple)) and fn.name in c)

    # -- incoming --------------------------------------------------------------------
    def handle_call(self, text: Any) -> None:
        """Handle one ``/master/output`` payload; never raises."""
        try:
            self._handle_call(text)
        except Exception:
            log.exception("unexpected error while handling a call")

    def _handle_call(self, text: Any) -> None:
        try:
            head = load_payload(text, self.max_bytes)
        except ProtocolError as exc:
            log.warning("ignored a malformed call: %s", exc)
            return
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
            call = FunctionCall.from_obj(head)
            inputs = fn.inputs_of(call)
        except ProtocolError as exc:
            self._reject(call_id, fname, "bad inputs: %s" % exc)
            return
        ctx = CallContext(call_id, fname)
        with self._lock:
            if not self._is_concurrent(fn):
                if self._exclusive is not None:
                    busy = self._exclusive
                    ctx = None
                else:
                    self._exclusive = ctx
            if ctx is not None and call_id is not None:
                self._running[call_id] = ctx
        if ctx is None:
            self._reject(call_id, fname, "busy with call %s (%s)" % (busy.call_id, busy.function))
            return
        self._workers.submit(self._run, fn, ctx, inputs)

    def handle_cancel(self, text: Any) -> None:
        """Handle one ``/master/cancel`` payload; never raises."""
        try:
            req = CancelRequest.decode(text, self.max_bytes)
        except ProtocolError as exc:
            log.warning("ignored a malformed cancel: %s", exc)
            return
        if req.basic_mod != self.definition.name:
            return
        with self._lock:
            ctx = self._running.get(req.call_id)
        if ctx is None:
            return
        ctx.cancel()
        timer = threading.Timer(self.cancel_grace, self._answer_cancelled, args=(ctx,))
        timer.daemon = True
        timer.start()

    # -- running ---------------------------------------------------------------------
    def _run(self, fn: FunctionDefinition, ctx: CallContext, inputs: Dict[str, Any]) -> None:
        self.impl._local.ctx = ctx
        result: Optional[FunctionResult] = None
        try:
            self.impl.before_call(fn.name, inputs)
            out = getattr(self.impl, fn.name)(**inputs)
            if isinstance(out, Failure):
                raise out
            if out is None:
                out = {}
            if not isinstance(out, dict):
                raise ProtocolError("%s returned %s, expected a dict of outputs" % (fn.qualified, type(out).__name__))
            if not ctx.cancelled.is_set():
                try:
                    result = fn.build_result(out, ctx.call_id)
                except ProtocolError as exc:
                    result = self._result(ctx, "failed", "invalid outputs: %s" % exc)
        except Failure as exc:
            result = self._result(ctx, "failed", str(exc) or "failed")
        except Rejected as exc:
            result = self._result(ctx, "rejected", str(exc) or "rejected")
        except Exception as exc:
            log.exception("%s raised", fn.qualified)
            result = self._result(ctx, "failed", "%s: %s" % (type(exc).__name__, exc))
        finally:
            self.impl._local.ctx = None
        with self._lock:
            if self._exclusive is ctx:
                self._exclusive = None
            if ctx.call_id is not None:
                self._running.pop(ctx.call_id, None)
        if ctx.cancelled.is_set():
            self._answer_cancelled(ctx)
        elif result is not None:
            self._send(ctx, result)

    def _answer_cancelled(self, ctx: CallContext) -> None:
        self._send(ctx, self._result(ctx, "cancelled", "cancelled by the coordinator"))

    def _send(self, ctx: CallContext, result: FunctionResult) -> None:
        with self._lock:
            if ctx.answered:
                return
            ctx.answered = True
        self._publish_result(result.encode())

    def _result(self, ctx: CallContext, status: str, error: str) -> FunctionResult:
        return FunctionResult(call_id=ctx.call_id, basic_mod=self.definition.name, function=ctx.function,
                              status=status, error=error)

    def _reject(self, call_id: Optional[str], function: Any, error: str) -> None:
        log.warning("rejected call %s of %s.%s: %s", call_id, self.definition.name, function, error)
        fname = function if isinstance(function, str) else None
        self._publish_result(FunctionResult(call_id=call_id, basic_mod=self.definition.name, function=fname,
                                            status="rejected", error=error).encode())

    # -- events ----------------------------------------------------------------------
    def emit(self, event: str, params: Dict[str, Any]) -> None:
        ev = self.definition.events.get(event)
        if ev is None:
            raise ProtocolError("module %r has no event %r" % (self.definition.name, event))
        msgs = ev.build_values(params)
        self._publish_event(Event(self.definition.name, event, [p.name for p in ev.params], msgs).encode())

    def running(self) -> Iterable[str]:
        with self._lock:
            return list(self._running)

    def wait_idle(self, timeout: float = 5.0) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self._lock:
                if not self._running and self._exclusive is None:
                    return True
            time.sleep(0.01)
        return False
