"""What a node kind is: its options as data, and the hooks every generic walk calls.

A kind (one object, in one family file of this package) says how its YAML parses into a
typed spec, which tree keys it reads and writes, how it becomes a py_trees behaviour, its
default name, and documents itself (the language reference's tables and the JSON Schema are
generated from these objects).
"""
from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Dict, FrozenSet, Iterable, List, Optional, Set, Tuple

import py_trees

from comm.errors import did_you_mean
from coordinator.bounds import MAX_COUNT, beyond_bound, finite_number, shown
from coordinator.errors import Pos, TreeError
from coordinator.nodes.writtenkeys import NEVER, join, meet
from coordinator.refs import Computed, Ref, RefError, refs_in, resolve, unwrap
from coordinator.treeast import TreeFile, TreeNode, nodes_of, top_of

if TYPE_CHECKING:  # pragma: no cover
    from coordinator.context import RunContext
    from coordinator.language import Parser
    from coordinator.yamlsrc import LMap
    from modules.definition import FunctionDefinition

__all__ = ["Flow", "NEVER", "NodeKind", "Option", "TYPES", "ValueType", "NO_DEFAULT", "SET_ARG", "PARAM_TYPES", "fixed", "join",
           "meet", "param_keys", "repeated_outputs", "run_param", "where"]

NO_DEFAULT = object()
SET_ARG = "--set"   # a binding's "argument" for a value the run is given, not a default (dataflow._bindings)
_NOTHING: FrozenSet[str] = frozenset()


def fixed(*values: Any) -> bool:
    """Whether these values are known when the tree loads (no reference, no expression): a node reading
    them cannot fail because of them (a bad literal is an error of the check)."""
    return not any(refs_in(v) for v in values)


BuildChild = Callable[[TreeNode], py_trees.behaviour.Behaviour]


@dataclass(frozen=True)
class ValueType:
    """A type of option or main value: its check, its error text, its table text and its JSON Schema."""

    name: str
    doc: str
    schema: Dict[str, Any]
    ok: Optional[Callable[[Any], bool]] = None   # None: parsed by the kind itself
    expect: str = ""


_NODE = {"$ref": "#/definitions/node"}
_PARAM = {"type": "string", "pattern": r"^\$[^$]"}
_KEY = {"type": "string", "pattern": r"^[^\W\d]\w*$"}
TYPES: Dict[str, ValueType] = {t.name: t for t in (
    ValueType("bool", "`true` or `false`", {"type": "boolean"}, lambda v: isinstance(v, bool)),
    ValueType("count", "an integer ≥ 1", {"anyOf": [{"type": "integer", "minimum": 1}, _PARAM]},
              lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1, "an integer >= 1"),
    ValueType("seconds", "seconds (> 0)", {"anyOf": [{"type": "number", "exclusiveMinimum": 0}, _PARAM]},
              lambda v: finite_number(v) and v > 0, "a positive number of seconds"),
    ValueType("seconds0", "seconds (≥ 0)", {"anyOf": [{"type": "number", "minimum": 0}, _PARAM]},
              lambda v: finite_number(v) and v >= 0, "a number of seconds >= 0"),
    ValueType("policy", "`all` or `one`", {"enum": ["all", "one"]}),
    ValueType("children", "list of children", {"type": "array", "minItems": 1, "items": _NODE}),
    ValueType("node", "a node", _NODE),
    ValueType("function", "`module.function`", {"type": "string", "pattern": r"^\w+\.\w+$"}),
    ValueType("event", "`module.event`", {"type": "string", "pattern": r"^\w+\.\w+$"}),
    ValueType("inputs", "input name → value", {"type": "object"}),
    ValueType("outputs", "name → tree key", {"type": "object", "additionalProperties": _KEY}),
    ValueType("recall", "tree key → Blackboard name (`name` or `module/function/name`)",
              {"type": "object", "minProperties": 1,
               "additionalProperties": {"type": "string", "pattern": r"^[^/\s]+(/[^/\s]+/[^/\s]+)?$"}}),
    ValueType("values", "tree key → value", {"type": "object", "minProperties": 1}),
    ValueType("list", "a list, `$key` or `$( … )`", {"anyOf": [{"type": "array"}, _PARAM]}),
    ValueType("key", "a tree key", _KEY, lambda v: isinstance(v, str) and v.isidentifier(), "a tree key"),
    ValueType("cases", "case value → node", {"type": "object", "minProperties": 1, "additionalProperties": _NODE}),
    ValueType("match", "`equals`, `contains` or `words`", {"enum": ["equals", "contains", "words"]}),
    ValueType("value", "a value: `$key`, `$( … )`, text with `{…}`", {}),
    ValueType("expr", "an expression", {"type": "string", "minLength": 1}),
    ValueType("path", "a tree file (relative to this file)", {"type": "string", "minLength": 1}),
)}


