"""``call``: call a module function, its inputs checked and converted once, when the tree loads.

Its ``status`` and ``error`` options write how the call ended (succeeded or not) to tree keys, for a
``switch`` to route on; ``timeout: none`` waits as long as it takes."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, FrozenSet, Iterable, List, Optional, Tuple

import py_trees
from py_trees.common import Status
from std_msgs.msg import String

from comm.errors import ProtocolError, did_you_mean
from comm.messages import FunctionCall, new_id
from comm.rostypes import resolve_type
from comm.typewords import ValueMisfit, misfit_text, said_of, type_words
from coordinator.context import SUCCESS_FALSE, CallRecord, RecordStatus, success_false_said
from coordinator.errors import Pos, TreeError
from coordinator.keykinds import kind_misfit
from coordinator.nodes.base import (
    Flow,
    NodeKind,
    Option,
    param_keys,
    param_type_errors,
    repeated_outputs,
    run_param,
    where,
)
from coordinator.nodes.leafbase import Leaf
from coordinator.nodes.timeouts import NO_TIMEOUT, timeout_option, with_no_timeout
from coordinator.refs import Ref, RefError, refs_in, resolve, unwrap
from coordinator.treeast import TreeNode
from coordinator.values import (
    Template,
    read_at,
    ref_type,
    template_fix,
    template_hint,
    templates_as_text,
    value_type_errors,
)
from coordinator.yamlsrc import bool_hint, pos_of
from modules.definition import FunctionDefinition

__all__ = ["Call", "CallSpec", "KINDS", "NOT_SENT", "NO_TIMEOUT", "STATUS_TEXTS"]

NOT_SENT = "not_sent"
"""The status of a call that could not be built (an input's reference unset, a bad value): never sent."""
STATUS_TEXTS: Tuple[str, ...] = tuple(s.value for s in RecordStatus if s not in (
    RecordStatus.RUNNING, RecordStatus.HALTED)) + (NOT_SENT,)
"""What a call's ``status`` key may hold: how it ended (a halted call writes nothing)."""
TEXT = "std_msgs/String"   # the type of the status and error keys, as the checks see it


@dataclass
class CallSpec:
    target: Any
    function: Optional[FunctionDefinition] = None
    inputs: Dict[str, Any] = field(default_factory=dict)        # input name -> literal (with Refs)
    static: Dict[str, Any] = field(default_factory=dict)        # input name -> message, for inputs without Refs
    outputs: Dict[str, str] = field(default_factory=dict)       # output name -> tree key
    timeout: Any = None          # seconds, a Ref/Computed, NO_TIMEOUT, or None: the run's --call-timeout
    status: Optional[str] = None  # tree key: how the call ended (STATUS_TEXTS), on success and failure
    error: Optional[str] = None   # tree key: the error text ('' on success)
    check_success: bool = True
    input_pos: Dict[str, Pos] = field(default_factory=dict)
    timeout_pos: Optional[Pos] = None
    # input name -> the place of each $reference inside its mapping or list (keys, indices) -> where it is written
    ref_pos: Optional[Dict[str, Dict[Tuple[Any, ...], Pos]]] = None


class Call(Leaf):
    """Call ``module.function``; SUCCESS when it succeeds (and ``success`` is not false)."""

    def initialise(self) -> None:
        self.reason = ""
        self.feedback_message = ""
        self.record: Optional[CallRecord] = None
        spec: CallSpec = self.node.spec
        self.deadline: Optional[float] = None
        if _unlimited(spec.timeout):
            self.timeout = None
        else:
            self.timeout, self.reason = run_param(spec.timeout, self.ctx.lookup, "seconds", "timeout of call")
            if self.reason:
                return
            self.timeout = self.timeout or self.ctx.default_timeout
        fn = spec.function
        assert fn is not None
        msgs = []
        for p in fn.inputs:
            if p.name in spec.static:
                msgs.append(spec.static[p.name])
                continue
            try:
                value = resolve(spec.inputs[p.name], self.ctx.lookup)
                msgs.append(p.convert(value))
            except (KeyError, RefError) as exc:
                self.reason = "cannot build the call: %s" % (exc.args[0] if exc.args else exc)
                return
            except ProtocolError as exc:   # said in the tree's words, as the checks say it
                self.reason = "cannot build the call: %s" % said_of("input %r" % p.name, exc)
                return
        call = FunctionCall(fn.module, fn.name, msgs, [p.name for p in fn.inputs], new_id())
        self.record = self.ctx.start_call(fn, call, owner=self)
        if self.timeout is None:
            self.feedback_message = "waiting for %s (no time limit)" % fn.qualified
            return
        self.deadline = self.ctx.clock.now() + self.timeout
        self.ctx.wake_after(self.timeout)
        self.feedback_message = "waiting for %s" % fn.qualified

    def update(self) -> Status:
        rec = self.record
        if rec is None:
            return self._ended(NOT_SENT, self.reason, self.reason)
        result = rec.result
        if result is None:
            if rec.ended is not None:  # ended without an answer (its module was lost): say which call
                return self._ended(rec.status, rec.error, "%s %s: %s" % (rec.target, rec.status, rec.error)
                                   if rec.error else "%s %s" % (rec.target, rec.status))
            if self.deadline is not None and self.ctx.clock.now() >= self.deadline:
                unsent = self.ctx.transport.unsent_note(rec.call_id) if rec.call_id else ""
                error = "no answer within %gs%s" % (self.timeout, " (%s)" % unsent if unsent else "")
                self.ctx.cancel(rec, RecordStatus.TIMEOUT, error)
                return self._ended(RecordStatus.TIMEOUT, error, "%s: %s" % (rec.target, error))
            return Status.RUNNING
        fn = rec.function
        assert fn is not None
        if result.status != "succeeded":
            self.ctx.finish(rec, result.status, result.error)
            return self._ended(result.status, result.error, "%s %s: %s" % (rec.target, result.status, result.error))
        try:   # (the transport's screen checks answers to calls it sent; an original module's come here)
            fn.check_result(result)
        except ProtocolError as exc:
            self.ctx.finish(rec, RecordStatus.FAILED, str(exc))
            return self._ended(RecordStatus.FAILED, str(exc), "%s answered outputs that break its definition%s: %s" % (
                rec.target, " (node %s)" % result.publisher if result.publisher else "", exc))
        values = result.values
        rec.output_messages = dict(values)
        if self.node.spec.check_success and "success" in values and unwrap(values["success"]) is False:
            self.ctx.finish(rec, RecordStatus.FAILED, SUCCESS_FALSE)
            self._write_outputs(values)   # the original modules' convention: why, in the other outputs
            return self._ended(RecordStatus.FAILED, SUCCESS_FALSE, "%s %s" % (
                rec.target, success_false_said(SUCCESS_FALSE, rec.outputs)))
        self.ctx.finish(rec, RecordStatus.SUCCEEDED)
        self.feedback_message = "succeeded in %.3fs" % (rec.duration or 0.0)
        self._write_outputs(values)
        self._say(RecordStatus.SUCCEEDED, "")
        return Status.SUCCESS

    def _write_outputs(self, values: Dict[str, Any]) -> None:
        for out, key in self.node.spec.outputs.items():
            self.ctx.write(key, values[out])

    def _ended(self, status: str, error: str, reason: str) -> Status:
        """FAILURE with ``reason``, after writing the ``status`` and ``error`` keys."""
        self._say(status, error)
        return self._fail(reason)

    def _say(self, status: str, error: str) -> None:
        """Write how the call ended to the ``status`` and ``error`` keys the tree gave (as text)."""
        spec: CallSpec = self.node.spec
        if spec.status is not None:
            self.ctx.write(spec.status, String(data=str(status)))
        if spec.error is not None:
            self.ctx.write(spec.error, String(data=error or ""))

    def terminate(self, new_status: Status) -> None:
        """Halted (the tree moved on): the call is cancelled, and its status and error keys not written."""
        rec = getattr(self, "record", None)
        if new_status == Status.INVALID and rec is not None and rec.ended is None:
            self.ctx.cancel(rec, RecordStatus.HALTED, "halted by the tree")


def _unlimited(timeout: Any) -> bool:
    """Whether a spec's timeout is ``none`` (the only text it may be)."""
    return isinstance(timeout, str) and timeout == NO_TIMEOUT


class _Unknown(Exception):
    """A reference whose type is not known statically: nothing to check."""


def _says_now(value: Any) -> bool:
    """Whether a literal holds the text ``now`` (a time taken when the call is made, not at load)."""
    if isinstance(value, str):
        return value == "now"
    if isinstance(value, dict):
        return any(_says_now(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(_says_now(v) for v in value)
    return False


class CallKind(NodeKind):
    name = "call"
    family = "leaf"
    value = ("function", "`module.function`")
    summary = ("send the call; RUNNING until the answer, SUCCESS when it succeeds (and its `success` output, "
               "if any, is not false)")
    options = (Option("inputs", "inputs", "input name → value (YAML literal, `$reference`, `$( … )`, `{…}` text)"),
               Option("outputs", "outputs", "output name → tree key (written when the module answered them: the call "
                                              "succeeded, or answered `success: false`)"),
               Option("status", "key", "a tree key given how the call ended, whether it succeeded or not: "
                                       "`succeeded`, `failed` (also an answered `success: false`, but `succeeded` "
                                       "under `check_success: false`), `rejected`, `cancelled`, `timeout`, `module_lost`, `not_sent` (it could not be built); "
                                       "not written when the call is halted"),
               Option("error", "key", "a tree key given why the call did not succeed (the module's error, "
                                      "`answered success: false`, …), `\"\"` when it succeeded; written like "
                                      "`status`"),
               Option("timeout", "seconds", "seconds, or `none`: no limit (it still ends when its module is "
                                            "lost, or when halted)", shown="`--call-timeout` (30)"),
               Option("check_success", "bool", "`false`: a `success: false` output is not a failure", default=True))

    lasts = "a call waits for its module's answer"

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> CallSpec:
        spec = CallSpec(target=value, timeout=timeout_option(p, node, raw, self.option("timeout"), "call", _HOW),
                        check_success=p.opt(node, raw, self.option("check_success")),
                        status=p.opt(node, raw, self.option("status")), error=p.opt(node, raw, self.option("error")))
        if "timeout" in raw:
            spec.timeout_pos = raw.val_pos["timeout"]
        found = p.target(node, value, at, "function")
        inputs_raw = p.mapping(raw, "inputs", at, "'inputs' must be a mapping of input name: value")
        spec.inputs = {k: p.literal_at(inputs_raw, k, at) for k in inputs_raw}
        spec.input_pos = {k: inputs_raw.val_pos[k] for k in inputs_raw}
        fn = None
        if found is not None:
            mod, fname = found
            fn = mod.functions.get(fname)
            if fn is None:
                p.err(at, mod.no_function(fname))
        if fn is None:  # its outputs still write their keys: no knock-on errors where they are read
            spec.outputs = p.key_map(node, raw, "outputs", None, "output")
            repeated_outputs(p, raw, spec.outputs)
            _clashing_keys(p, raw, spec)
            return spec
        spec.function = fn
        params = {q.name: q for q in fn.inputs}
        for k in inputs_raw:
            if k not in params:
                p.err(inputs_raw.key_pos[k], "%s has no input %r%s" % (value, k, _read_as_bool(k, params)
                                                                       or did_you_mean(k, params)))
        for q in fn.inputs:
            if q.name not in inputs_raw:
                if q.name in raw:   # written beside the call: its error says to move it under inputs
                    continue
                p.err(raw.key_pos.get("inputs", at), "%s needs input %r (%s)" % (value, q.name, q.rostype))
            elif inputs_raw[q.name] is None:  # no message type takes null: the call could never be built
                p.err(inputs_raw.val_pos[q.name], "input %r: null is not a %s value" % (q.name, q.rostype))
            elif spec.inputs[q.name] is not None and not refs_in(spec.inputs[q.name]):
                try:  # converted here, once: the call leaf sends these messages as they are
                    msg = q.convert(spec.inputs[q.name])
                    if not _says_now(spec.inputs[q.name]):  # a time `now` is the time of each call
                        spec.static[q.name] = msg
                except ProtocolError as exc:
                    p.err(inputs_raw.val_pos[q.name], said_of("input %r" % q.name, exc))
            elif isinstance(spec.inputs[q.name], (dict, list)):   # references inside: where, for the checks
                spec.ref_pos = spec.ref_pos or {}
                spec.ref_pos[q.name] = _ref_places(inputs_raw[q.name], spec.inputs[q.name], (), {})
        spec.outputs = p.key_map(node, raw, "outputs", {q.name: q for q in fn.outputs}, "output")
        repeated_outputs(p, raw, spec.outputs)
        _clashing_keys(p, raw, spec)
        return spec

    def default_name(self, node: TreeNode) -> str:
        return str(node.spec.target)

    def reads(self, node: TreeNode) -> Iterable[str]:
        return [r.key for r in refs_in(node.spec.inputs)] + param_keys(node.spec.timeout)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        where = node.spec.input_pos
        return next((p for p in (read_at(v, where[k], key) for k, v in node.spec.inputs.items() if k in where)
                     if p is not None), None)

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        spec = node.spec
        fn = spec.function
        types = {q.name: q.rostype for q in fn.outputs} if fn is not None else {}
        out = {key: types.get(name) for name, key in spec.outputs.items()}
        for key in _ending_keys(spec):
            out[key] = TEXT
        return out

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Its outputs (with its status and error keys) when it succeeds; its status and error keys when
        it fails: a later child of a selector, or a node after ``force_success``, may read them."""
        read = self.reads(node)
        if read:
            f.need(node, read, avail)
        ended = frozenset(_ending_keys(node.spec))
        return frozenset(self.writes(node)), ended

    def never_matches(self, node: TreeNode, key: str, label: Any, contains: bool, seen_from: Pos) -> Optional[str]:
        """For a ``switch`` on ``$key``: why its case ``label`` can never match what this node writes to
        ``key`` ('' when it may; None when the node may write any value there)."""
        if key != node.spec.status:
            return None
        text = str(label).lower() if contains else label
        if (any(text in s for s in STATUS_TEXTS) if contains else text in STATUS_TEXTS):
            return ""
        said = "the status of the call to %s at %s" % (node.spec.target, where(node.pos, seen_from))
        if text in (RecordStatus.HALTED.value, RecordStatus.RUNNING.value):
            return "case %r never matches: $%s is %s, written when the call has ended, never when it is halted " \
                   "(its parent moved on, and a halted call writes no status)" % (label, key, said)
        return "case %r never matches: $%s is %s, one of %s%s" % (
            label, key, said, ", ".join(repr(s) for s in STATUS_TEXTS), did_you_mean(label, STATUS_TEXTS))

    def schema(self) -> Dict[str, Any]:
        return with_no_timeout(super().schema())

    def modules(self, node: TreeNode) -> Iterable[str]:
        t = node.spec.target
        return [t.split(".")[0]] if isinstance(t, str) and "." in t else []

    def functions(self, node: TreeNode) -> Iterable[FunctionDefinition]:
        return [node.spec.function] if node.spec.function is not None else []

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        if not _unlimited(node.spec.timeout):
            param_type_errors(node.spec.timeout, node.spec.timeout_pos, types, "seconds", "timeout of call", errors)
        fn = node.spec.function
        if fn is None:
            return
        for q in fn.inputs:
            value = node.spec.inputs.get(q.name)
            at = node.spec.input_pos.get(q.name, node.pos)
            for off, msg in value_type_errors(value, types):
                errors.append(TreeError(Pos(at.file, at.line, at.column + off), "input %r: %s" % (q.name, msg)))
            refs = refs_in(value)
            if not refs:
                continue
            said = _text_misfit(q, value, types, at)
            if said is not None:   # a template (or an include's template argument) where text is not taken
                if said:
                    errors.append(TreeError(at, said))
                continue
            try:
                sample = resolve(value, lambda key: _sample(types, key))
            except (_Unknown, RefError):
                said = kind_misfit(q.rostype, value, types)   # a key only `set` writes: its kind is known
                if said:
                    errors.append(TreeError(at, "input %r %s" % (q.name, said)))
                continue
            try:
                q.convert(sample)
            except ProtocolError as exc:
                errors.append(TreeError(at, _cannot_take(q.name, q.rostype, value, sample, types, exc)))

    def typed_inputs(self, node: TreeNode) -> List[Tuple[str, Any, Any, Pos, Dict[Tuple[Any, ...], Pos]]]:
        """The inputs that read keys, for the check of the values tree inputs are given
        (``coordinator.dataflow``): what each is called (``navigation.approach's target``), its definition
        (``convert``: what the call does with its value), its value, where it is written, and where each
        reference inside a mapping or a list of it is."""
        spec = node.spec
        fn = spec.function
        if fn is None:
            return []
        places = spec.ref_pos or {}
        return [("%s's %s" % (spec.target, q.name), q, spec.inputs[q.name], spec.input_pos.get(q.name, node.pos),
                 places.get(q.name, {})) for q in fn.inputs if spec.inputs.get(q.name) is not None
                and q.name not in spec.static]

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return Call(node, ctx)


_HOW = "for no time limit write 'timeout: none'; else give seconds (> 0), or leave it out for --call-timeout"
"""How a call's timeout is written, said after an error of it."""


def _ending_keys(spec: CallSpec) -> List[str]:
    """The tree keys a call writes however it ends (not halted): its ``status`` and ``error``."""
    return [k for k in (spec.status, spec.error) if k is not None]


def _clashing_keys(p: Any, raw: Any, spec: CallSpec) -> None:
    """An error where ``status`` or ``error`` writes the key of an output, or of each other: one value
    would replace the other."""
    taken = {key: "output %r" % name for name, key in spec.outputs.items()}
    for option in ("status", "error"):
        key = getattr(spec, option)
        if key is None:
            continue
        if key in taken:
            p.err(raw.val_pos[option], "%s and %s both write tree key %r: one value would replace the other; give "
                                       "%s its own key" % (taken[key], option, key, option))
        else:
            taken[key] = option


def _ref_places(raw: Any, value: Any, here: Tuple[Any, ...],
                out: Dict[Tuple[Any, ...], Pos]) -> Dict[Tuple[Any, ...], Pos]:
    """Where each reference inside a mapping or a list (``value``, parsed from ``raw``) is written, by its place."""
    for step, v in (value.items() if isinstance(value, dict) else enumerate(value)):
        if isinstance(v, Ref):
            at = pos_of(raw, step, None)
            if at is not None:
                out[here + (step,)] = at
        elif isinstance(v, (dict, list)) and isinstance(raw, (dict, list)):
            _ref_places(raw[step], v, here + (step,), out)
    return out


def _text_misfit(q: Any, value: Any, types: Any, at: Pos) -> Optional[str]:
    """Why input ``q`` cannot take ``value`` because text is made where it takes no text: a ``{…}`` template
    in it, or a ``$key`` that an include's argument (``types.bound``) sets to one; '' when that text fits,
    None when ``value`` holds no such text (or its other references' types are not known)."""
    hint = template_hint(value)
    if hint:
        try:
            sample = resolve(templates_as_text(value), lambda key: _sample(types, key))
        except (_Unknown, RefError):
            return None
        try:
            q.convert(sample)
        except ProtocolError as exc:
            return "%s: %s" % (said_of("input %r" % q.name, exc), hint)
        return ""
    if not isinstance(value, Ref) or value.path or _sample_or_none(types, value.key) is not None:
        return None
    for given, arg, include in getattr(types, "bound", {}).get(value.key, {}).get(at.file, ()):
        if not isinstance(given, Template):
            continue
        origin = ("argument %r of the include at %s" % (arg, where(include, at)) if arg and include is not None
                  else "the default of input %r" % value.key)
        said = misfit_text(q.rostype, given.text, "%s, which is the template %r (%s)" % (value, given.text, origin))
        if said:
            fix = template_fix(given)
            warn = "warning: " if include is None else ""   # the tree's own default: its caller may set it
            return "%sinput %r %s: a {…} template makes text%s" % (warn, q.name, said, "; pass %s: %s there" % (
                arg, fix) if arg and fix else "")
    return None


def _sample_or_none(types: Any, key: str) -> Any:
    try:
        return _sample(types, key)
    except _Unknown:
        return None


def _cannot_take(name: str, rostype: str, value: Any, sample: Any, types: Dict[str, set], exc: Exception) -> str:
    """Why input ``name`` cannot take ``value`` (holding references; ``sample``: it made of messages of the
    types its references hold), in the tree's words."""
    if isinstance(value, Ref):
        t = ref_type(types, value)
        got = "%s, which holds %s (%s)" % (value, type_words(t), t) if t else str(value)
        said = misfit_text(rostype, sample, got)
        if said:
            return "input %r %s" % (name, said)
    held = "; ".join("%s holds %s" % (r, next(iter(types[r.key]))) for r in refs_in(value))
    if isinstance(exc, ValueMisfit):
        return "input %r %s (%s)" % (name, exc.said, held)
    return "input %r (%s) cannot take %s: %s" % (name, rostype, held, exc)


def _sample(types: Dict[str, set], key: str) -> Any:
    """A default message of the one type ``key`` is known to hold."""
    known = types.get(key)
    if not known or len(known) != 1 or None in known:
        raise _Unknown(key)
    cls = resolve_type(next(iter(known)))
    if cls is None:
        raise _Unknown(key)
    return cls()


KINDS = (CallKind(),)


_BOOL_WORDS = {True: ("on", "yes", "y", "true"), False: ("off", "no", "n", "false")}


def _read_as_bool(key: Any, params: Dict[str, Any]) -> str:
    """For an input name YAML read as true or false (an unquoted ``on``, ``yes``, ``off``, ``no``): how to
    write it (``'on': …``, quoted), naming the input it meant when the function has one such."""
    if not isinstance(key, bool):
        return ""
    meant = [n for n in params if n.lower() in _BOOL_WORDS[key]]
    return bool_hint(key) + (" ('%s': …)" % meant[0] if len(meant) == 1 else "")

