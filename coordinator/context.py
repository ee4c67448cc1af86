"""State of one run: the tree blackboard, calls in flight and their correlation, the log."""
from __future__ import annotations

import logging
import queue
import typing
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional

from comm.messages import (
    BlackboardAnswer,
    BlackboardRequest,
    CancelRequest,
    Event,
    FunctionCall,
    FunctionResult,
)
from comm.rostypes import from_message
from coordinator.clock import Clock
from coordinator.expr import field_of, unwrap
from coordinator.language import Ref
from coordinator.transport import Transport
from modules.definition import FunctionDefinition, ModuleDefinition

__all__ = ["CallRecord", "RunContext", "WAKE", "plain"]

log = logging.getLogger("bmtree.coordinator")

WAKE = object()


def plain(value: Any) -> Any:
    """A ROS message as test-friendly data: one-field messages unwrap to their value."""
    v = unwrap(value)
    if hasattr(v, "__slots__") and hasattr(v, "_type"):
        return from_message(v)
    return v


@dataclass
class CallRecord:
    """One call made by the tree, for the run report and the testing kit."""

    target: str
    call_id: str
    messages: Dict[str, Any]      # the inputs as sent (ROS messages)
    started: float
    ended: Optional[float] = None
    status: str = "running"      # running, succeeded, failed, rejected, cancelled, timeout, halted
    error: str = ""
    outputs: Dict[str, Any] = field(default_factory=dict)
    function: Optional[FunctionDefinition] = None
    result: Optional[FunctionResult] = None

    @property
    def inputs(self) -> Dict[str, Any]:
        """The inputs as plain data (``{"place": "kitchen"}``), for reports and tests."""
        return {k: plain(v) for k, v in self.messages.items()}

    @property
    def duration(self) -> Optional[float]:
        return None if self.ended is None else self.ended - self.started


class RunContext:
    """Shared by every behaviour of one run; only touched from the ticking thread."""

    def __init__(self, transport: Transport, clock: Clock, definitions: Mapping[str, ModuleDefinition],
                 default_timeout: float = 30.0, recall_timeout: float = 5.0):
        self.transport = transport
        self.clock = clock
        self.definitions = dict(definitions)
        self.default_timeout = default_timeout
        self.recall_timeout = recall_timeout
        self.blackboard: Dict[str, Any] = {}
        self.calls: List[CallRecord] = []
        self.pending: typing.OrderedDict[str, CallRecord] = OrderedDict()
        self.events: List[Event] = []
        self.event_times: List[float] = []
        self.answers: Dict[str, BlackboardAnswer] = {}
        self.dropped: List[FunctionResult] = []
        self.inbox: queue.Queue = queue.Queue()

    # values ------------------------------------------------------------------------
    def lookup(self, key: str) -> Any:
        if key not in self.blackboard:
            raise KeyError("tree key %r is not set" % key)
        return self.blackboard[key]

    def resolve(self, value: Any) -> Any:
        """A YAML literal with every Ref replaced by the current tree-blackboard value."""
        if isinstance(value, Ref):
            v = self.lookup(value.key)
            for step in value.path:
                v = field_of(v, step, value.key)
            return v
        if isinstance(value, dict):
            return {k: self.resolve(v) for k, v in value.items()}
        if isinstance(value, list):
            return [self.resolve(v) for v in value]
        return value

    def wake_after(self, delay: float) -> None:
        """Make the runner tick again after ``delay`` (timeouts, waits, retries)."""
        self.clock.call_later(delay, lambda: self.inbox.put(WAKE))

    # calls -------------------------------------------------------------------------
    def start_call(self, fn: FunctionDefinition, call: FunctionCall) -> CallRecord:
        rec = CallRecord(target=fn.qualified, call_id=call.call_id or "", function=fn, started=self.clock.now(),
                         messages=dict(zip(call.names or [], call.msgs)))
        self.calls.append(rec)
        self.pending[rec.call_id] = rec
        self.transport.send_call(call)
        return rec

    def finish(self, rec: CallRecord, status: str, error: str = "") -> None:
        if rec.ended is not None:
            return
        rec.ended = self.clock.now()
        rec.status = status
        rec.error = error
        self.pending.pop(rec.call_id, None)

    def cancel(self, rec: CallRecord, status: str = "halted", error: str = "") -> None:
        """Stop waiting for ``rec`` and ask its module to stop it."""
        if rec.ended is not None:
            return
        self.finish(rec, status, error)
        fn = rec.function
        assert fn is not None
        self.transport.send_cancel(CancelRequest(call_id=rec.call_id, basic_mod=fn.module, function=fn.name))

    def request(self, names: List[str]) -> str:
        req = BlackboardRequest(var_names=list(names))
        self.transport.send_request(req)
        return req.request_id or ""

    # incoming ----------------------------------------------------------------------
    def dispatch(self, item: Any) -> None:
        if isinstance(item, FunctionResult):
            rec = self.correlate(item)
            if rec is None:
                self.dropped.append(item)
                log.debug("result matched no pending call: %s", item.call_id)
                return
            self.pending.pop(rec.call_id, None)
            rec.result = item
        elif isinstance(item, Event):
            self.events.append(item)
            self.event_times.append(self.clock.now())
        elif isinstance(item, BlackboardAnswer):
            if item.request_id:
                self.answers[item.request_id] = item

    def correlate(self, result: FunctionResult) -> Optional[CallRecord]:
        """The pending call a result answers (DESIGN §2).

        By ``call_id`` when present (a late answer to a call that is no longer
        pending matches nothing); a legacy result is matched by module and function
        when present, else by the output names of the pending calls' definitions,
        else to the oldest pending call.
        """
        if result.call_id is not None:
            return self.pending.get(result.call_id)
        if not self.pending:
            return None
        if result.basic_mod is not None and result.function is not None:
            for rec in self.pending.values():
                fn = rec.function
                if fn is not None and fn.module == result.basic_mod and fn.name == result.function:
                    return rec
            return None
        names = set(result.names)
        for rec in self.pending.values():
            fn = rec.function
            if fn is not None and {p.name for p in fn.outputs} == names:
                return rec
        return next(iter(self.pending.values()))
