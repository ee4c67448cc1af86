"""State of one run: the tree blackboard, calls in flight and their correlation, the log."""
from __future__ import annotations

import json
import logging
import queue
import typing
from collections import OrderedDict, deque
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Tuple

import genpy

from comm.liveness import BlackboardLost, ModuleLost
from comm.messages import (
    BlackboardAnswer,
    BlackboardRequest,
    CancelRequest,
    Event,
    FunctionCall,
    FunctionResult,
)
from comm.rostypes import from_message
from comm.textenum import TextEnum
from coordinator.clock import Clock
from coordinator.received import Received
from coordinator.refs import resolve, unwrap
from coordinator.runevents import Notice, RunObserver, notify
from coordinator.transport import Transport
from modules.answers import NOT_RETURNED, NOT_STOPPED
from modules.definition import FunctionDefinition, ModuleDefinition

__all__ = ["CallRecord", "LATE_ANSWER", "MODULE_GONE", "RecordStatus", "RunContext", "STILL_RUNNING", "SUCCESS_FALSE",
           "WAKE", "gone_text", "late_answer_text", "plain", "success_false_said"]

log = logging.getLogger("bmtree.coordinator")

WAKE = object()


SUCCESS_FALSE = "answered success: false"


def _unset(value: Any, depth: int = 0) -> bool:
    """An output left at its message's default (``""``, 0, an empty list, a point at 0,0,0): it says nothing."""
    if isinstance(value, dict):
        return depth < 8 and all(_unset(v, depth + 1) for v in value.values())
    return value in ("", 0, False, None, [])


def _set_part(value: Any) -> Any:
    """``value`` without the fields left at their defaults (``{"position": {"x": 1.5}}``)."""
    if isinstance(value, dict):
        return {k: _set_part(v) for k, v in value.items() if not _unset(v)}
    return value


def success_false_said(error: Any, outputs: Any, width: int = 100) -> str:
    """``error`` with the other outputs of a call that answered ``success: false`` (the original modules'
    way to say why: ``answered success: false (error_code "E42: gripper jammed")``); else ``error``."""
    if error != SUCCESS_FALSE or not isinstance(outputs, dict):
        return str(error or "")
    said = ", ".join("%s %s" % (k, json.dumps(_set_part(v), ensure_ascii=False, separators=(",", ":"), default=str))
                     for k, v in outputs.items() if k != "success" and not _unset(v))
    return "%s (%s)" % (error, said if len(said) <= width else said[:width - 1] + "…") if said else str(error)


def plain(value: Any) -> Any:
    """A ROS message as test-friendly data: one-field messages unwrap to their value, and a time or
    duration is ``{"secs": S, "nsecs": N}`` (as inside a message, and as a tree writes one; run logs
    before this recorded a ``std_msgs/Time`` as its nanoseconds in text)."""
    v = unwrap(value)
    if isinstance(v, genpy.TVal):
        return _time(v)
    if hasattr(v, "__slots__") and hasattr(v, "_type"):
        return from_message(v)
    if isinstance(v, (list, tuple)) and v and isinstance(v[0], genpy.TVal):  # a time[] field unwrapped
        return [_time(t) if isinstance(t, genpy.TVal) else t for t in v]
    return v


def _time(t: Any) -> Dict[str, int]:
    return {"secs": t.secs, "nsecs": t.nsecs}


class RecordStatus(TextEnum):
    """How a call of the tree ended: a result's status, or the coordinator's own verdict."""

    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    REJECTED = "rejected"
    CANCELLED = "cancelled"
    TIMEOUT = "timeout"            # no answer within the call's timeout
    HALTED = "halted"              # the tree stopped the call (a parent ended it)
    MODULE_LOST = "module_lost"    # the module's node died or restarted during the call


