"""The leaves other than ``call``: ``recall``, ``check``, ``wait_event``, ``set`` (its kind in
:mod:`coordinator.nodes.setkeys`), ``wait``."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, FrozenSet, Iterable, List, Optional

from py_trees.common import Status

from comm.errors import did_you_mean
from coordinator.errors import Pos, TreeError
from coordinator.expr import Expr, ExprError
from coordinator.exprhints import quoted_key_warnings
from coordinator.nodes.base import (
    Flow,
    NodeKind,
    Option,
    param_keys,
    param_type_errors,
    repeated_outputs,
    run_param,
)
from coordinator.nodes.leafbase import Leaf
from coordinator.nodes.loops import expr_option, expr_type_errors
from coordinator.nodes.setkeys import SetKeys, SetKind
from coordinator.nodes.timeouts import NO_TIMEOUT, long_seconds, timeout_option, with_no_timeout
from coordinator.refs import RefError
from coordinator.statusflow import SUCCEEDED, sure_when_status
from coordinator.treeast import TreeNode
from coordinator.values import KeyTypes, expr_errors, read_at

__all__ = ["Check", "KINDS", "Recall", "SetKeys", "Wait", "WaitEvent"]

_WRITES_NOTHING: FrozenSet[str] = frozenset()
_RECALL_HOW = "a recall always has a time limit (by default 5 s): give seconds (> 0), or leave it out for 5 s"
_WAIT_EVENT_HOW = ("wait_event waits without a time limit by default: leave timeout out, or write 'timeout: none', "
                   "for no limit; else give seconds (> 0)")


# recall -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class RecallSpec:
    names: Dict[str, str]             # tree key -> Blackboard name
    timeout: Optional[float] = None
    types: Dict[str, str] = field(default_factory=dict)   # tree key -> the ROS type of its output, when known
    timeout_pos: Optional[Pos] = None


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
        if self.ctx.observers:  # a run log keeps where each value came from (an earlier run, or this one)
            at = {n: i for i, n in reversed(list(enumerate(ans.names)))}
            self.ctx.recalled([dict(
                ans.sources[at[name]] if at[name] < len(ans.sources) else {}, key=key, name=name,
                rostype=ans.rostypes[at[name]], value=values[name]) for key, name in self.node.spec.names.items()])
        for key, name in self.node.spec.names.items():
            self.ctx.write(key, values[name])
        return Status.SUCCESS


class RecallKind(NodeKind):
    name = "recall"
    family = "leaf"
    value = ("recall", "tree key → Blackboard name (`name` or `module/function/name`)")
    summary = "ask the Blackboard node for the latest values; FAILURE names the missing ones"
    options = (Option("timeout", "seconds", "seconds (a recall always has a limit: no `none`)", shown="`5`"),)
    uses_blackboard_node = True
    lasts = "a recall waits for the Blackboard node's answer"

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> RecallSpec:
        timeout = timeout_option(p, node, raw, self.option("timeout"), "recall", _RECALL_HOW, unlimited=False)
        m = p.keys(node, value, at, "tree key: blackboard name")
        names = {}
        types = {}
        for k, v in (m or {}).items():
            parts = v.split("/") if isinstance(v, str) else []
            if len(parts) not in (1, 3) or not all(parts):
                p.err(m.val_pos[k], "blackboard name %r must be 'name' or 'module/function/name'" % (v,))
                continue
            names[k] = v
            rostype = _recalled_type(p, parts, m.val_pos[k]) if p.definitions else None
            if rostype is not None:
                types[k] = rostype
        return RecallSpec(names, timeout, types, raw.val_pos["timeout"] if "timeout" in raw else None)

    def default_name(self, node: TreeNode) -> str:
        return "recall %s" % ", ".join(node.spec.names.values())

    def reads(self, node: TreeNode) -> Iterable[str]:
        return param_keys(node.spec.timeout)

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        types = node.spec.types
        return {k: types.get(k) for k in node.spec.names}

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        param_type_errors(node.spec.timeout, node.spec.timeout_pos, types, "seconds", "timeout of recall", errors)

    leaf = Recall


def _recalled_type(p: Any, parts: List[str], at: Pos) -> Optional[str]:
    """The ROS type of the output a Blackboard name stands for, when the definitions say, after reporting a
    name that cannot be stored: ``module/function/output`` of a module whose definition is loaded must
    name one of its functions and one of that function's outputs (an error); a module without a
    definition here may still store values (a warning only when its name is close to a known module's:
    likely misspelt); a plain ``output`` not among the outputs of any known function is likely misspelt,
    or stored by a module whose definition is not given (a warning)."""
    defs = p.definitions
    name = "/".join(parts)
    if len(parts) == 3:
        mod_name, fname, out = parts
        mod = defs.get(mod_name)
        if mod is None:
            close = did_you_mean(mod_name, defs)
            if close:
                p.warn(at, "recall of %r: no definition of module %r is loaded%s: the recall finds it only if a "
                           "module of that name stored it" % (name, mod_name, close))
            return None
        fn = mod.functions.get(fname)
        if fn is None:
            p.err(at, "blackboard name %r: %s" % (name, mod.no_function(fname)))
            return None
        outputs = {q.name: q for q in fn.outputs}
        if out not in outputs:
            p.err(at, "blackboard name %r: %s has no output %r%s" % (
                name, fn.qualified, out, did_you_mean(out, outputs) or " (outputs: %s)"
                % (", ".join(outputs) or "none")))
            return None
        return outputs[out].rostype
    out = parts[0]
    known = {q.name for mod in defs.values() for fn in mod.functions.values() for q in fn.outputs}
    if out not in known:
        p.warn(at, "recall of %r: no function of the known modules (%s) has an output %r%s" % (
            name, ", ".join(sorted(defs)), out, did_you_mean(out, known)
            or ": the recall finds it only if a module whose definition is not given stored it"))
    return None   # the latest value of any module's output of that name: its type is not known


# check ------------------------------------------------------------------------------------
def _status_compared(tree: Any) -> str:
    """``KEY`` of an expression ``KEY == "succeeded"`` (either way round), else ''."""
    if tree[0] != "cmp" or tree[1] != "==":
        return ""
    for ref, text in ((tree[2], tree[3]), (tree[3], tree[2])):
        if ref[0] == "ref" and not ref[1].path and text[0] == "lit" and text[1] == SUCCEEDED:
            return str(ref[1].key)
    return ""


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
        return self._fail("%s is false%s" % (expr.text, expr.values_read(self.ctx.lookup)))


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
        """The base's flow, in one call (checks are many): a check reads keys and writes none; but
        ``check: 'found == "succeeded"'`` on a call's status key passes only after that call succeeded,
        so the nodes after it may read its outputs (:mod:`coordinator.statusflow`)."""
        if node.spec is None or not node.spec.keys:
            return _WRITES_NOTHING
        f.need(node, node.spec.keys, avail)
        key = _status_compared(node.spec.tree)
        return sure_when_status(f, key, [SUCCEEDED]) if key else _WRITES_NOTHING

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        errors.extend(quoted_key_warnings(node.spec, node.value_pos, types))
        if node.spec is not None and not node.spec.well_typed:
            found = expr_errors(node.spec, types)
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
    timeout_pos: Optional[Pos] = None
    where: Optional[Expr] = None      # over the event's params, by their names (and tree keys)
    where_pos: Optional[Pos] = None
    where_keys: FrozenSet[str] = frozenset()   # the names ``where`` reads that are no param: tree keys


class WaitEvent(Leaf):
    """SUCCESS at the first ``module.event`` that arrives after the leaf starts (and satisfies ``where``:
    the others are skipped).

    Events that arrive together (between two ticks) are one moment for the tree: started again
    (by a loop) after taking one of them, the leaf first takes the others of that moment, in their
    order, so that ``repeat … until`` over it sees each one (two people seen at once). While it waits,
    the run watches the module's node as a call's: once that node is gone, it fails (no event can come)."""

    took: Optional[int] = None   # the index of the event the last run took
    watch: Optional[str] = None  # the run's watch on the module's node while it waits

    def initialise(self) -> None:
        self.ctx.unwatch(self.watch)   # (a watch left by a run that was not terminated)
        ev_def = self.node.spec.event
        self.watch = self.ctx.watch_module(ev_def.module, ev_def.name) if ev_def is not None else None
        events = self.ctx.events
        self.seen = len(events)
        took, self.took = self.took, None
        self.together = [] if took is None or not events.kept(took) else [
            j for j in range(took + 1, self.seen) if events.tick_of(j) == events.tick_of(took)]
        events.read_from(self, self.together[0] if self.together else self.seen)
        self.timeout, self.reason = run_param(self.node.spec.timeout, self.ctx.lookup, "seconds",
                                              "timeout of wait_event")
        self.deadline = None if self.timeout is None else self.ctx.clock.now() + self.timeout
        self.skipped = 0
        if self.timeout is not None:
            self.ctx.wake_after(self.timeout)

    def update(self) -> Status:
        if self.reason:
            return self._fail(self.reason)
        ev_def, where = self.node.spec.event, self.node.spec.where
        events = self.ctx.events
        while self.together or self.seen < len(events):
            if self.together:
                index = self.together.pop(0)
            else:
                index = self.seen
                self.seen += 1
            ev = events[index]
            if ev.basic_mod == ev_def.module and ev.event == ev_def.name:
                values = ev.values
                if where is not None:   # over its params (a later event may satisfy it)
                    try:
                        if not where.evaluate(self._names(values)):
                            self.skipped += 1
                            continue
                    except (KeyError, RefError) as exc:
                        why = exc.args[0] if not isinstance(exc, KeyError) else (
                            "the tree key %s has no value" if exc.args[0] in self.node.spec.where_keys
                            else "the event has no param %s") % exc
                        return self._fail("where %s: %s" % (where.text, why))
                for param, key in self.node.spec.outputs.items():
                    if param in values:
                        self.ctx.write(key, values[param])
                self.took = index
                return Status.SUCCESS
        events.read_from(self, self.seen)   # all read: the older ones may go
        gone = self.ctx.module_gone(self.watch)
        if gone:   # after the events that came before: one sent before it died is still taken
            return self._fail(gone)
        if self.deadline is not None and self.ctx.clock.now() >= self.deadline:
            return self._fail("no %s.%s%s within %gs%s" % (
                ev_def.module, ev_def.name, " where %s" % where.text if where is not None else "", self.timeout,
                " (%d skipped)" % self.skipped if self.skipped else ""))
        return Status.RUNNING

    def _names(self, values: Dict[str, Any]) -> Any:
        """What ``where`` reads a name as: the event's param, else (no param of it) the tree key."""
        keys = self.node.spec.where_keys
        return lambda k: self.ctx.lookup(k) if k in keys else values[k]

    def terminate(self, new_status: Status) -> None:
        """Ended or halted: its module's node is no longer watched for it, nor events kept for it."""
        self.ctx.unwatch(self.watch)
        self.ctx.events.done(self)
        self.watch = None