PARAM_TYPES = ("count", "seconds", "seconds0")
"""Types whose values may also be a ``$reference`` or a ``$( … )`` expression, checked when the node starts."""


def param_keys(*values: Any) -> List[str]:
    """The tree keys that parameters (counts, durations) read."""
    return [r.key for v in values for r in refs_in(v)]


def run_param(value: Any, lookup: Callable[[str], Any], type_name: str, label: str) -> Tuple[Any, str]:
    """A parameter's value now, and '' — or None and why it cannot be used (the node then fails)."""
    if not isinstance(value, (Ref, Computed)):
        return value, ""
    try:
        v = unwrap(resolve(value, lookup))
    except (KeyError, RefError) as exc:
        return None, "%s %r: %s" % (label, value, exc.args[0] if exc.args else exc)
    if type_name == "count" and isinstance(v, float) and v.is_integer() and abs(v) <= MAX_COUNT:
        v = int(v)
    t = TYPES[type_name]
    too_big = beyond_bound(type_name, v)
    if too_big:
        return None, "%s %s is %s" % (label, value, too_big)
    if t.ok is not None and not t.ok(v):
        return None, "%s %s is %s, not %s" % (label, value, shown(v), t.expect)
    return v, ""


_PARAM_KINDS = {"count": "number", "seconds": "number", "seconds0": "number", "list": "list"}


def param_type_errors(value: Any, where: Any, types: Dict[str, set], type_name: str, label: str,
                      errors: List[TreeError], limit: Optional[int] = None) -> None:
    """A count, a duration or ``for_each``'s list that cannot be one, found before running: operands of
    the wrong kind and references into fields their keys' types do not have, in its expressions; a
    reference or an expression whose type the definitions give (``$answer`` after ``speech.listen``
    wrote it: text, not seconds); and a constant expression worked out when the tree loaded
    (``$(2.5)``: not a count). A tree input ``$key`` that nothing but its default or its includes'
    arguments writes is checked with those literals (``tries: {default: three}``: not a count); a key that
    only ``set`` writes, by its kind (``set: {n: two}``: text, not a count); another value (a number a ``set``
    writes: 0 is no count) is left to :func:`run_param`.

    ``where``: the value's position, or a function that makes it (read only when there is an error);
    ``limit``: the most elements a tree input's literal list may have (``for_each``'s ``max``)."""
    if value is None:
        return
    from coordinator.values import value_kind, value_type_errors

    found: List[Tuple[int, str]] = []
    at = None
    if isinstance(value, (Ref, Computed)):
        found = value_type_errors(value, types)
        if not found:   # (else its own errors say what is wrong)
            kind, said = value_kind(types, value)
            if kind is not None and kind != _PARAM_KINDS[type_name]:
                found.append((0, "%s %s, not %s" % (label, said, TYPES[type_name].expect or "a list")))
            elif kind is None and isinstance(value, Ref) and not value.path and value.key in getattr(
                    types, "bound", ()):
                at = where() if callable(where) else where   # a tree input: the literals it is given
                found = _bound_errors(value, at, types, type_name, label, limit) if at is not None else []
    elif isinstance(value, list):   # a literal list: its elements may hold references
        found = value_type_errors(value, types)
    elif type_name == "list":
        found.append((0, "%s is %r, not a list" % (label, value)))
    else:   # a literal was checked when parsed: this is a constant expression, worked out then
        if type_name == "count" and isinstance(value, float) and value.is_integer() and abs(value) <= MAX_COUNT:
            value = int(value)   # as run_param takes it
        t = TYPES[type_name]
        if beyond_bound(type_name, value):
            found.append((0, "%s is %s" % (label, beyond_bound(type_name, value))))
        elif t.ok is not None and not t.ok(value):
            found.append((0, "%s is %s, not %s" % (label, shown(value), t.expect)))
    if not found:
        return
    at = at or (where() if callable(where) else where)
    if at is None:
        return
    for off, msg in found:
        errors.append(TreeError(Pos(at.file, at.line, at.column + off), msg))


