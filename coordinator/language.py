"""The YAML tree language: files, inputs, and the generic walk that parses nodes.

Every problem of a file (and of the files it includes) is collected before anything
is built, each as ``file:line:column: message``. What each node kind accepts is in
its registry object (``coordinator.nodes``); see ``trees/README.md``.
"""
from __future__ import annotations

import os
from typing import Any, Callable, Dict, List, Mapping, Optional, Set, Tuple

from comm.errors import did_you_mean
from comm.textfile import read_text, text_pos
from coordinator import othernames, parsehints
from coordinator.bounds import shown
from coordinator.cleanupparse import CLEANUP_TOP_KEYS, parse_cleanup, reserved_key_problems
from coordinator.dataflow import check_flow, check_types
from coordinator.errors import Pos, TreeError, TreeErrors
from coordinator.nodes import REGISTRY
from coordinator.nodes.base import NO_DEFAULT, PARAM_TYPES, TYPES, Option
from coordinator.othernames import decorator_mapping, kind_hint, one_child, option_hint, top_key_hint
from coordinator.parsehints import LEAF_OPTIONS, closest, misplaced, nearby, nest_hint, unquoted
from coordinator.refs import RefError
from coordinator.treeast import REQUIRED, TreeFile, TreeNode, gc_paused, nodes_of, top_of, used_modules, walk
from coordinator.treewarnings import TreeErrorsWithWarnings, warnings
from coordinator.values import literal, loose_dollars
from coordinator.yamlsrc import LList, LMap, bool_hint, load_yaml, pos_of
from modules.definition import ModuleDefinition

__all__ = ["FORMAT", "Parser", "TreeErrorsWithWarnings", "load_tree", "used_modules", "walk", "warnings"]

FORMAT = 1
# Parsing, the checks, the builder and py_trees (tick, visitors, display) recurse per level of the tree,
# includes expanded: at most 5 frames a level (parsing) keeps 100 levels far below Python's 1,000.
MAX_TREE_DEPTH = 100
MAX_INCLUDE_DEPTH = 32       # files in a chain of includes
MAX_REPEATED_NODES = 100000  # nodes that includes of an already-read file add (each include is a copy)
_TOP_KEYS = ("format", "name", "description", "inputs", "root") + CLEANUP_TOP_KEYS
_INPUT_KEYS = ("default", "description")
_COMMON = ("name",)
# 'timeout' is a decorator, and an option of call/recall/wait_event: it is the kind only alone
_OPTION_NAMES = {k: frozenset(o.name for o in nk.options) for k, nk in REGISTRY.items()}
_ALLOWED = {k: _COMMON + tuple(o.name for o in nk.options) for k, nk in REGISTRY.items()}
_REQUIRED = {k: tuple(o.name for o in nk.options if o.required) for k, nk in REGISTRY.items()}
_KEYS = {k: frozenset(_ALLOWED[k] + (k,)) for k in REGISTRY}   # every key a node of the kind may have
_KINDS = frozenset(REGISTRY)
_LISTS = frozenset(k for k, nk in REGISTRY.items() if nk.value[0] == "children")   # may be written inline
_NO_CHILDREN = LList()   # a composite whose children are missing, already reported (see _inline, _node)
_CHILDREN_HINT = (": the children of %s are its value, a list (%s: [...]), or go under 'children:' inside it "
                  "(%s: {children: [...]})")
# per kind, what parsing a node asks of it (one lookup per node)
_INFO = {k: (nk, _ALLOWED[k], _KEYS[k], _REQUIRED[k], k in _LISTS) for k, nk in REGISTRY.items()}