@dataclass
class CallRecord:
    """One call made by the tree, for the run report and the testing kit."""

    target: str
    call_id: str
    messages: Dict[str, Any]      # the inputs as sent (ROS messages)
    started: float
    ended: Optional[float] = None
    answered: Optional[float] = None  # when its answer came in (the tree may take it later: paused)
    status: RecordStatus = RecordStatus.RUNNING
    error: str = ""
    output_messages: Dict[str, Any] = field(default_factory=dict)   # the outputs as answered (ROS messages)
    function: Optional[FunctionDefinition] = None
    result: Optional[FunctionResult] = None
    owner: Any = None             # the behaviour that made the call
    # an answer that came after the call had ended unanswered (timed out, halted, module lost), other than
    # the ``cancelled`` that answers the coordinator's cancel: the module ran the call (or refused it) after all
    late_status: Optional[RecordStatus] = None
    late_at: Optional[float] = None   # when it came (clock time, as ``started``)
    late_error: str = ""
    late_result: Optional[FunctionResult] = None
    cancel_sent: bool = False   # the tree stopped it (halted, timed out): its module was asked to cancel it
    cancel_answer: str = ""     # the module's ``cancelled`` answer to that (its text)

    def __repr__(self) -> str:
        """What a failed ``assert run.calls(...) == ...`` shows of it: target, status, times, inputs, outputs
        or error (not its definition and ROS messages, which buried the difference)."""
        said = "%s %s at %.3fs" % (self.target, self.status, self.started)
        if self.duration is not None:
            said += " for %.3fs" % self.duration
        said += " inputs=%r" % (self.inputs,)
        if self.output_messages:
            said += " outputs=%r" % (self.outputs,)
        if self.error:
            said += " error=%r" % (self.error,)
        if self.late_status is not None:
            said += " late=%s" % self.late_status
        return "<CallRecord %s>" % said

    @property
    def maybe_running(self) -> str:
        """Why a call the tree stopped may still run on its module ('' when it is known to have ended): no
        answer to its cancel (yet: see ``TreeRunner.confirm_cancels``), or its module says its code goes on."""
        if not self.cancel_sent or self.late_status is not None:
            return ""
        if not self.cancel_answer:
            return "its module did not answer the cancel"
        if NOT_RETURNED in self.cancel_answer or NOT_STOPPED in self.cancel_answer:
            return "its module says %s" % self.cancel_answer.partition(", but ")[2]
        return ""

    @property
    def inputs(self) -> Dict[str, Any]:
        """The inputs as plain data (``{"place": "kitchen"}``), for reports and tests."""
        return {k: plain(v) for k, v in self.messages.items()}

    @property
    def outputs(self) -> Dict[str, Any]:
        """The outputs of a call that succeeded as plain data, like ``inputs`` (``{"success": True}``)."""
        return {k: plain(v) for k, v in self.output_messages.items()}

    @property
    def duration(self) -> Optional[float]:
        """From sending to the answer (to the end, for calls that ended unanswered)."""
        if self.ended is None:
            return None
        return (self.answered if self.answered is not None else self.ended) - self.started


LATE_ANSWER = "late_answer"
"""The ``what`` of the notice of a late answer (:func:`late_answer_text`)."""
STILL_RUNNING = "still_running"
"""The ``what`` of the notice of a cancel's answer saying the call may go on (``maybe_running``)."""

_ENDED: Dict[str, str] = {RecordStatus.TIMEOUT: "timed out", RecordStatus.HALTED: "halted",
                          RecordStatus.MODULE_LOST: "given up as module_lost"}
_MEANING: Dict[str, str] = {RecordStatus.SUCCEEDED: "the module did run it", RecordStatus.FAILED: "the module did run it",
                            RecordStatus.REJECTED: "the module did not run it"}


MODULE_GONE = "module_lost"
"""The ``what`` of the notice that a module a ``wait_event`` waits on is gone (:func:`gone_text`)."""


def gone_text(module: str, reason: str, events: List[str]) -> str:
    """Why no event of ``events`` (``module.event``) can come now that ``module``'s node is gone
    (``reason``: the watchdog's, which names the node): the reason of a ``wait_event`` that fails."""
    said = " or ".join(sorted(set(events)))
    if "restarted" in reason:  # a new process may send them, but one sent meanwhile is lost
        return "%s's node was restarted (%s): a %s event may have been lost meanwhile" % (module, reason, said)
    return "%s's node is gone (%s): no %s event can come" % (module, reason, said)


def late_answer_text(rec: CallRecord, start: float) -> str:
    """The notice of ``rec``'s late answer, times from the run's ``start``: ``navigation.go_to (call
    1b26…, timed out at 6.00s) answered succeeded at 7.40s: the module did run it``."""
    ended = (rec.ended if rec.ended is not None else start) - start
    at = (rec.late_at if rec.late_at is not None else start) - start
    answered = "answered %s%s" % (rec.late_status, " (%s)" % rec.late_error if rec.late_error else "")
    if rec.status == RecordStatus.HALTED:
        answered += " after it was cancelled,"
    meaning = _MEANING.get(str(rec.late_status), "")
    return "%s (call %s, %s at %.2fs) %s at %.2fs%s" % (rec.target, rec.call_id,
                                                      _ENDED.get(str(rec.status), "ended %s" % rec.status), ended,
                                                      answered, at, ": " + meaning if meaning else "")


