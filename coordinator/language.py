"""The YAML tree language: node kinds, parsing into an AST, and whole-file validation.

Every problem of a file (and of the files it includes) is collected before anything
is built, each as ``file:line:column: message``. See ``trees/README.md``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Mapping, Optional, Set, Tuple

from comm.errors import ProtocolError, did_you_mean
from coordinator.dataflow import check_flow
from coordinator.errors import Pos, TreeError, TreeErrors
from coordinator.expr import Expr, ExprError
from coordinator.treeast import REQUIRED, Node, Ref, TreeFile, refs_in, used_modules, walk
from coordinator.yamlsrc import LList, LMap, load_yaml, pos_of
from modules.definition import FunctionDefinition, ModuleDefinition

__all__ = ["FORMAT", "KINDS", "Node", "Ref", "TreeFile", "load_tree", "refs_in", "used_modules", "walk"]

FORMAT = 1
_TOP_KEYS = ("format", "name", "description", "inputs", "root")
_INPUT_KEYS = ("default", "description")


@dataclass(frozen=True)
class Kind:
    """A node kind: what its main value is and which options it takes."""

    value: str                      # 'children' | 'child' | 'int' | 'number' | 'target' | 'map' | 'expr' | 'path'
    options: Tuple[str, ...] = ()
    required: Tuple[str, ...] = ()
    doc: str = ""


KINDS: Dict[str, Kind] = {
    "sequence": Kind("children", ("memory",), doc="children in order until one fails (memory: true)"),
    "selector": Kind("children", ("memory",), doc="children in order until one succeeds (memory: true)"),
    "parallel": Kind("children", ("policy", "synchronise"), doc="children together; policy all|one"),
    "retry": Kind("int", ("child",), ("child",), doc="re-run the child up to N times while it fails"),
    "repeat": Kind("int", ("child",), ("child",), doc="run the child N times while it succeeds"),
    "timeout": Kind("number", ("child",), ("child",), doc="fail the child (and halt it) after N seconds"),
    "inverter": Kind("child", doc="success <-> failure"),
    "force_success": Kind("child", doc="failure -> success"),
    "force_failure": Kind("child", doc="success -> failure"),
    "call": Kind("target", ("inputs", "outputs", "timeout", "check_success"), doc="call module.function"),
    "recall": Kind("map", ("timeout",), doc="key: blackboard name, read from the Blackboard node"),
    "check": Kind("expr", doc="a condition on tree-blackboard keys"),
    "wait_event": Kind("target", ("outputs", "timeout"), doc="wait for module.event"),
    "set": Kind("map", doc="key: value"),
    "wait": Kind("number", doc="wait N seconds"),
    "include": Kind("path", ("args",), doc="a subtree from another file"),
}
_COMMON = ("name",)


def _parse_ref(text: str) -> Optional[Ref]:
    if not text.startswith("$") or text.startswith("$$"):
        return None
    body = text[1:]
    parts: List[Any] = []
    for chunk in body.replace("]", "").split("."):
        name, _, idx = chunk.partition("[")
        parts.append(name)
        for i in idx.split("[") if idx else []:
            if not i.lstrip("-").isdigit():
                raise ValueError("bad index %r in reference %r" % (i, text))
            parts.append(int(i))
    if not parts or not isinstance(parts[0], str) or not parts[0].isidentifier():
        raise ValueError("%r is not a valid reference (expected $key or $key.field)" % text)
    for p in parts[1:]:
        if isinstance(p, str) and not p.isidentifier():
            raise ValueError("%r is not a valid reference (expected $key or $key.field)" % text)
    return Ref(parts[0], tuple(parts[1:]))


def _literal(value: Any) -> Any:
    """A YAML value with ``$refs`` turned into Ref objects (``$$`` escapes a dollar)."""
    if isinstance(value, str):
        ref = _parse_ref(value)
        if ref is not None:
            return ref
        return value[1:] if value.startswith("$$") else value
    if isinstance(value, dict):
        return {k: _literal(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_literal(v) for v in value]
    return value


class _Parser:
    def __init__(self, definitions: Mapping[str, ModuleDefinition], loader: Callable[[str], str]):
        self.definitions = definitions
        self.loader = loader
        self.errors: List[TreeError] = []
        self.files: Dict[str, TreeFile] = {}

    def err(self, pos: Pos, message: str) -> None:
        self.errors.append(TreeError(pos, message))

    # files ---------------------------------------------------------------------------
    def load_file(self, path: str, stack: Tuple[str, ...], at: Optional[Pos]) -> Optional[TreeFile]:
        path = os.path.abspath(path)
        if path in stack:
            chain = " -> ".join(os.path.basename(p) for p in stack + (path,))
            self.err(at or Pos(path, 1, 1), "include cycle: %s" % chain)
            return None
        if path in self.files:
            return self.files[path]
        shown = os.path.relpath(path) if not os.path.relpath(path).startswith("..") else path
        try:
            text = self.loader(path)
        except OSError as exc:
            self.err(at or Pos(shown, 1, 1), "cannot read %s: %s" % (shown, exc.strerror or exc))
            return None
        try:
            data = load_yaml(text, shown)
        except TreeErrors as exc:
            self.errors.extend(exc.errors)
            return None
        top = Pos(shown, 1, 1)
        if not isinstance(data, LMap):
            self.err(getattr(data, "pos", top), "a tree file must be a mapping with 'format' and 'root'")
            return None
        for k in data:
            if k not in _TOP_KEYS:
                self.err(data.key_pos[k], "unknown top-level key %r%s" % (k, did_you_mean(k, _TOP_KEYS)))
        if data.get("format") != FORMAT:
            where = data.val_pos.get("format", top)
            self.err(where, "missing or unsupported 'format' (this bmtree reads format: %d)" % FORMAT
                     if "format" in data else "missing 'format: %d' (the tree language version)" % FORMAT)
        inputs, required = self.parse_inputs(data)
        if "root" not in data:
            self.err(top, "missing 'root' (the tree's top node)")
            return None
        tree = TreeFile(path=path, name=str(data.get("name") or os.path.splitext(os.path.basename(path))[0]),
                        description=str(data.get("description", "")), inputs=inputs, root=None,  # type: ignore
                        required_inputs=frozenset(required))
        self.files[path] = tree
        root = self.node(data["root"], data.val_pos["root"], stack + (path,))
        if root is None:
            del self.files[path]
            return None
        tree.root = root
        return tree

    def parse_inputs(self, data: LMap) -> Tuple[Dict[str, Any], List[str]]:
        raw = data.get("inputs") or {}
        inputs: Dict[str, Any] = {}
        required: List[str] = []
        if not isinstance(raw, LMap):
            if raw:
                self.err(pos_of(data, "inputs"), "'inputs' must be a mapping of name: {default: …}")
            return inputs, required
        for name, spec in raw.items():
            if not isinstance(name, str) or not name.isidentifier():
                self.err(raw.key_pos[name], "input name %r is not an identifier" % (name,))
                continue
            if spec is None:
                spec = {}
            if not isinstance(spec, dict):
                self.err(raw.val_pos[name], "input %r must be a mapping (default, description)" % name)
                continue
            for k in spec:
                if k not in _INPUT_KEYS:
                    self.err(getattr(spec, "key_pos", {}).get(k, raw.val_pos[name]),
                             "unknown option %r of input %r%s" % (k, name, did_you_mean(k, _INPUT_KEYS)))
            if "default" in spec:
                inputs[name] = _literal(spec["default"])
            else:
                inputs[name] = REQUIRED
                required.append(name)
        return inputs, required

    # nodes ---------------------------------------------------------------------------
    def node(self, raw: Any, at: Pos, stack: Tuple[str, ...]) -> Optional[Node]:
        if not isinstance(raw, LMap):
            self.err(at, "a node must be a mapping with one of: %s" % ", ".join(KINDS))
            return None
        kinds = [k for k in raw if k in KINDS]
        if len(kinds) > 1:  # 'timeout' is a decorator, and an option of call/recall/wait_event
            kinds = [k for k in kinds if not any(k in KINDS[o].options for o in kinds if o != k)]
        if len(kinds) != 1:
            if not kinds:
                unknown = [k for k in raw if k not in _COMMON]
                hint = did_you_mean(unknown[0], KINDS) if unknown else ""
                first = unknown[0] if unknown else None
                self.err(raw.key_pos[first] if first is not None else raw.pos,
                         "unknown node kind %r%s" % (first, hint) if first is not None
                         else "node has no kind (one of: %s)" % ", ".join(KINDS))
            else:
                self.err(raw.key_pos[kinds[1]], "node has two kinds, %r and %r: split it or nest it" % tuple(kinds[:2]))
            return None
        kind = kinds[0]
        spec = KINDS[kind]
        allowed = _COMMON + spec.options
        if spec.value == "children" and isinstance(raw[kind], LMap):
            raw = self._inline(raw, kind, allowed)
        for k in raw:
            if k != kind and k not in allowed:
                self.err(raw.key_pos[k], "unknown option %r for %s%s" % (k, kind, did_you_mean(k, allowed)))
        for k in spec.required:
            if k not in raw:
                self.err(raw.key_pos[kind], "%s needs option %r" % (kind, k))
        name = raw.get("name")
        if name is not None and not isinstance(name, str):
            self.err(raw.val_pos["name"], "'name' must be a string")
            name = None
        node = Node(kind=kind, name=name or "", pos=raw.key_pos[kind])
        getattr(self, "k_" + kind)(node, raw, raw[kind], raw.val_pos[kind], stack)
        if not node.name:
            node.name = _default_name(node)
        return node

    def _inline(self, outer: LMap, kind: str, allowed: Tuple[str, ...]) -> LMap:
        """``selector: {name: …, children: […]}`` read as ``selector: […]`` with options beside it."""
        inner: LMap = outer[kind]
        merged = LMap()
        merged.pos, merged.key_pos, merged.val_pos = outer.pos, {}, {}
        for src in (outer, inner):
            for k, v in src.items():
                if src is outer and k == kind:
                    continue
                if src is inner and k == "children":
                    continue
                if k in merged:
                    self.err(src.key_pos[k], "option %r given twice" % k)
                    continue
                if src is inner and k not in allowed:
                    self.err(src.key_pos[k], "unknown option %r for %s%s" % (k, kind, did_you_mean(k, allowed + ("children",))))
                    continue
                merged[k] = v
                merged.key_pos[k], merged.val_pos[k] = src.key_pos[k], src.val_pos[k]
        merged[kind] = inner.get("children")
        merged.key_pos[kind] = outer.key_pos[kind]
        merged.val_pos[kind] = inner.val_pos.get("children", inner.pos)
        if "children" not in inner:
            self.err(inner.pos, "%s needs 'children' (a list of nodes)" % kind)
        return merged

    def _child(self, node: Node, raw: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        child = self.node(raw, at, stack)
        if child is not None:
            node.children.append(child)

    def _children(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        if not isinstance(value, LList) or not value:
            self.err(at, "%s takes a non-empty list of children" % node.kind)
            return
        for i, item in enumerate(value):
            self._child(node, item, value.item_pos[i], stack)

    def _bool(self, node: Node, raw: LMap, key: str, default: bool) -> bool:
        v = raw.get(key, default)
        if not isinstance(v, bool):
            self.err(raw.val_pos[key], "%r must be true or false" % key)
            return default
        return v

    def _number(self, node: Node, raw: LMap, key: str, value: Any, at: Pos, minimum: float = 0.0,
                integer: bool = False) -> Optional[float]:
        """A count (integer >= minimum) or a duration (> 0 seconds; >= 0 for ``wait``)."""
        numeric = isinstance(value, int) if integer else isinstance(value, (int, float))
        if integer:
            ok, what = numeric and value >= minimum, "an integer >= %d" % minimum
        elif node.kind == "wait":
            ok, what = numeric and value >= 0, "a number of seconds >= 0"
        else:
            ok, what = numeric and value > 0, "a positive number of seconds"
        if not ok or isinstance(value, bool):
            self.err(at, "%s of %s must be %s, got %r" % (key, node.kind, what, value))
            return None
        return value

    def k_sequence(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        node.opts["memory"] = self._bool(node, raw, "memory", True)
        self._children(node, raw, value, at, stack)

    def k_selector(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        node.opts["memory"] = self._bool(node, raw, "memory", True)
        self._children(node, raw, value, at, stack)

    def k_parallel(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        policy = raw.get("policy", "all")
        if policy not in ("all", "one"):
            self.err(raw.val_pos["policy"], "policy must be 'all' or 'one'%s" % did_you_mean(policy, ("all", "one")))
        node.opts["policy"] = policy
        node.opts["synchronise"] = self._bool(node, raw, "synchronise", True)
        self._children(node, raw, value, at, stack)

    def _decorator_count(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        node.opts["times"] = self._number(node, raw, "count", value, at, 1, integer=True)
        if "child" in raw:
            self._child(node, raw["child"], raw.val_pos["child"], stack)

    k_retry = _decorator_count
    k_repeat = _decorator_count

    def k_timeout(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        node.opts["seconds"] = self._number(node, raw, "duration", value, at)
        if "child" in raw:
            self._child(node, raw["child"], raw.val_pos["child"], stack)

    def _wrap(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        self._child(node, value, at, stack)

    k_inverter = _wrap
    k_force_success = _wrap
    k_force_failure = _wrap

    def _timeout_opt(self, node: Node, raw: LMap) -> None:
        if "timeout" in raw:
            node.opts["timeout"] = self._number(node, raw, "timeout", raw["timeout"], raw.val_pos["timeout"])

    def _target(self, node: Node, value: Any, at: Pos) -> Optional[Tuple[ModuleDefinition, str]]:
        if not isinstance(value, str) or value.count(".") != 1:
            self.err(at, "%s takes 'module.%s', got %r" % (node.kind, "function" if node.kind == "call" else "event",
                                                           value))
            return None
        mod_name, member = value.split(".")
        mod = self.definitions.get(mod_name)
        if mod is None:
            self.err(at, "unknown module %r%s" % (mod_name, did_you_mean(mod_name, self.definitions)
                                                  or " (known: %s)" % ", ".join(sorted(self.definitions))))
            return None
        return mod, member

    def _literal_at(self, raw: Any, key: Any, at: Pos) -> Any:
        try:
            return _literal(raw[key])
        except ValueError as exc:
            self.err(pos_of(raw, key, at), str(exc))
            return None

    def _key_map(self, node: Node, raw: LMap, key: str, allowed: Dict[str, Any], what: str) -> Dict[str, str]:
        """``outputs``: {output name: tree key}."""
        value = raw.get(key) or {}
        if not isinstance(value, LMap):
            if value:
                self.err(raw.val_pos[key], "%r must be a mapping of %s name: tree key" % (key, what))
            return {}
        out = {}
        for name, target in value.items():
            if name not in allowed:
                self.err(value.key_pos[name], "%s has no %s %r%s" % (node.opts.get("target", node.kind), what, name,
                                                                    did_you_mean(name, allowed)))
            elif not isinstance(target, str) or not target.isidentifier():
                self.err(value.val_pos[name], "tree key %r is not an identifier" % (target,))
            else:
                out[name] = target
        return out

    def k_call(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        self._timeout_opt(node, raw)
        node.opts["check_success"] = self._bool(node, raw, "check_success", True)
        node.opts["target"] = value
        found = self._target(node, value, at)
        inputs_raw = raw.get("inputs") or {}
        if not isinstance(inputs_raw, LMap):
            if inputs_raw:
                self.err(raw.val_pos["inputs"], "'inputs' must be a mapping of input name: value")
            inputs_raw = LMap()
            inputs_raw.pos, inputs_raw.key_pos, inputs_raw.val_pos = at, {}, {}
        inputs = {k: self._literal_at(inputs_raw, k, at) for k in inputs_raw}
        node.opts["inputs"] = inputs
        node.opts["outputs"] = {}
        if found is None:
            return
        mod, fname = found
        fn: Optional[FunctionDefinition] = mod.functions.get(fname)
        if fn is None:
            self.err(at, "module %r has no function %r%s" % (mod.name, fname, did_you_mean(fname, mod.functions)
                                                              or " (functions: %s)" % ", ".join(mod.functions)))
            return
        node.opts["function"] = fn
        params = {p.name: p for p in fn.inputs}
        for k in inputs_raw:
            if k not in params:
                self.err(inputs_raw.key_pos[k], "%s has no input %r%s" % (value, k, did_you_mean(k, params)))
        for p in fn.inputs:
            if p.name not in inputs_raw:
                self.err(raw.key_pos.get("inputs", at), "%s needs input %r (%s)" % (value, p.name, p.rostype))
            elif inputs[p.name] is not None and not refs_in(inputs[p.name]):
                try:
                    p.convert(inputs[p.name])
                except ProtocolError as exc:
                    self.err(inputs_raw.val_pos[p.name], "input %r: %s" % (p.name, exc))
        node.opts["outputs"] = self._key_map(node, raw, "outputs", {p.name: p for p in fn.outputs}, "output")

    def k_wait_event(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        self._timeout_opt(node, raw)
        node.opts["target"] = value
        node.opts["outputs"] = {}
        found = self._target(node, value, at)
        if found is None:
            return
        mod, ename = found
        ev = mod.events.get(ename)
        if ev is None:
            self.err(at, "module %r has no event %r%s" % (mod.name, ename, did_you_mean(ename, mod.events)
                                                           or " (events: %s)" % (", ".join(mod.events) or "none")))
            return
        node.opts["event"] = ev
        node.opts["outputs"] = self._key_map(node, raw, "outputs", {p.name: p for p in ev.params}, "event param")

    def _map(self, node: Node, value: Any, at: Pos, what: str) -> Optional[LMap]:
        if not isinstance(value, LMap) or not value:
            self.err(at, "%s takes a non-empty mapping of %s" % (node.kind, what))
            return None
        for k in value:
            if not isinstance(k, str) or not k.isidentifier():
                self.err(value.key_pos[k], "tree key %r is not an identifier" % (k,))
        return value

    def k_recall(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        self._timeout_opt(node, raw)
        m = self._map(node, value, at, "tree key: blackboard name")
        node.opts["names"] = {}
        for k, v in (m or {}).items():
            parts = v.split("/") if isinstance(v, str) else []
            if len(parts) not in (1, 3) or not all(parts):
                self.err(m.val_pos[k], "blackboard name %r must be 'name' or 'module/function/name'" % (v,))
            else:
                node.opts["names"][k] = v

    def k_set(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        m = self._map(node, value, at, "tree key: value")
        node.opts["values"] = {k: self._literal_at(m, k, at) for k in (m or {})}

    def k_check(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        if not isinstance(value, str) or not value.strip():
            self.err(at, "check takes an expression string, e.g. 'answer == \"yes\"'")
            return
        try:
            node.opts["expr"] = Expr(value)
        except ExprError as exc:
            # the column of the offending token, when the value is a plain one-line scalar
            self.err(Pos(at.file, at.line, at.column + exc.offset), "bad expression: %s" % exc)

    def k_wait(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        node.opts["seconds"] = self._number(node, raw, "duration", value, at)

    def k_include(self, node: Node, raw: LMap, value: Any, at: Pos, stack: Tuple[str, ...]) -> None:
        args_raw = raw.get("args") or {}
        if not isinstance(args_raw, LMap):
            if args_raw:
                self.err(raw.val_pos["args"], "'args' must be a mapping of input name: value")
            args_raw = {}
        args = {k: self._literal_at(args_raw, k, at) for k in args_raw}
        node.opts["args"] = args
        if not isinstance(value, str) or not value:
            self.err(at, "include takes a file path")
            return
        base = os.path.dirname(stack[-1]) if stack else os.getcwd()
        sub = self.load_file(os.path.join(base, value), stack, at)
        if sub is None:
            return
        node.opts["tree"] = sub
        if not node.name:
            node.name = "%s%s" % (sub.name, "(%s)" % ", ".join("%s=%s" % (k, v) for k, v in args.items()) if args else "")
        for k in args:
            if k not in sub.inputs:
                self.err(args_raw.key_pos[k], "%s has no input %r%s" % (value, k, did_you_mean(k, sub.inputs)
                                                                         or " (inputs: %s)" % (", ".join(sub.inputs) or "none")))
        for k in sorted(sub.required_inputs - set(args)):
            self.err(at, "include of %s needs argument %r" % (value, k))


def _default_name(node: Node) -> str:
    o = node.opts
    if node.kind in ("call", "wait_event"):
        return str(o.get("target", node.kind))
    if node.kind == "check":
        return "check %s" % (o["expr"].text if "expr" in o else "?")
    if node.kind == "recall":
        return "recall %s" % ", ".join(o.get("names", {}).values())
    if node.kind == "set":
        return "set %s" % ", ".join(o.get("values", {}))
    if node.kind in ("wait", "timeout"):
        return "%s %ss" % (node.kind, o.get("seconds"))
    if node.kind in ("retry", "repeat"):
        return "%s x%s" % (node.kind, o.get("times"))
    return node.kind


def load_tree(path: str, definitions: Mapping[str, ModuleDefinition],
              loader: Optional[Callable[[str], str]] = None, given: Set[str] = frozenset()) -> TreeFile:
    """Parse and validate a tree file and its includes; TreeErrors lists every problem.

    Args:
        given: tree inputs the caller will set (e.g. from the command line).
    """

    def read(p: str) -> str:
        with open(p, encoding="utf-8") as fh:
            return fh.read()

    parser = _Parser(definitions, loader or read)
    tree = parser.load_file(path, (), None)
    errors = list(parser.errors)
    if tree is not None:
        errors.extend(check_flow(tree, frozenset(given)))
    if errors:
        raise TreeErrors(errors)
    assert tree is not None
    return tree
