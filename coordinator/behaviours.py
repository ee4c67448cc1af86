"""The leaves and the clock-aware decorators that YAML nodes become.

Leaves never block: they send, return RUNNING, and look at what the runner has
dispatched into the run context on later ticks. Halting a running ``call`` leaf
(a higher-priority branch won, a timeout fired) sends a cancel.
"""
from __future__ import annotations

from typing import Any, Dict, Optional

import py_trees
from py_trees.common import Status

from comm.errors import ProtocolError
from comm.messages import FunctionCall, new_id
from coordinator.context import CallRecord, RunContext
from coordinator.expr import ExprError, unwrap
from coordinator.treeast import Node, refs_in

__all__ = ["Call", "Recall", "Check", "WaitEvent", "SetKeys", "Wait", "Timeout", "Retry", "Repeat", "Leaf"]


class Leaf(py_trees.behaviour.Behaviour):
    """A leaf built from a YAML node (``node.pos`` says where it was written)."""

    def __init__(self, node: Node, ctx: RunContext):
        super().__init__(node.name)
        self.node = node
        self.ctx = ctx
        self.reason = ""

    def _fail(self, reason: str) -> Status:
        self.reason = reason
        self.feedback_message = reason
        return Status.FAILURE


class Call(Leaf):
    """Call ``module.function``; SUCCESS when it succeeds (and ``success`` is not false)."""

    def __init__(self, node: Node, ctx: RunContext):
        super().__init__(node, ctx)
        # Inputs without references are the same on every call: convert them once (they were
        # validated with the tree, so this cannot fail).
        fn = node.opts["function"]
        self._static = None if refs_in(node.opts["inputs"]) else fn.convert_inputs(node.opts["inputs"])

    def initialise(self) -> None:
        self.reason = ""
        self.feedback_message = ""
        self.record: Optional[CallRecord] = None
        o = self.node.opts
        self.timeout = o.get("timeout") or self.ctx.default_timeout
        fn = o["function"]
        try:
            if self._static is not None:
                call = FunctionCall(fn.module, fn.name, list(self._static), [p.name for p in fn.inputs], new_id())
            else:
                call = fn.build_call(self.ctx.resolve(o["inputs"]))
        except (KeyError, ExprError, ProtocolError) as exc:
            self.reason = "cannot build the call: %s" % (exc.args[0] if exc.args else exc)
            return
        self.record = self.ctx.start_call(fn, call)
        self.deadline = self.ctx.clock.now() + self.timeout
        self.ctx.wake_after(self.timeout)
        self.feedback_message = "waiting for %s" % fn.qualified

    def update(self) -> Status:
        rec = self.record
        if rec is None:
            return self._fail(self.reason)
        result = rec.result
        if result is None:
            if rec.ended is not None:
                return self._fail(rec.error or rec.status)
            if self.ctx.clock.now() >= self.deadline:
                self.ctx.cancel(rec, "timeout", "no answer within %gs" % self.timeout)
                return self._fail("%s: no answer within %gs" % (rec.target, self.timeout))
            return Status.RUNNING
        fn = rec.function
        assert fn is not None
        if result.status != "succeeded":
            self.ctx.finish(rec, result.status, result.error)
            return self._fail("%s %s: %s" % (rec.target, result.status, result.error))
        try:
            fn.check_result(result)
        except ProtocolError as exc:
            self.ctx.finish(rec, "failed", str(exc))
            return self._fail("%s answered outputs that break its definition: %s" % (rec.target, exc))
        values = result.values
        rec.outputs = {k: v for k, v in values.items()}
        if self.node.opts.get("check_success", True) and "success" in values and unwrap(values["success"]) is False:
            self.ctx.finish(rec, "failed", "answered success: false")
            return self._fail("%s answered success: false" % rec.target)
        self.ctx.finish(rec, "succeeded")
        self.feedback_message = "succeeded in %.3fs" % (rec.duration or 0.0)
        for out, key in self.node.opts.get("outputs", {}).items():
            self.ctx.blackboard[key] = values[out]
        return Status.SUCCESS

    def terminate(self, new_status: Status) -> None:
        rec = getattr(self, "record", None)
        if new_status == Status.INVALID and rec is not None and rec.ended is None:
            self.ctx.cancel(rec, "halted", "halted by the tree")