class RunContext:
    """Shared by every behaviour of one run; only touched from the ticking thread."""

    def __init__(self, transport: Transport, clock: Clock, definitions: Mapping[str, ModuleDefinition],
                 default_timeout: float = 30.0, recall_timeout: float = 5.0,
                 observers: Optional[List[RunObserver]] = None):
        self.transport = transport
        self.clock = clock
        self.definitions = dict(definitions)
        self.default_timeout = default_timeout
        self.recall_timeout = recall_timeout
        self.blackboard: Dict[str, Any] = {}
        self.calls: List[CallRecord] = []
        self.pending: typing.OrderedDict[str, CallRecord] = OrderedDict()
        # the events received, each with the ticks done before it arrived (events with one number came
        # together, between two ticks, and a wait_event restarted by a loop takes the ones that came with
        # the one it took); only the recent ones and those a waiting wait_event has not read are kept
        self.events = Received()
        self.ticks_done = 0
        self.notices: List[Notice] = []
        self.observers: List[RunObserver] = list(observers or [])
        self.answers: Dict[str, BlackboardAnswer] = {}
        self.dropped: typing.Deque[FunctionResult] = deque(maxlen=100)  # the last results that matched no call
        self._ended: typing.OrderedDict[str, CallRecord] = OrderedDict()  # calls that ended without an answer
        self.inbox: queue.SimpleQueue = queue.SimpleQueue()  # in C: a cheap hand-off from the receiving threads
        # calls whose results the next recall must see stored: call_id -> (module.function, the
        # Blackboard names its values answer to); then, per request, the ones it asked about
        self.unstored: typing.OrderedDict[str, Tuple[str, Tuple[str, ...]]] = OrderedDict()
        self._asked: Dict[str, typing.OrderedDict[str, Tuple[str, Tuple[str, ...]]]] = {}
        self.lost: Dict[str, Tuple[str, str]] = {}  # Blackboard name -> (module.function, call_id) it lost
        self._watches: Dict[str, str] = {}  # watch key -> the module.event a wait_event waits for
        self._gone: Dict[str, str] = {}  # watch key -> why its module can send no event now
        self.started = clock.now()  # the run's start (the runner sets it at its first tick): for notice texts

    # values ------------------------------------------------------------------------
    def lookup(self, key: str) -> Any:
        if key not in self.blackboard:
            raise KeyError("tree key %r is not set" % key)
        return self.blackboard[key]

    def resolve(self, value: Any) -> Any:
        """A YAML literal with every Ref replaced by the current tree-blackboard value."""
        return resolve(value, self.lookup)

    def write(self, key: str, value: Any) -> None:
        """Set a tree-blackboard key (behaviours write only through here, so observers see it)."""
        self.blackboard[key] = value
        if self.observers:
            notify(self.observers, "on_blackboard_write", key, value, self.clock.now())

    def recalled(self, values: List[Dict[str, Any]]) -> None:
        """Tell the observers what a ``recall`` read and where it came from (see ``RunObserver.on_recall``)."""
        if self.observers:
            notify(self.observers, "on_recall", values, self.clock.now())

    def wake_after(self, delay: float) -> None:
        """Make the runner tick again after ``delay`` (timeouts, waits, retries)."""
        self.clock.call_later(delay, lambda: self.inbox.put(WAKE))

    # modules whose events are awaited --------------------------------------------------
    def watch_module(self, module: str, event: str) -> Optional[str]:
        """Have the transport watch ``module``'s node while a ``wait_event`` waits for its ``event``
        (as it watches the node of a call in flight): a key for :meth:`module_gone` and
        :meth:`unwatch`, or None when the transport cannot watch (in process: mocks do not die)."""
        key = self.transport.watch_module(module)
        if key is not None:
            self._watches[key] = "%s.%s" % (module, event)
        return key

    def unwatch(self, key: Optional[str]) -> None:
        """The wait that watched with ``key`` ended (or was halted)."""
        if key is None or self._watches.pop(key, None) is None:
            return
        self._gone.pop(key, None)
        self.transport.unwatch_module(key)

    def module_gone(self, key: Optional[str]) -> str:
        """Why the module watched with ``key`` can send no event now ('' while it can)."""
        return self._gone.get(key, "") if key is not None else ""

    # calls -------------------------------------------------------------------------
    def start_call(self, fn: FunctionDefinition, call: FunctionCall, owner: Any = None) -> CallRecord:
        rec = CallRecord(target=fn.qualified, call_id=call.call_id or "", function=fn, started=self.clock.now(),
                         messages=dict(zip(call.names or [], call.msgs)), owner=owner)
        self.calls.append(rec)
        self.pending[rec.call_id] = rec
        if self.observers:  # before sending: a record of the call precedes any of its answer
            notify(self.observers, "on_call_start", rec)
        self.transport.send_call(call)
        return rec

    def finish(self, rec: CallRecord, status: str, error: str = "") -> None:
        if rec.ended is not None:
            return
        rec.ended = self.clock.now()
        rec.status = RecordStatus(status)
        rec.error = error
        if self.pending.pop(rec.call_id, None) is not None and rec.result is None and rec.call_id:
            self._ended[rec.call_id] = rec  # ended unanswered: an answer may still come
            while len(self._ended) > 10000:
                self._ended.popitem(last=False)
        if self.observers:
            notify(self.observers, "on_call_end", rec)

    def cancel(self, rec: CallRecord, status: str = RecordStatus.HALTED, error: str = "") -> None:
        """Stop waiting for ``rec`` and ask its module to stop it."""
        if rec.ended is not None:
            return
        # a call still kept for its module's node to connect was never sent: the transport takes it back, and
        # nothing can be running it (no "may still be running: its module did not answer the cancel")
        unsent = bool(rec.call_id) and bool(self.transport.unsent_note(rec.call_id or ""))
        self.finish(rec, status, error)
        fn = rec.function
        assert fn is not None
        rec.cancel_sent = not unsent
        self.transport.send_cancel(CancelRequest(call_id=rec.call_id, basic_mod=fn.module, function=fn.name))

    def request(self, names: List[str]) -> str:
        # The Blackboard answers only once the results received since the last request are
        # committed: they reach it on another connection than the request, maybe later.
        req = BlackboardRequest(var_names=list(names), after=list(self.unstored))
        if self.unstored and req.request_id:
            self._asked[req.request_id] = self.unstored
        self.unstored = OrderedDict()
        self.transport.send_request(req)
        return req.request_id or ""

    def lost_value(self, name: str) -> str:
        """Why the Blackboard's value of ``name`` is older than the run's (``''`` when it is not):
        it did not store the result of a call that wrote it (restarted or cut off meanwhile)."""
        lost = self.lost.get(name)
        if lost is None:
            return ""
        return ("the Blackboard node did not store the result of %s (call %s) that wrote %s, so its value is an older "
                "one (was the Blackboard node restarted, or cut off from the module, while the call ran?)"
                % (lost[0], lost[1], name))

    def _confirmed(self, answer: BlackboardAnswer) -> None:
        """Which results the Blackboard stored, by the answer to a request that asked."""
        asked = self._asked.pop(answer.request_id or "", None)
        if asked is None:
            return
        if answer.error and not answer.names and not answer.missing:  # not answered: ask again next time
            asked.update(self.unstored)
            self.unstored = asked
            return
        unstored = set(answer.unstored)
        for call_id, (target, names) in asked.items():  # in the order the results came
            for name in names:
                if call_id in unstored:
                    self.lost[name] = (target, call_id)
                else:
                    self.lost.pop(name, None)

    # incoming ----------------------------------------------------------------------
    def dispatch(self, item: Any) -> None:
        if isinstance(item, FunctionResult):
            rec = self.correlate(item)
            if rec is None:
                self.dropped.append(item)
                ended = self._ended.get(item.call_id or "")
                if ended is not None:  # the answer to a cancel, or one that came too late
                    self._late(ended, item)
                    return
                log.warning("dropped a result that matches no pending call (call_id %s, module %s, function %s, "
                            "outputs %s, from node %s)", item.call_id, item.basic_mod, item.function,
                            ", ".join(item.names), item.publisher or "unknown")
                return
            self.pending.pop(rec.call_id, None)
            rec.result = item
            rec.answered = self.clock.now()
            if item.names and rec.call_id:  # an original module's result is stored under the call it answers
                fn = rec.function
                target = rec.target
                prefix = "%s/%s/" % (fn.module, fn.name) if fn is not None else ""
                self.unstored[rec.call_id] = (target, tuple(item.names) + tuple(prefix + n for n in item.names))
                while len(self.unstored) > 1000:  # a long run without recalls: the old ones are stored by now
                    self.unstored.popitem(last=False)
        elif isinstance(item, Event):
            self.events.append(item, self.ticks_done)
            if self.observers:
                notify(self.observers, "on_event", item, self.clock.now())
        elif isinstance(item, BlackboardAnswer):
            if item.request_id:
                self._confirmed(item)
                self.answers[item.request_id] = item
        elif isinstance(item, Notice):
            self.notices.append(item)
            if self.observers:
                notify(self.observers, "on_notice", item, self.clock.now())
        elif isinstance(item, ModuleLost):
            waits = []
            for call_id in item.call_ids:
                rec = self.pending.get(call_id)
                if rec is not None:
                    self.finish(rec, RecordStatus.MODULE_LOST, "module %s lost: %s" % (item.module, item.reason))
                elif call_id in self._watches:
                    waits.append(self._watches[call_id])
                    self._gone[call_id] = gone_text(item.module, item.reason, [self._watches[call_id]])
            if waits:
                self._notice(Notice(MODULE_GONE, "%s; %s" % (gone_text(item.module, item.reason, waits), (
                    "the wait_event for it fails" if len(waits) == 1 else "the %d wait_events fail" % len(waits)))))
        elif isinstance(item, BlackboardLost):
            for request_id in item.request_ids:
                lost = BlackboardAnswer(request_id=request_id, error="Blackboard node lost: %s" % item.reason)
                self._confirmed(lost)
                self.answers.setdefault(request_id, lost)

    def _late(self, rec: CallRecord, result: FunctionResult) -> None:
        """An answer to ``rec``, which had ended unanswered: ``cancelled`` answers the coordinator's cancel
        (expected); any other is kept on the record and told as a ``late_answer`` notice, since the module
        ran the call (or refused it) after all, and a ``retry`` may have sent it again meanwhile."""
        fn = rec.function
        if fn is not None and (result.basic_mod not in (None, fn.module) or result.function not in (None, fn.name)):
            log.warning("ignored a result of %s.%s carrying the id of call %s to %s", result.basic_mod,
                        result.function, result.call_id, fn.qualified)
            return
        if result.status == RecordStatus.CANCELLED and not rec.cancel_answer:
            rec.cancel_answer = result.error or "cancelled"
            if rec.maybe_running:  # in the run log and the viewers too, not only in bmtree run's summary
                ended = (rec.ended if rec.ended is not None else self.started) - self.started
                self._notice(Notice(STILL_RUNNING, "%s (call %s, %s at %.2fs) may still be running: %s" % (
                    rec.target, rec.call_id, _ENDED.get(str(rec.status), "ended %s" % rec.status), ended,
                    rec.maybe_running), rec.call_id))
        if result.status == RecordStatus.CANCELLED or rec.late_status is not None:
            log.debug("a late answer (%s) to call %s of %s, which had ended %s", result.status, result.call_id,
                      rec.target, rec.status)
            return
        rec.late_status = RecordStatus(result.status)
        rec.late_at = self.clock.now()
        rec.late_error = result.error or ""
        rec.late_result = result
        notice = Notice(LATE_ANSWER, late_answer_text(rec, self.started), rec.call_id)
        log.info("%s", notice.text)
        self._notice(notice, rec.late_at)

    def _notice(self, notice: Notice, at: Optional[float] = None) -> None:
        """A notice of the run itself, told as the transport's are (the display, the run log and stream)."""
        self.notices.append(notice)
        if self.observers:
            notify(self.observers, "on_notice", notice, self.clock.now() if at is None else at)

    def correlate(self, result: FunctionResult) -> Optional[CallRecord]:
        """The pending call a result answers (DESIGN §2, README "Correlation").

        By ``call_id`` when present (a late answer to a call that is no longer pending
        matches nothing). A result without one (an original module) belongs to the module
        it names, else to the module whose node published it (``publisher``, mapped by the
        transport); a result from a node of no module of this run matches nothing. Within
        that module (or among all pending calls when the publisher is unknown, as in
        process), it answers the oldest pending call of the function it names, else the
        oldest whose definition's output names equal the result's names; else nothing.
        """
        if result.call_id is not None:
            rec = self.pending.get(result.call_id)
            fn = rec.function if rec is not None else None
            if fn is not None and (result.basic_mod not in (None, fn.module) or result.function not in (None, fn.name)):
                log.warning("ignored a result of %s.%s carrying the id of call %s to %s", result.basic_mod,
                            result.function, result.call_id, fn.qualified)
                return None
            return rec
        module = result.basic_mod
        if module is None and result.publisher is not None:
            return None
        for rec in self.pending.values():
            fn = rec.function
            if fn is None or (module is not None and fn.module != module):
                continue
            if result.function is not None:
                if fn.name == result.function:
                    return rec
            elif [p.name for p in fn.outputs] == list(result.names) or (
                    {p.name for p in fn.outputs} == set(result.names) and len(fn.outputs) == len(result.names)):
                return rec
        return None