def _where_types(spec: WaitEventSpec, types: Dict[str, set]) -> KeyTypes:
    """What ``where`` reads each name as, for its checks: the event's param, else the tree key (its kinds too)."""
    keys = spec.where_keys
    out = KeyTypes({k: types[k] for k in keys if k in types})
    out.kinds = {k: v for k, v in getattr(types, "kinds", {}).items() if k in keys}
    why_not = getattr(types, "why_not", None)
    if why_not is not None:
        out.why_not = lambda key, text, contains: why_not(key, text, contains) if key in keys else ""
    out.update({q.name: {q.rostype} for q in spec.event.params})
    return out


class WaitEventKind(NodeKind):
    name = "wait_event"
    family = "leaf"
    value = ("event", "`module.event`")
    summary = "SUCCESS at the first matching event that arrives after the leaf starts"
    options = (Option("outputs", "outputs", "event param → tree key"),
               Option("timeout", "seconds", "seconds, or `none`: no limit, as when left out (it still fails when "
                                            "its module is lost)", shown="none"),
               Option("where", "expr", "an expression over the event's params, by their names (`person == "
                                       "\"Ana\"`), and tree keys (a name that is no param: `person == guest`): "
                                       "the first event for which it is true is taken, the others skipped"))
    lasts = "a wait_event waits for its event"

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> WaitEventSpec:
        timeout = timeout_option(p, node, raw, self.option("timeout"), "wait_event", _WAIT_EVENT_HOW)
        if isinstance(timeout, str) and timeout == NO_TIMEOUT:
            timeout = None   # no limit, as when left out
        spec = WaitEventSpec(target=value, timeout=timeout,
                             timeout_pos=raw.val_pos["timeout"] if "timeout" in raw else None)
        if "where" in raw:
            spec.where, spec.where_pos = expr_option(p, raw, "where"), raw.val_pos["where"]
        found = p.target(node, value, at, "event")
        ev = None
        if found is not None:
            mod, ename = found
            ev = mod.events.get(ename)
            if ev is None:
                p.err(at, "module %r has no event %r%s" % (mod.name, ename, did_you_mean(ename, mod.events)
                                                           or " (events: %s)" % (", ".join(mod.events) or "none")))
        if ev is None:   # (already an error) its outputs still write their keys: no knock-on errors where read
            spec.outputs = p.key_map(node, raw, "outputs", None, "event param")
            return spec
        spec.event = ev
        spec.outputs = p.key_map(node, raw, "outputs", {q.name: q for q in ev.params}, "event param")
        repeated_outputs(p, raw, spec.outputs)
        if spec.where is not None and spec.where_pos is not None:   # its names: params first, then tree keys
            at = spec.where_pos
            params = [q.name for q in ev.params]
            keys = set()
            for ref, off in zip(spec.where.refs, spec.where.ref_offsets):
                if ref.key in params:
                    continue
                close = did_you_mean(ref.key, params)
                if close:   # a misspelt param rather than a tree key
                    p.err(Pos(at.file, at.line, at.column + off), "where reads %r, which is no param of %s.%s%s" % (
                        ref.key, mod.name, ename, close))
                else:
                    keys.add(ref.key)
            spec.where_keys = frozenset(keys)
        return spec

    def default_name(self, node: TreeNode) -> str:
        return str(node.spec.target)

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        types = {q.name: q.rostype for q in node.spec.event.params} if node.spec.event is not None else {}
        return {key: types.get(param) for param, key in node.spec.outputs.items()}

    def reads(self, node: TreeNode) -> Iterable[str]:
        return param_keys(node.spec.timeout) + sorted(node.spec.where_keys)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        s = node.spec
        if key in s.where_keys and s.where is not None and s.where_pos is not None:
            return read_at(s.where, s.where_pos, key)
        return read_at(s.timeout, s.timeout_pos, key) if s.timeout_pos is not None else None

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        spec = node.spec
        param_type_errors(spec.timeout, spec.timeout_pos, types, "seconds", "timeout of wait_event", errors)
        if spec.where is not None and spec.event is not None:   # a param's type, else the tree key's
            expr_type_errors(spec.where, spec.where_pos, _where_types(spec, types), errors)
            errors.extend(quoted_key_warnings(spec.where, spec.where_pos, types))

    def schema(self) -> Dict[str, Any]:
        return with_no_timeout(super().schema())

    def modules(self, node: TreeNode) -> Iterable[str]:
        t = node.spec.target
        return [t.split(".")[0]] if isinstance(t, str) and "." in t else []

    leaf = WaitEvent


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
    lasts = "a wait waits its seconds"

    def lasting(self, node: TreeNode) -> str:
        return "" if node.spec == 0 and isinstance(node.spec, (int, float)) else self.lasts

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> Optional[float]:
        seconds = p.typed(node, self.label, value, at, self.value[0])
        long_seconds(p, seconds, at, "duration of wait")
        return seconds

    def default_name(self, node: TreeNode) -> str:
        seconds = node.spec   # a number: 'wait 5s'; a reference or an expression as written: 'wait $pause'
        return "wait %ss" % seconds if isinstance(seconds, (int, float)) else "wait %s" % seconds

    def reads(self, node: TreeNode) -> Iterable[str]:
        return param_keys(node.spec)

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        param_type_errors(node.spec, lambda: node.value_pos or node.pos, types, "seconds0", "duration of wait",
                          errors)

    leaf = Wait


KINDS = (RecallKind(), CheckKind(), WaitEventKind(), SetKind(), WaitKind())
