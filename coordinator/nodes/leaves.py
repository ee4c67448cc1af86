"""The leaves other than ``call``: ``recall``, ``check``, ``wait_event``, ``set``, ``wait``."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, FrozenSet, Iterable, List, Optional

from py_trees.common import Status

from comm.errors import did_you_mean
from coordinator.errors import Pos, TreeError
from coordinator.expr import Expr, ExprError
from coordinator.nodes.base import Flow, NodeKind, Option, param_keys, run_param
from coordinator.nodes.leafbase import Leaf
from coordinator.refs import RefError, refs_in, resolve
from coordinator.treeast import TreeNode
from coordinator.values import read_at, ref_kind, value_type_errors

__all__ = ["Check", "KINDS", "Recall", "SetKeys", "Wait", "WaitEvent"]

_WRITES_NOTHING: FrozenSet[str] = frozenset()


# recall -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class RecallSpec:
    names: Dict[str, str]             # tree key -> Blackboard name
    timeout: Optional[float] = None


class Recall(Leaf):
    """Copy values from the Blackboard node into tree keys; FAILURE names what is missing."""

    def initialise(self) -> None:
        self.reason = ""
        self.timeout, self.reason = run_param(self.node.spec.timeout, self.ctx.lookup, "seconds", "timeout of recall")
        if self.reason:
            return
        self.timeout = self.timeout or self.ctx.recall_timeout
        self.request_id = self.ctx.request(list(self.node.spec.names.values()))
        self.deadline = self.ctx.clock.now() + self.timeout
        self.ctx.wake_after(self.timeout)

    def update(self) -> Status:
        if self.reason:
            return self._fail(self.reason)
        ans = self.ctx.answers.pop(self.request_id, None)
        if ans is None:
            if self.ctx.clock.now() >= self.deadline:
                return self._fail("no answer from the Blackboard node within %gs" % self.timeout)
            return Status.RUNNING
        if ans.error and not ans.missing:
            return self._fail(ans.error)
        stale = [why for why in map(self.ctx.lost_value, self.node.spec.names.values()) if why]
        if stale:
            return self._fail("; ".join(stale))
        if ans.missing or ans.error:
            return self._fail("the Blackboard has no %s%s" % (", ".join(ans.missing), "; " + ans.error if ans.error else ""))
        values = ans.values
        for key, name in self.node.spec.names.items():
            self.ctx.write(key, values[name])
        return Status.SUCCESS


class RecallKind(NodeKind):
    name = "recall"
    family = "leaf"
    value = ("recall", "tree key → Blackboard name (`name` or `module/function/name`)")
    summary = "ask the Blackboard node for the latest values; FAILURE names the missing ones"
    options = (Option("timeout", "seconds", "seconds", shown="`5`"),)
    uses_blackboard_node = True

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> RecallSpec:
        timeout = p.opt(node, raw, self.option("timeout"))
        m = p.keys(node, value, at, "tree key: blackboard name")
        names = {}
        for k, v in (m or {}).items():
            parts = v.split("/") if isinstance(v, str) else []
            if len(parts) not in (1, 3) or not all(parts):
                p.err(m.val_pos[k], "blackboard name %r must be 'name' or 'module/function/name'" % (v,))
            else:
                names[k] = v
        return RecallSpec(names, timeout)

    def default_name(self, node: TreeNode) -> str:
        return "recall %s" % ", ".join(node.spec.names.values())

    def reads(self, node: TreeNode) -> Iterable[str]:
        return param_keys(node.spec.timeout)

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        return dict.fromkeys(node.spec.names)

    leaf = Recall


# check ------------------------------------------------------------------------------------
class Check(Leaf):
    def update(self) -> Status:
        expr = self.node.spec
        if expr is None:
            return self._fail("no expression")
        try:
            ok = expr.evaluate(self.ctx.lookup)
        except (KeyError, RefError) as exc:
            return self._fail(str(exc.args[0] if exc.args else exc))
        if ok:
            return Status.SUCCESS
        return self._fail("%s is false" % expr.text)


class CheckKind(NodeKind):
    name = "check"
    family = "leaf"
    value = ("expr", "an expression (below)")
    summary = "SUCCESS when the expression on tree keys is true, else FAILURE with the reason"
    parse_without_pos = True

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Optional[Pos]) -> Optional[Expr]:
        if not isinstance(value, str) or not value.strip():
            p.err(at or node.value_pos, "check takes an expression string, e.g. 'answer == \"yes\"'")
            return None
        try:
            return Expr.parse(value)
        except ExprError as exc:
            # the column of the offending token, when the value is a plain one-line scalar
            at = at or node.value_pos
            p.err(Pos(at.file, at.line, at.column + exc.offset), "bad expression: %s" % exc)
            return None

    def default_name(self, node: TreeNode) -> str:
        return "check %s" % (node.spec.text if node.spec is not None else "?")

    def reads(self, node: TreeNode) -> Iterable[str]:
        return node.spec.keys if node.spec is not None else ()

    def flow(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> FrozenSet[str]:
        """The base's flow, in one call (checks are many): a check reads keys and writes none."""
        if node.spec is not None and node.spec.keys:
            f.need(node, node.spec.keys, avail)
        return _WRITES_NOTHING

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        if node.spec is not None and not node.spec.well_typed:
            found = node.spec.type_errors(lambda r: ref_kind(types, r))
            at = node.value_pos if found else None   # a Pos made only when needed
            for off, msg in found if at is not None else ():
                errors.append(TreeError(Pos(at.file, at.line, at.column + off), msg))

    leaf = Check


# wait_event -------------------------------------------------------------------------------
@dataclass
class WaitEventSpec:
    target: Any
    event: Any = None                 # EventDefinition
    outputs: Dict[str, str] = field(default_factory=dict)
    timeout: Optional[float] = None