def _bound_errors(ref: Ref, at: Pos, types: Any, type_name: str, label: str,
                  limit: Optional[int] = None) -> List[Tuple[int, str]]:
    """The literals a tree input ``$key`` is given (``types.bound``: the default, an include's argument;
    only where nothing else writes its key) that cannot be this count, duration or list (or one of more
    than ``limit`` elements): errors, but a warning for a tree's own default (its caller may set it)."""
    from coordinator.expr import brief

    t = TYPES[type_name]
    out: List[Tuple[int, str]] = []
    for given, arg, include in types.bound[ref.key].get(at.file, ()):
        whole = type_name == "count" and isinstance(given, float) and given.is_integer()
        v = int(given) if whole else given
        long = isinstance(v, list) and limit is not None and len(v) > limit
        if not long and (isinstance(v, list) if t.ok is None else t.ok(v)):
            continue
        one = "a shorter list" if long else "one"
        warn, risk, fix = "", "", "give the input a %s" % ("shorter default" if long else "default that is one")
        if arg == SET_ARG:   # a value the run is given (bmtree run --set)
            origin, fix = "--set %s" % ref.key, "give --set %s a value that is %s" % (ref.key, one)
        elif arg:
            origin, fix = "argument %r of the include at %s" % (arg, where(include, at)), "pass %s there" % one
        elif include is not None:
            origin = "the default of input %r; the include at %s passes no argument" % (ref.key, where(include, at))
            fix += ", or pass %s" % one
        else:   # the tree's own: its caller may set it
            warn, origin = "warning: ", "the default of input %r" % ref.key
            risk, fix = "a run that does not set the input fails here; ", fix.replace("the input", "it")
        said = ("has %d elements (%s), more than max %d: %sraise max: to %d, or %s" % (
            len(v), origin, limit, risk, len(v), fix) if long else
            "is %s (%s), not %s: %s%s" % (brief(given), origin, t.expect or "a list", risk, fix))
        out.append((0, "%s%s %s %s" % (warn, label, ref, said)))
    return out


@dataclass(frozen=True)
class Option:
    """An option key beside the kind key."""

    name: str
    type: str
    doc: str = ""
    default: Any = NO_DEFAULT
    required: bool = False
    shown: str = ""          # the default as the tables say it, when it is not a plain value

    @property
    def default_text(self) -> str:
        if self.shown or self.default is NO_DEFAULT:
            return self.shown
        if isinstance(self.default, bool):
            return "`%s`" % str(self.default).lower()
        return "`%s`" % self.default


def where(pos: Pos, seen_from: Pos) -> str:
    """A place as a message at ``seen_from`` names it: ``line 7`` in the same file, else ``file:7``."""
    return "line %d" % pos.line if pos.file == seen_from.file else "%s:%d" % (pos.file, pos.line)


_CLEANUP_KEYS = ("ended", "ended_reason")   # coordinator.nodes.task.CLEANUP_KEYS (which imports this module)