class Parser:
    """Parses tree files; node kinds call back into it (``p.opt``, ``p.children``, ``p.target``…)."""

    def __init__(self, definitions: Mapping[str, ModuleDefinition], loader: Callable[[str], str]):
        self.definitions = definitions
        self.loader = loader
        self.errors: List[TreeError] = []
        self.warnings: List[TreeError] = []
        self.files: Dict[str, TreeFile] = {}
        self.stack: Tuple[str, ...] = ()
        self.depth = 0   # of the node being parsed, in the tree with its includes expanded
        self.repeated = 0
        self._sizes: Dict[TreeNode, Tuple[int, int]] = {}   # see _measure
        self._unquoted: Dict[Pos, str] = {}   # where a value is text YAML read as a mapping or a list: the hint
        self.inputs_raw: Dict[str, LMap] = {}   # each file's inputs as written, by the file's name in positions

    def err(self, pos: Pos, message: str, module: str = "") -> None:
        if self._unquoted and "takes text" in message and pos in self._unquoted:   # see literal_at
            message += self._unquoted.pop(pos)
        self.errors.append(TreeError(pos, message, module))

    def warn(self, pos: Pos, message: str) -> None:
        self.warnings.append(TreeError(pos, "warning: " + message))

    # files ---------------------------------------------------------------------------
    def load_file(self, path: str, at: Optional[Pos]) -> Optional[TreeFile]:
        path = os.path.abspath(path)
        stack = self.stack
        if path in stack:
            chain = " -> ".join(os.path.basename(p) for p in stack + (path,))
            self.err(at or Pos(path, 1, 1), "include cycle: %s" % chain)
            return None
        if len(stack) >= MAX_INCLUDE_DEPTH and at is not None:
            chain = [os.path.basename(p) for p in stack + (path,)]
            self.err(at, "includes nest deeper than %d files: this one makes a chain of %d (%s)" % (
                MAX_INCLUDE_DEPTH, len(chain), " -> ".join(chain[:2] + ["…"] + chain[-2:])))
            return None
        if path in self.files:
            return self._repeat(self.files[path], at)
        rel = os.path.relpath(path)
        shown = rel if not rel.startswith("..") else path
        try:
            text = self.loader(path)
        except OSError as exc:
            self.err(at or Pos(shown, 1, 1), "cannot read %s: %s%s" % (shown, exc.strerror or exc,
                                                                       parsehints.include_hint(path, stack)))
            return None
        except UnicodeDecodeError as exc:   # where it is, if the loader decoded the whole file at once
            data = exc.object
            self.err(Pos(shown, *text_pos(data, exc.start)), "not UTF-8 text: byte 0x%02x" % data[exc.start]
                     if isinstance(data, bytes) else "cannot read %s: not UTF-8 text" % shown)
            return None
        if parsehints.looks_like_xml(text):   # a BehaviorTree.CPP file
            self.err(Pos(shown, 1, 1), parsehints.XML_HINT)
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
                self.err(data.key_pos[k], "unknown top-level key %r%s" % (k, top_key_hint(k) or did_you_mean(k, _TOP_KEYS)))
        for key in ("name", "description"):
            if key in data and not isinstance(data[key], str):
                self.err(data.val_pos[key], "'%s' must be a string" % key)
        if data.get("format") != FORMAT or isinstance(data.get("format"), bool):  # True == 1 in Python
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
        self.stack = stack + (path,)
        try:
            root = tree.root = self.node(data["root"], data.val_pos["root"])
            parse_cleanup(self, data, tree)   # cleanup: and cleanup_timeout: (coordinator/cleanupparse.py)
        finally:
            self.stack = stack
        if root is None:
            del self.files[path]
            return None
        return tree

    def _repeat(self, tree: TreeFile, at: Optional[Pos]) -> Optional[TreeFile]:
        """A file read before, included again here: its copy must fit the depth and size limits too."""
        height, size = self._measure(tree.root)
        if self.depth + height > MAX_TREE_DEPTH:
            self.err(at or tree.root.pos, "the tree nests deeper than %d levels: %s adds %d levels below level %d"
                     % (MAX_TREE_DEPTH, os.path.basename(tree.path), height, self.depth))
            return None
        self.repeated += size
        if self.repeated > MAX_REPEATED_NODES:
            if self.repeated - size <= MAX_REPEATED_NODES:   # said once
                self.err(at or tree.root.pos, "includes of files already included expand the tree by more "
                                              "than %d nodes" % MAX_REPEATED_NODES)
            return None
        return tree

    def _measure(self, root: TreeNode) -> Tuple[int, int]:
        """Height and node count of a parsed subtree, includes expanded (iterative, each node once)."""
        sizes = self._sizes
        todo = [root]
        while todo:
            n = todo[-1]
            if n in sizes:
                todo.pop()
                continue
            nk = n.nodekind
            below = nk.expand(n) if nk.own_expand else n.children
            missing = [c for c in below if c not in sizes]
            if missing:
                todo.extend(missing)
                continue
            todo.pop()
            sizes[n] = (1 + max([sizes[c][0] for c in below] or [0]), 1 + sum(sizes[c][1] for c in below))
        return sizes[root]

    def include(self, relpath: str, at: Pos) -> Optional[TreeFile]:
        """A file named relative to the file being parsed."""
        base = os.path.dirname(self.stack[-1]) if self.stack else os.getcwd()
        return self.load_file(os.path.join(base, relpath), at)

    def parse_inputs(self, data: LMap) -> Tuple[Dict[str, Any], List[str]]:
        raw = data.get("inputs") or {}
        inputs: Dict[str, Any] = {}
        required: List[str] = []
        if not isinstance(raw, LMap):
            if raw:
                self.err(pos_of(data, "inputs"), "'inputs' must be a mapping of name: {default: …}")
            return inputs, required
        self.inputs_raw[raw.pos.file] = raw   # where each default is, for the checks' errors
        for name, spec in raw.items():
            if not isinstance(name, str) or not name.isidentifier():
                self.err(raw.key_pos[name], "input name %r is not an identifier%s" % (name, bool_hint(name)))
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
                inputs[name] = self.literal_at(spec, "default", raw.val_pos[name])
            else:
                inputs[name] = REQUIRED
                required.append(name)
        return inputs, required

    # nodes: the generic walk -----------------------------------------------------------
    def node(self, raw: Any, at: Pos) -> Optional[TreeNode]:
        if not isinstance(raw, LMap):
            self.err(at, "a node must be a mapping with one of: %s" % ", ".join(REGISTRY))
            return None
        return self._node(raw)

    def _node(self, raw: LMap) -> Optional[TreeNode]:
        depth = self.depth + 1
        if depth > MAX_TREE_DEPTH:
            self.err(raw.pos, "the tree nests deeper than %d levels%s" % (
                MAX_TREE_DEPTH, " (counting the files that include this one)" if len(self.stack) > 1 else ""))
            return None
        kind = None
        for k in raw:   # a node has few keys, one of them its kind
            if k in _KINDS:
                if kind is not None:
                    kind = self._kind_of(raw)
                    if kind is None:
                        return None
                    break
                kind = k
        if kind is None:
            self._no_kind(raw)
            return None
        nk, allowed, keys, required, inline = _INFO[kind]
        value = raw[kind]
        if inline and isinstance(value, LMap):
            raw = self._inline(raw, kind, allowed)
            value = raw[kind]
        elif value.__class__ is LMap and nk.family == "decorator":   # retry: {attempts: 3, child: …}
            raw = decorator_mapping(self, raw, kind, nk, allowed) or raw
            value = raw[kind]
        meant: Set[str] = set()   # options that unknown keys look like misspellings of
        if not keys.issuperset(raw):
            for k in raw:
                if k != kind and k not in allowed:
                    said = parsehints.foreign_hint(k, kind, allowed, raw, self.definitions)
                    hint = "" if said else did_you_mean(k, allowed + ("children",) if inline else allowed)
                    if inline and (k == "children" or hint == " (did you mean 'children'?)"):
                        hint = _CHILDREN_HINT % (kind, kind, kind)
                        meant.add("children")
                    elif hint or said:
                        meant.update([hint[len(" (did you mean '"):-len("'?)")]] if hint else [])
                        hint = hint or said
                    elif k in LEAF_OPTIONS and nk.family != "leaf":
                        hint = misplaced(k, kind, allowed, nearby(raw, kind))
                    else:
                        hint = option_hint(k, kind, allowed)
                    self.err(raw.key_pos[k], "unknown option %r for %s%s" % (k, kind, hint))
        for o in required:
            if o not in raw and o not in meant:   # a misspelt option is one error, not two
                self.err(raw.key_pos[kind], "%s needs option %r" % (kind, o))
        if "children" in meant and not value:
            value = _NO_CHILDREN   # the list is under the misplaced key: its error is enough
        name = raw.get("name")
        if name is not None and not isinstance(name, str):
            self.err(raw.val_pos["name"], "'name' must be a string")
            name = None
        # positions as the loader stores them: each becomes a Pos only if it is read (see yamlsrc.settle)
        file, value_at = raw._file, raw._vp[kind]
        node = TreeNode(kind, name or "", raw._kp[kind], None, None, nk, value_at, file)
        self.depth = depth
        try:
            node.spec = nk.parse(self, node, raw, value, None if nk.parse_without_pos else node.value_pos)
        finally:
            self.depth = depth - 1
        if not node.name:
            node.name = nk.default_name(node)
        return node

    def _kind_of(self, raw: LMap) -> Optional[str]:
        """The kind of a node with several kind keys: the one that is not an option of another (else None,
        after reporting)."""
        kinds = [k for k in raw if k in REGISTRY]   # in the order written, for the messages
        kinds = [k for k in kinds if not any(k in _OPTION_NAMES[o] for o in kinds if o != k)]
        if len(kinds) == 1:
            return kinds[0]
        if not kinds:
            self._no_kind(raw)
        else:
            self.err(raw.key_pos[kinds[1]], "node has two kinds, %r and %r: %s" % (
                kinds[0], kinds[1], nest_hint(raw, kinds[0], kinds[1])))
        return None

    def _no_kind(self, raw: LMap) -> None:
        unknown = [k for k in raw if k not in _COMMON]
        first = unknown[0] if unknown else None
        if first is not None:
            self.err(raw.key_pos[first], "unknown node kind %r%s" % (
                first, kind_hint(first, self.definitions) or did_you_mean(first, REGISTRY)))
            othernames.check_inside(self, raw, first)
        else:
            self.err(raw.pos, "node has no kind (one of: %s)" % ", ".join(REGISTRY))

    def _inline(self, outer: LMap, kind: str, allowed: Tuple[str, ...]) -> LMap:
        """``selector: {name: …, children: […]}`` read as ``selector: […]`` with options beside it."""
        inner: LMap = outer[kind]
        merged = LMap()
        merged.pos, merged.key_pos, merged.val_pos = outer.pos, {}, {}
        misspelt = False   # 'chilren:': its error says it all
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
                    hint = "" if parsehints.foreign_option(k) else did_you_mean(k, allowed + ("children",))
                    misspelt = misspelt or hint == " (did you mean 'children'?)"
                    if not hint and k in LEAF_OPTIONS:
                        hint = misplaced(k, kind, allowed, nearby(inner, "children"))
                    elif not hint:
                        hint = option_hint(k, kind, allowed)
                    self.err(src.key_pos[k], "unknown option %r for %s%s" % (k, kind, hint))
                    continue
                merged[k] = v
                merged.key_pos[k], merged.val_pos[k] = src.key_pos[k], src.val_pos[k]
        merged[kind] = inner.get("children", _NO_CHILDREN)
        merged.key_pos[kind] = outer.key_pos[kind]
        merged.val_pos[kind] = inner.val_pos.get("children", inner.pos)
        misspelt = misspelt or any(k == "children" or did_you_mean(k, allowed + ("children",)) ==
                                   " (did you mean 'children'?)" for k in outer if k != kind and k not in allowed)
        if "children" not in inner and not misspelt:
            self.err(inner.pos, "%s needs 'children' (a list of nodes)" % kind)
        return merged

    # helpers for the kinds -------------------------------------------------------------
    def child(self, node: TreeNode, raw: Any, at: Pos) -> None:
        if raw.__class__ is LList:   # child: [a, b]: one error, and each of a and b checked all the same
            self.err(at, one_child(node.kind, "child" in _OPTION_NAMES[node.kind], len(raw)))
            for item in raw:
                if item.__class__ is LMap:
                    self.node(item, item.pos)
            return
        c = self.node(raw, at)
        if c is not None:
            node.children.append(c)

    def children(self, node: TreeNode, value: Any, at: Pos) -> None:
        if value is _NO_CHILDREN:   # already reported (see _inline)
            return
        if not isinstance(value, LList) or not value:
            self.err(at, "%s takes a non-empty list of children" % node.kind)
            return
        append, parse, parse_map = node.children.append, self.node, self._node
        for i, item in enumerate(value):   # a mapping's item position is read only for errors
            c = parse_map(item) if item.__class__ is LMap else parse(item, value.item_pos[i])
            if c is not None:
                append(c)

    def typed(self, node: TreeNode, label: str, value: Any, at: Pos, type_name: str) -> Any:
        """``value`` if it is of the type, else None after reporting ``label of kind must be …``."""
        t = TYPES[type_name]
        if type_name in PARAM_TYPES and isinstance(value, str) and value.startswith("$") and not value.startswith("$$"):
            try:   # a reference or an expression: checked when the node starts
                return literal(value)
            except RefError as exc:
                self.err(Pos(at.file, at.line, at.column + exc.offset), "%s of %s: %s" % (label, node.kind, exc))
                return None
        if t.ok is not None and not t.ok(value):
            if type_name == "bool":
                self.err(at, "%r must be true or false" % label)
            else:
                self.err(at, "%s of %s must be %s, got %s%s" % (label, node.kind, t.expect, shown(value),
                                                                bool_hint(value)))
            return None
        return value

    def opt(self, node: TreeNode, raw: LMap, option: Option) -> Any:
        """An option's value (checked against its type) or its default."""
        default = None if option.default is NO_DEFAULT else option.default
        if option.name not in raw:
            return default
        v = self.typed(node, option.name, raw[option.name], raw.val_pos[option.name], option.type)
        return default if v is None else v

    def mapping(self, raw: LMap, key: str, at: Pos, message: str) -> LMap:
        """An optional mapping option (empty when absent or wrong, after reporting)."""
        value = raw.get(key) or {}
        if isinstance(value, LMap):
            return value
        if value:
            self.err(raw.val_pos[key], message)
        empty = LMap()
        empty.pos, empty.key_pos, empty.val_pos = at, {}, {}
        return empty

    def literal_at(self, raw: Any, key: Any, at: Pos) -> Any:
        """A value (references, ``$( … )`` expressions and ``{…}`` templates parsed) or None after reporting."""
        value = raw[key]
        where = pos_of(raw, key, at)
        if isinstance(value, str) and parsehints.quoted_mapping(value):   # "{x: 1, y: 2}": no mapping, text
            named = key if isinstance(key, str) and key not in REGISTRY else None   # (not `switch: …`)
            self.err(where, parsehints.quoted_mapping_message(value, named))
            return None
        if value.__class__ is LMap or value.__class__ is LList:
            hint = unquoted(raw, key, value)
            if hint:   # said if the value must be text (a kind's error at ``where`` says "takes text")
                self._unquoted[where] = hint
        for name in loose_dollars(value):
            self.warn(where, "'$%s' inside text is sent as written, not replaced: write '{%s}' to insert the "
                             "value of %s" % (name, name, name))
        try:
            return literal(value)
        except RefError as exc:
            if isinstance(value, str):  # the column of the problem, when the value is a one-line scalar
                where = Pos(where.file, where.line, where.column + exc.offset)
            self.err(where, str(exc))
            return None

    def target(self, node: TreeNode, value: Any, at: Pos, what: str) -> Optional[Tuple[ModuleDefinition, str]]:
        """``module.member`` against the definitions."""
        if not isinstance(value, str) or value.count(".") != 1:
            self.err(at, "%s takes 'module.%s', got %r" % (node.kind, what, value))
            return None
        mod_name, member = value.split(".")
        mod = self.definitions.get(mod_name)
        if mod is None:
            close = did_you_mean(mod_name, self.definitions)
            self.err(at, "unknown module %r%s" % (mod_name, close or (
                " (known: %s; give your module's definition with --modules FILE.json or a folder of them, or source "
                "the catkin workspace of the package that exports it)"
                % ", ".join(sorted(self.definitions)))), "" if close else mod_name)
            return None
        return mod, member

    def key_map(self, node: TreeNode, raw: LMap, key: str, allowed: Optional[Dict[str, Any]],
                what: str) -> Dict[str, str]:
        """``outputs``: {output name: tree key}; ``allowed`` None: names not known (an unknown
        function, already an error), so its keys still count as written and nothing follows from it."""
        value = raw.get(key) or {}
        if not isinstance(value, LMap):
            if value:
                self.err(raw.val_pos[key], "%r must be a mapping of %s name: tree key" % (key, what))
            return {}
        out = {}
        target = getattr(node.spec, "target", None) or raw.get(node.kind, node.kind)
        for name, key_ in value.items():
            if allowed is not None and name not in allowed:
                turned = isinstance(key_, str) and key_ in allowed and name.isidentifier()   # SMACH's remapping order
                self.err(value.key_pos[name], "%s has no %s %r%s" % (target, what, name, (
                    "; %s maps %s name → tree key: did you mean {%s: %s}?" % (key, what, key_, name)) if turned
                    else closest(name, allowed, what)))
                if isinstance(key_, str) and key_.isidentifier():
                    out[name] = key_   # its key still counts as written: no knock-on "no node writes" below
            elif not isinstance(key_, str) or not key_.isidentifier():
                hint, out[name] = parsehints.key_fix(key_)   # "{obj_pos}": obj_pos meant (written: no knock-on error)
                self.err(value.val_pos[name], "tree key %r is not an identifier%s" % (
                    key_, hint or bool_hint(key_)))
            else:
                out[name] = key_
        return out

    def keys(self, node: TreeNode, value: Any, at: Pos, what: str) -> Optional[LMap]:
        """A non-empty mapping whose keys are tree keys."""
        if not isinstance(value, LMap) or not value:
            self.err(at, "%s takes a non-empty mapping of %s" % (node.kind, what))
            return None
        for k in value:
            if not isinstance(k, str) or not k.isidentifier():
                self.err(value.key_pos[k], "tree key %r is not an identifier%s" % (k, bool_hint(k)))
        return value