class WaitEvent(Leaf):
    """SUCCESS at the first ``module.event`` that arrives after the leaf starts."""

    def initialise(self) -> None:
        self.seen = len(self.ctx.events)
        self.timeout, self.reason = run_param(self.node.spec.timeout, self.ctx.lookup, "seconds",
                                              "timeout of wait_event")
        self.deadline = None if self.timeout is None else self.ctx.clock.now() + self.timeout
        if self.timeout is not None:
            self.ctx.wake_after(self.timeout)

    def update(self) -> Status:
        if self.reason:
            return self._fail(self.reason)
        ev_def = self.node.spec.event
        events = self.ctx.events
        while self.seen < len(events):
            ev = events[self.seen]
            self.seen += 1
            if ev.basic_mod == ev_def.module and ev.event == ev_def.name:
                values = ev.values
                for param, key in self.node.spec.outputs.items():
                    if param in values:
                        self.ctx.write(key, values[param])
                return Status.SUCCESS
        if self.deadline is not None and self.ctx.clock.now() >= self.deadline:
            return self._fail("no %s.%s within %gs" % (ev_def.module, ev_def.name, self.timeout))
        return Status.RUNNING


class WaitEventKind(NodeKind):
    name = "wait_event"
    family = "leaf"
    value = ("event", "`module.event`")
    summary = "SUCCESS at the first matching event that arrives after the leaf starts"
    options = (Option("outputs", "outputs", "event param → tree key"),
               Option("timeout", "seconds", "seconds", shown="none"))

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> WaitEventSpec:
        spec = WaitEventSpec(target=value, timeout=p.opt(node, raw, self.option("timeout")))
        found = p.target(node, value, at, "event")
        if found is None:
            return spec
        mod, ename = found
        ev = mod.events.get(ename)
        if ev is None:
            p.err(at, "module %r has no event %r%s" % (mod.name, ename, did_you_mean(ename, mod.events)
                                                       or " (events: %s)" % (", ".join(mod.events) or "none")))
            return spec
        spec.event = ev
        spec.outputs = p.key_map(node, raw, "outputs", {q.name: q for q in ev.params}, "event param")
        return spec

    def default_name(self, node: TreeNode) -> str:
        return str(node.spec.target)

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        types = {q.name: q.rostype for q in node.spec.event.params} if node.spec.event is not None else {}
        return {key: types.get(param) for param, key in node.spec.outputs.items()}

    def reads(self, node: TreeNode) -> Iterable[str]:
        return param_keys(node.spec.timeout)

    def modules(self, node: TreeNode) -> Iterable[str]:
        t = node.spec.target
        return [t.split(".")[0]] if isinstance(t, str) and "." in t else []

    leaf = WaitEvent


# set --------------------------------------------------------------------------------------
class SetKeys(Leaf):
    def update(self) -> Status:
        try:
            values: Dict[str, Any] = resolve(self.node.spec, self.ctx.lookup)
        except (KeyError, RefError) as exc:
            return self._fail(str(exc.args[0] if exc.args else exc))
        for k, v in values.items():
            self.ctx.write(k, v)
        return Status.SUCCESS


class SetSpec(dict):
    """Tree key -> value, with where each value is written (``pos``)."""

    pos: Dict[str, Pos] = {}


class SetKind(NodeKind):
    name = "set"
    family = "leaf"
    value = ("values", "tree key → value")
    summary = "write values (literals, `$references`, `$( … )` expressions, `{…}` templates) to tree keys"

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> Dict[str, Any]:
        m = p.keys(node, value, at, "tree key: value")
        spec = SetSpec((k, p.literal_at(m, k, at)) for k in (m or {}))
        spec.pos = {k: m.val_pos[k] for k in (m or {})}
        return spec

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        for k, v in node.spec.items():
            at = getattr(node.spec, "pos", {}).get(k, node.pos)
            for off, msg in value_type_errors(v, types):
                errors.append(TreeError(Pos(at.file, at.line, at.column + off), msg))

    def default_name(self, node: TreeNode) -> str:
        return "set %s" % ", ".join(node.spec)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        where = getattr(node.spec, "pos", {})
        return next((p for p in (read_at(v, where[k], key) for k, v in node.spec.items() if k in where)
                     if p is not None), None)

    def reads(self, node: TreeNode) -> Iterable[str]:
        return [r.key for r in refs_in(node.spec)]

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        return dict.fromkeys(node.spec)

    leaf = SetKeys


# wait -------------------------------------------------------------------------------------
class Wait(Leaf):
    def initialise(self) -> None:
        seconds, self.reason = run_param(self.node.spec, self.ctx.lookup, "seconds0", "duration of wait")
        if self.reason:
            return
        self.end = self.ctx.clock.now() + seconds
        self.ctx.wake_after(seconds)

    def update(self) -> Status:
        if self.reason:
            return self._fail(self.reason)
        return Status.SUCCESS if self.ctx.clock.now() >= self.end else Status.RUNNING


class WaitKind(NodeKind):
    name = "wait"
    family = "leaf"
    value = ("seconds0", "seconds (≥ 0)")
    label = "duration"
    summary = "RUNNING for N seconds, then SUCCESS"

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> Optional[float]:
        return p.typed(node, self.label, value, at, self.value[0])

    def default_name(self, node: TreeNode) -> str:
        return "wait %ss" % node.spec

    def reads(self, node: TreeNode) -> Iterable[str]:
        return param_keys(node.spec)

    leaf = Wait


KINDS = (RecallKind(), CheckKind(), WaitEventKind(), SetKind(), WaitKind())