class Recall(Leaf):
    """Copy values from the Blackboard node into tree keys; FAILURE names what is missing."""

    def initialise(self) -> None:
        self.reason = ""
        names = self.node.opts["names"]
        self.request_id = self.ctx.request(list(names.values()))
        self.timeout = self.node.opts.get("timeout") or self.ctx.recall_timeout
        self.deadline = self.ctx.clock.now() + self.timeout
        self.ctx.wake_after(self.timeout)

    def update(self) -> Status:
        ans = self.ctx.answers.pop(self.request_id, None)
        if ans is None:
            if self.ctx.clock.now() >= self.deadline:
                return self._fail("no answer from the Blackboard node within %gs" % self.timeout)
            return Status.RUNNING
        if ans.missing or ans.error:
            return self._fail("the Blackboard has no %s%s" % (", ".join(ans.missing), "; " + ans.error if ans.error else ""))
        values = ans.values
        for key, name in self.node.opts["names"].items():
            self.ctx.blackboard[key] = values[name]
        return Status.SUCCESS


class Check(Leaf):
    def update(self) -> Status:
        try:
            ok = self.node.opts["expr"].evaluate(self.ctx.lookup)
        except (KeyError, ExprError) as exc:
            return self._fail(str(exc.args[0] if exc.args else exc))
        if ok:
            return Status.SUCCESS
        return self._fail("%s is false" % self.node.opts["expr"].text)


class WaitEvent(Leaf):
    """SUCCESS at the first ``module.event`` that arrives after the leaf starts."""

    def initialise(self) -> None:
        self.seen = len(self.ctx.events)
        self.timeout = self.node.opts.get("timeout")
        self.deadline = None if self.timeout is None else self.ctx.clock.now() + self.timeout
        if self.timeout is not None:
            self.ctx.wake_after(self.timeout)

    def update(self) -> Status:
        ev_def = self.node.opts["event"]
        events = self.ctx.events
        while self.seen < len(events):
            ev = events[self.seen]
            self.seen += 1
            if ev.basic_mod == ev_def.module and ev.event == ev_def.name:
                values = ev.values
                for param, key in self.node.opts.get("outputs", {}).items():
                    if param in values:
                        self.ctx.blackboard[key] = values[param]
                return Status.SUCCESS
        if self.deadline is not None and self.ctx.clock.now() >= self.deadline:
            return self._fail("no %s.%s within %gs" % (ev_def.module, ev_def.name, self.timeout))
        return Status.RUNNING


class SetKeys(Leaf):
    def update(self) -> Status:
        try:
            values: Dict[str, Any] = self.ctx.resolve(self.node.opts["values"])
        except (KeyError, ExprError) as exc:
            return self._fail(str(exc.args[0] if exc.args else exc))
        self.ctx.blackboard.update(values)
        return Status.SUCCESS


class Wait(Leaf):
    def initialise(self) -> None:
        self.end = self.ctx.clock.now() + self.node.opts["seconds"]
        self.ctx.wake_after(self.node.opts["seconds"])

    def update(self) -> Status:
        return Status.SUCCESS if self.ctx.clock.now() >= self.end else Status.RUNNING


class Timeout(py_trees.decorators.Decorator):
    """FAILURE (and the child halted) when the child runs longer than ``duration`` on the run's clock."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, duration: float, ctx: RunContext):
        super().__init__(name=name, child=child)
        self.duration = duration
        self.ctx = ctx

    def initialise(self) -> None:
        self.deadline = self.ctx.clock.now() + self.duration
        self.ctx.wake_after(self.duration)

    def update(self) -> Status:
        status = self.decorated.status
        if status == Status.RUNNING and self.ctx.clock.now() >= self.deadline:
            self.feedback_message = "timed out after %gs" % self.duration
            return Status.FAILURE
        return status


class _Rerun(py_trees.decorators.Decorator):
    """Run the child again, at most ``times`` runs in all, while it ends in ``again``;
    ticks again at once instead of waiting for the next period."""

    again = Status.FAILURE

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, times: int, ctx: RunContext):
        super().__init__(name=name, child=child)
        self.times = times
        self.ctx = ctx

    def initialise(self) -> None:
        self.runs = 0

    def update(self) -> Status:
        if self.decorated.status == self.again:
            self.runs += 1
            if self.runs < self.times:
                self.feedback_message = "run %d of %d ended in %s" % (self.runs, self.times, self.again.value)
                self.decorated.stop(Status.INVALID)
                self.ctx.wake_after(0.0)
                return Status.RUNNING
        return self.decorated.status


class Retry(_Rerun):
    """Re-run a failing child up to ``times`` attempts in all."""

    again = Status.FAILURE


class Repeat(_Rerun):
    """Run a child ``times`` times in a row; FAILURE as soon as it fails."""

    again = Status.SUCCESS