def load_tree(path: str, definitions: Mapping[str, ModuleDefinition],
              loader: Optional[Callable[[str], str]] = None, given: Set[str] = frozenset()) -> TreeFile:
    """Parse and validate a tree file and its includes; TreeErrors lists every problem.

    Args:
        given: tree inputs the caller will set (e.g. from the command line).
    """

    parser = Parser(definitions, loader or read_text)
    found: List[TreeError] = []
    with gc_paused():
        tree = parser.load_file(path, None)
        errors = list(parser.errors)
        if tree is not None:
            nodes = nodes_of(top_of(tree))
            errors.extend(check_flow(tree, frozenset(given)))
            reserved, reserved_warned = reserved_key_problems(tree, list(parser.files.values()), nodes)
            errors.extend(reserved)
            typed = check_types(tree, nodes, frozenset(given), parser.inputs_raw)
            warned = {e for e in typed if e.message.startswith("warning: ")}
            errors.extend(e for e in typed if e not in warned)
            found = sorted(set(parser.warnings) | set(warnings(nodes)) | warned | set(reserved_warned),
                           key=lambda e: (e.pos.file, e.pos.line, e.pos.column, e.message))
            if not errors:
                tree.warnings = found
        else:
            found = list(parser.warnings)
    if errors:
        raise TreeErrorsWithWarnings(errors, found)
    assert tree is not None
    return tree