class Flow:
    """The data-flow walk (``coordinator.dataflow``): kinds call back into it for their children.

    A kind says what its node surely writes when it succeeds (``flow``, and ``of`` here) and, when it
    knows, when it fails too (``outcome``): a selector's later children and an inverter need the latter.
    Each read of a key not surely written is noted (``missed``); :meth:`report` makes the errors once
    the walk is over and the keys written anywhere in the tree are known."""

    def __init__(self, errors: List[TreeError], tree: Optional[TreeFile] = None):
        self.errors = errors
        self.missed: List[Tuple[TreeNode, str, FrozenSet[str]]] = []
        self.tree = tree
        # the files being walked, innermost last (an include pushes its subtree's): whose keys a subtree meets
        self.files: List[TreeFile] = [tree] if tree is not None else []
        self._writers: Optional[Dict[str, Dict[TreeNode, None]]] = None
        self._file_writes: Dict[int, Dict[str, TreeNode]] = {}
        self.cleanup_nodes: Set[TreeNode] = set()   # the nodes of the tree's cleanup: (nodes/task.py)

    def need(self, node: TreeNode, keys: Iterable[str], avail: FrozenSet[str]) -> None:
        missing = [k for k in keys if k not in avail]
        for k in sorted(set(missing)) if missing else ():
            self.missed.append((node, k, avail))

    def report(self, written: Iterable[str]) -> None:
        """The errors of the reads noted, at each reference; ``written``: every key a node of the tree
        writes or an input gives (a key outside it is likely misspelt; one inside it is not, so a close
        name would mislead: the error says where it is written instead)."""
        anywhere = frozenset(written)
        for node, k, avail in self.missed:
            at = node.nodekind.read_pos(node, k) or node.pos
            if k in _CLEANUP_KEYS and node not in self.cleanup_nodes:
                message = ("reads %r, which bmtree sets only for the tree's cleanup: (how root ended): a node "
                           "outside the cleanup cannot read it" % k)
            elif k in anywhere and node in self.cleanup_nodes:
                message = ("reads %r, which the cleanup cannot count on: it runs however root ended, also when "
                           "root was stopped before writing it (%s)" % (k, self._written_at(node, k, at)))
            elif k in anywhere:
                message = "reads %r, which is not written on every path before this node (%s)" % (
                    k, self._written_at(node, k, at))
            else:
                message = "reads %r, which no node writes and no input declares (%s)" % (
                    k, did_you_mean(k, anywhere | avail)[2:-1]
                    or "write it first, with a call's 'outputs:' or a 'set', or declare it under 'inputs:'")
            self.errors.append(TreeError(at, message))
        self.missed = []

    def _written_at(self, node: TreeNode, key: str, at: Pos) -> str:
        hint = "write it earlier on every path or declare it under 'inputs:'"
        if node in self.cleanup_nodes:
            hint = "write it in the cleanup first, or declare it under 'inputs:' with a default"
        writers = self.writers(key)
        if not writers:
            return hint
        if writers == [node]:
            return "only this node writes it: %s" % hint
        places = [where(w.pos, at) for w in writers if w is not node]
        shown = ", ".join(places[:3]) + (", …" if len(places) > 3 else "")
        return "written at %s, but not before it on every path: %s" % (shown, hint)

    def outcome(self, node: TreeNode, avail: FrozenSet[str]) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Keys surely written when ``node`` succeeds, and when it fails (``NEVER``: it cannot end so)."""
        nk = node.nodekind
        if nk.own_outcome:
            return nk.outcome(node, avail, self)
        return nk.flow(node, avail, self), _NOTHING

    def of(self, node: TreeNode, avail: FrozenSet[str]) -> FrozenSet[str]:
        """Keys surely written when ``node`` succeeds."""
        return node.nodekind.flow(node, avail, self)

    def writers(self, key: str) -> List[TreeNode]:
        """The nodes of the whole tree (includes expanded) that write ``key``, in walk order. Made on
        first use: only a problem needs them."""
        if self._writers is None:
            self._writers = {}
            for n in nodes_of(top_of(self.tree)) if self.tree is not None else ():
                nk = n.nodekind
                written = nk.writes(n) if nk.own_writes else None
                for k in written if written else ():
                    self._writers.setdefault(k, {})[n] = None
        return list(self._writers.get(key, ()))

    def file_writes(self, tree: TreeFile) -> Dict[str, TreeNode]:
        """The keys the nodes of ``tree``'s own file write, each with its first writer; not those of the
        files it includes, nor the arguments of its includes (each include is looked at by itself)."""
        found = self._file_writes.get(id(tree))
        if found is None:
            found = self._file_writes[id(tree)] = {}
            stack = [tree.root]
            while stack:
                n = stack.pop()
                nk = n.nodekind
                if nk.own_writes and not nk.own_expand:
                    for k in nk.writes(n) or ():
                        found.setdefault(k, n)
                stack.extend(reversed(n.children))
        return found


class NodeKind(abc.ABC):
    """One kind of node. Subclasses set the class attributes, ``parse`` and ``build``, and override
    the other hooks they need."""

    name = ""
    family = ""                        # 'composite' | 'decorator' | 'leaf'
    value: Tuple[str, str] = ("", "")  # (type of the main value, what it is, for the tables)
    label = ""                         # the main value's name in error messages ('duration of wait')
    options: Tuple[Option, ...] = ()
    summary = ""                       # what the node does, for the tables
    uses_blackboard_node = False
    # why a node of this kind can still be RUNNING after the tick it started in ('' : it ends in that tick,
    # unless a node below it runs): see ``lasting`` and ``coordinator.reactive``
    lasts = ""
    # True when ``parse`` reads its ``at`` only to report a problem: it is then given None and reads
    # ``node.value_pos`` instead (the same position, made only when read: most never are)
    parse_without_pos = False
    # whether the kind overrides these hooks (set for each subclass): the whole-tree walks skip the base's,
    # which find nothing
    own_expand = own_writes = own_check_types = own_warnings = own_outcome = own_copies = own_binds = False
    # a leaf kind's behaviour class, made as ``leaf(node, ctx)``: the builder makes it without calling
    # ``build`` (None: ``build`` makes the behaviour)
    leaf: Optional[Callable[[TreeNode, Any], py_trees.behaviour.Behaviour]] = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        for hook in ("expand", "writes", "check_types", "warnings", "outcome", "copies", "binds"):
            setattr(cls, "own_" + hook, getattr(cls, hook) is not getattr(NodeKind, hook))
        if cls.build is not NodeKind.build:
            cls.leaf = None   # its own build decides

    # parsing -----------------------------------------------------------------------------
    @abc.abstractmethod
    def parse(self, p: Parser, node: TreeNode, raw: LMap, value: Any, at: Pos) -> Any:
        """The typed spec of ``node``; problems go to ``p.err`` (parsing goes on)."""

    def option(self, name: str) -> Option:
        return next(o for o in self.options if o.name == name)

    def default_name(self, node: TreeNode) -> str:
        return self.name

    # data flow and checks ----------------------------------------------------------------
    def reads(self, node: TreeNode) -> Iterable[str]:
        return ()

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        """Tree keys written on SUCCESS, each with its ROS type when known (for the type checks)."""
        return {}

    def copies(self, node: TreeNode) -> Dict[str, Any]:
        """Keys among ``writes`` given a value written in the tree, each with that value: a reference the node
        reads (a ``set`` of ``$pose``, ``for_each``'s element ``$list[0]``), the key holds the type it holds; a
        ``set``'s literal, template or expression, the key holds a value of its kind
        (``coordinator.dataflow``)."""
        return {}

    def binds(self, node: TreeNode) -> Optional[Tuple[TreeFile, Dict[str, Any]]]:
        """The tree file whose inputs the node sets before running it (an include) and the arguments it
        gives (an input without one gets its default): the counts, durations and lists it reads are
        checked with these values."""
        return None

    def flow(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> FrozenSet[str]:
        """Keys surely written when ``node`` succeeds (``NEVER``: it never does); its reads are checked
        against ``avail``, the keys surely written before it."""
        if self.own_outcome:
            return self.outcome(node, avail, f)[0]
        read = self.reads(node)
        if read:
            f.need(node, read, avail)
        if not self.own_writes:
            return _NOTHING
        written = self.writes(node)
        return frozenset(written) if written else _NOTHING

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Keys surely written when ``node`` succeeds and when it fails (``NEVER``: it cannot end so). A
        composite or decorator overrides it: what its parent may count on depends on both (a selector's
        child that never succeeds is no way for it to succeed). By default: ``flow``; on failure nothing
        (a leaf writes its keys only when it succeeds)."""
        return self.flow(node, avail, f), _NOTHING

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:  # noqa: B027
        """Report references whose known type cannot fit where they are used (most kinds pass none)."""

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        """Where ``node`` reads ``key``, for the data-flow errors: by default its main value when that
        reads it, else None (the node itself)."""
        from coordinator.values import read_at

        return read_at(node.spec, node.value_pos, key) if node.value_pos is not None else None

    def warnings(self, node: TreeNode) -> List[TreeError]:
        return []

    def lasting(self, node: TreeNode) -> str:
        """Why ``node`` itself can be RUNNING after the tick it starts in (``lasts``; '' : it ends in that
        tick unless a node below it does not): a kind whose answer depends on its value overrides it."""
        return self.lasts

    # structure ---------------------------------------------------------------------------
    def expand(self, node: TreeNode) -> List[TreeNode]:
        """The nodes under this one (an include's subtree root too)."""
        return node.children

    def modules(self, node: TreeNode) -> Iterable[str]:
        return ()

    def functions(self, node: TreeNode) -> Iterable[FunctionDefinition]:
        """Module functions this node itself calls."""
        return ()

    # building ----------------------------------------------------------------------------
    def build(self, node: TreeNode, ctx: RunContext, child: BuildChild) -> py_trees.behaviour.Behaviour:
        """The behaviour of a validated node; ``child(n)`` builds a node below it."""
        if self.leaf is None:
            raise TypeError("node kind %s has neither a build method nor a leaf class" % type(self).__name__)
        return self.leaf(node, ctx)

    # documentation -----------------------------------------------------------------------
    def value_schema(self) -> Dict[str, Any]:
        return dict(TYPES[self.value[0]].schema)

    def schema(self) -> Dict[str, Any]:
        """JSON Schema of one node of this kind."""
        props: Dict[str, Any] = {self.name: self.value_schema(), "name": {"type": "string"}}
        for o in self.options:
            s = dict(TYPES[o.type].schema)
            if o.doc:
                s["description"] = o.doc
            props[o.name] = s
        props[self.name]["description"] = "%s: %s" % (self.value[1], self.summary)
        required = [self.name] + [o.name for o in self.options if o.required]
        return {"type": "object", "properties": props, "required": required, "additionalProperties": False}

    def options_text(self) -> str:
        """The options cell of the reference table."""
        parts = []
        for o in self.options:
            bits = []
            if o.required:
                bits.append("required")
            if o.default_text:
                bits.append("default %s" % o.default_text)
            head = "`%s`%s" % (o.name, " (%s)" % ", ".join(bits) if bits else "")
            parts.append("%s: %s" % (head, o.doc) if o.doc else head)
        return "; ".join(parts)


def repeated_outputs(p: Parser, raw: LMap, outputs: Dict[str, str], key: str = "outputs") -> None:
    """An error at each output written to a tree key an earlier output of the node writes: both are
    written when it succeeds, so one value is lost (``outputs: {success: result, text: result}``)."""
    first: Dict[str, str] = {}
    for name, tree_key in outputs.items():
        if tree_key not in first:
            first[tree_key] = name
            continue
        at = raw[key].val_pos[name]
        p.err(at, "%s %r and %r both write tree key %r: one value would replace the other; give %r its own "
                  "key" % (key, first[tree_key], name, tree_key, name))


def check_choice(p: Parser, raw: LMap, key: str, choices: Tuple[str, ...], default: str, hint: str = "") -> str:
    """``raw[key]``, one of ``choices`` (else an error with the closest one, or ``hint``)."""
    v = raw.get(key, default)
    if v not in choices:
        p.err(raw.val_pos[key], "%s must be %s%s" % (key, " or ".join("%r" % c for c in choices),
                                                      did_you_mean(v, choices) or hint))
    return v
