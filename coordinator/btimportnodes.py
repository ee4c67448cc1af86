"""``bmtree import``: BehaviorTree.CPP nodes (XML elements) turned into bmtree nodes.

Each node becomes an :class:`Out` (its YAML keys in order, and the element it came from, so that a problem
the tree checks find later is said at the XML's line). Every problem is collected, never a placeholder
written. SubTrees are inlined (see ``btimport``'s docstring for why). The decorators and controls are in
``btimportcontrols``, the reactive controls in ``btimportreactive``.
"""
from __future__ import annotations

import re
from typing import Any, Dict, List, Mapping, Optional, Set, Tuple, Union

from comm.errors import did_you_mean
from coordinator.btimportcontrols import Controls, seconds
from coordinator.btimportports import (
    Lit,
    Out,
    OutOfRange,
    Scope,
    escape_text,
    find_function,
    is_text,
    key_ref,
    plain_literal,
    typed_literal,
)
from coordinator.btimportreactive import POLL_DEFAULT, Reactive
from coordinator.btxml import Element
from coordinator.errors import Pos, TreeError
from coordinator.language import MAX_REPEATED_NODES, MAX_TREE_DEPTH
from coordinator.othernames import CONDITIONS, OTHER_KINDS
from modules.definition import ModuleDefinition

__all__ = ["Out", "Converter"]

_IGNORED = ("name", "ID", "_description", "_uid", "_fullpath")   # Groot's notes: nothing to run
_COMPOSITES = {"Sequence": "sequence", "SequenceStar": "sequence", "SequenceWithMemory": "sequence",
               "Fallback": "selector"}   # the reactive ones: btimportreactive
_MEMORY = ("SequenceStar", "SequenceWithMemory")
_SIMPLE_DECORATORS = {"Inverter": "inverter", "ForceSuccess": "force_success", "ForceFailure": "force_failure"}
_WRAPPERS = ("Action", "Condition", "Control", "Decorator")


def _snake(name: str) -> str:
    s = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name)
    s = re.sub(r"\W+", "_", s).strip("_").lower()
    return s if s and not s[0].isdigit() else "t_" + s


class Converter(Controls, Reactive):
    """Converts the trees of one file, collecting every problem in ``errors``."""

    def __init__(self, trees: Mapping[str, Element], version: int, definitions: Mapping[str, ModuleDefinition],
                 maps: Mapping[str, str], models: Optional[Mapping[str, str]] = None, poll: float = POLL_DEFAULT,
                 forever: Optional[int] = None, renames: Optional[Mapping[str, Mapping[str, Optional[str]]]] = None):
        self.trees = trees
        self.renames = renames or {}   # ID -> port -> the function's input/output it is (None: dropped)
        self.forever = forever   # what a count of -1 (for ever) becomes (--forever N); None: an error
        self.notes: List[TreeError] = []   # warnings of the conversion (a count made bounded)
        self.models = models or {}   # ID -> Action or Condition, as TreeNodesModel declares it
        self.poll = poll   # seconds between two checks of a reactive node's Conditions
        self.lastings: Dict[int, Any] = {}   # id(element) -> whether it can run (btimportreactive)
        self.version = version
        self.definitions = definitions
        self.maps = maps
        self.errors: List[TreeError] = []
        self.reads: Set[str] = set()     # keys of the main tree read (candidates for the tree's inputs)
        self.written: Set[str] = set()
        self.stack: Tuple[str, ...] = ()
        self.depth = 0
        self.count = 0
        self.flags = 0
        self.rerun = 0   # > 0 below a node that ticks its child again after a failure (a retry, a reactive parent)
        self.initial: Dict[str, Any] = {}   # generated keys set before the tree runs
        self.from_ms: Set[Tuple[int, int]] = set()   # elements whose seconds were milliseconds
        # what reads or writes each key: a port's definition, or "whole"/"number" (a count, milliseconds)
        self.uses: Dict[str, List[Any]] = {}
        self.literals: List[Tuple[Dict[str, Any], str, str, Element, str]] = []   # SetBlackboard's, typed last

    def err(self, pos: Pos, message: str) -> None:
        self.errors.append(TreeError(pos, message))

    # trees ------------------------------------------------------------------------------------
    def tree(self, tree_id: str, scope: Scope, at: Element) -> Optional[Out]:
        el = self.trees[tree_id]
        if tree_id in self.stack:
            self.err(at.pos, "SubTree %r includes itself: %s" % (tree_id, " -> ".join(self.stack + (tree_id,))))
            return None
        if len(el.children) != 1:
            self.err(el.pos, "BehaviorTree %r has %s: BehaviorTree.CPP takes exactly one (wrap several in a "
                             "Sequence)" % (tree_id, "no node" if not el.children else "%d nodes" % len(el.children)))
            for c in el.children:
                self.node(c, scope)
            return None
        self.stack += (tree_id,)
        try:
            return self.node(el.children[0], scope)
        finally:
            self.stack = self.stack[:-1]

    def finish(self) -> None:
        """Type SetBlackboard's literals from the ports that use their keys (all converted by now)."""
        for table, key, text, el, where in self.literals:
            table[key] = self.set_literal(key, text, el, where)

    # nodes ------------------------------------------------------------------------------------
    def node(self, el: Element, scope: Scope) -> Optional[Out]:
        self.count += 1
        if self.count == MAX_REPEATED_NODES + 1:
            self.err(el.pos, "the tree, its SubTrees inlined, has more than %d nodes" % MAX_REPEATED_NODES)
        if self.count > MAX_REPEATED_NODES:
            return None
        if self.depth >= MAX_TREE_DEPTH:
            self.err(el.pos, "the tree nests deeper than %d levels, its SubTrees inlined (bmtree's limit)"
                     % MAX_TREE_DEPTH)
            return None
        kind = el.tag
        if kind in _WRAPPERS:
            kind = el.attrs.get("ID", "")
            if not kind:
                self.err(el.pos, "<%s> needs an ID (the node's type)" % el.tag)
                return None
        self.depth += 1
        try:
            out = self._node(el, kind, scope)
        finally:
            self.depth -= 1
        return out.named(el.attrs.get("name")) if out is not None else None

    def _node(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        if kind in _COMPOSITES:
            self.attrs(el, kind, ())
            kids = self.kids(el, kind, scope, 1)
            if kids is None:
                return None
            if kind in _MEMORY and self.rerun and len(kids) > 1:
                return self.memory_sequence(el, kids)
            return Out(el.pos, (_COMPOSITES[kind], kids))
        if kind in _SIMPLE_DECORATORS:
            self.attrs(el, kind, ())
            child = self.one_child(el, kind, scope)
            return Out(el.pos, (_SIMPLE_DECORATORS[kind], child)) if child is not None else None
        method = getattr(self, "_" + kind, None)
        if method is not None:
            return method(el, kind, scope)   # type: ignore[no-any-return]
        if re.match(r"^Switch[2-6]$", kind):
            return self._switch(el, kind, scope)
        if kind in ("SubTree", "SubTreePlus"):
            return self.subtree(el, kind, scope)
        if self.version < 4 and kind in self.trees and kind not in self.maps and not el.children:
            return self.subtree(el, "SubTree", scope, kind)   # BehaviorTree.CPP 3: <Talk/> is <SubTree ID="Talk"/>
        other = OTHER_KINDS.get(re.sub(r"[_\-]", "", kind).lower()) if "." not in kind else None
        if other is not None:
            self.err(el.pos, "%s is not converted: bmtree has no such node (%s); write that in the YAML by hand, or "
                             "change the XML" % (kind, other[1]))
            return None
        if el.children:
            self.err(el.pos, "%s is not converted: a custom control or decorator node, which bmtree cannot run; write "
                             "it with bmtree's kinds (trees/README.md)" % kind)
            for c in el.children:
                self.node(c, scope)
            return None
        return self.action(el, kind, scope)

    def skipped(self, el: Element, k: str, what: str) -> bool:
        """True for an attribute that is not a port: Groot's bookkeeping (ignored), or a pre/post condition
        (reported: not converted)."""
        if k in _IGNORED:
            return True
        if k.lower() in CONDITIONS:
            self.err(el.at(k), "%s of %s (a BehaviorTree.CPP pre/post condition) is not converted: write %s"
                     % (k, what, CONDITIONS[k.lower()]))
            return True
        return False

    def attrs(self, el: Element, kind: str, allowed: Tuple[str, ...]) -> Dict[str, str]:
        """The attributes of a built-in node, each not in ``allowed`` reported."""
        out = {}
        for k, v in el.attrs.items():
            if self.skipped(el, k, kind):
                continue
            if k not in allowed:
                self.err(el.at(k), "%s has no attribute %r (%s)%s" % (
                    kind, k, "it takes %s" % ", ".join(allowed) if allowed else "it takes only name",
                    did_you_mean(k, allowed)))
            else:
                out[k] = v
        return out

    def kids(self, el: Element, kind: str, scope: Scope, least: int, most: int = 0) -> Optional[List[Out]]:
        """Every child converted (all, for their problems), or None."""
        done = [self.node(c, scope) for c in el.children]
        n = len(el.children)
        if n < least or (most and n > most):
            want = ("%d" % least if least == most else "%d or %d" % (least, most)) if most else "at least %d" % least
            one = (most or least) == 1   # "exactly 1", "at least 1": one child; otherwise children
            self.err(el.pos, "%s takes %s child%s, it has %d" % (kind, want, "" if one else "ren", n))
            return None
        kids = [c for c in done if c is not None]
        return kids if len(kids) == n else None

    def one_child(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        kids = self.kids(el, kind, scope, 1, 1)
        return kids[0] if kids else None

    def number(self, el: Element, kind: str, attr: str, scope: Scope, whole: bool,
               default: Optional[str] = None) -> Any:
        """A count or milliseconds attribute: a number, ``$key`` (a blackboard port), or None after reporting."""
        raw = el.attrs.get(attr, default)
        if raw is None:
            self.err(el.pos, "%s needs %s" % (kind, attr))
            return None
        ref = key_ref(raw)
        where: Any = el.at(attr)
        if ref is not None:
            key = self.use_key(el, attr, ref, scope, False, "whole" if whole else "number")
            if not isinstance(key, Lit):
                return None if key is None else "$" + key
            raw, where = key.text, key.where   # a SubTree gave the literal
        try:
            value = plain_literal(raw)
        except OutOfRange as exc:
            self.err(el.at(attr), "%s of %s is %s%s" % (attr, kind, exc, _from(where, el.at(attr))))
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (whole and not isinstance(value, int)):
            self.err(el.at(attr), "%s of %s must be a %s, got %r%s" % (attr, kind, "whole number" if whole else
                                                                     "number", raw, _from(where, el.at(attr))))
            return None
        if value < 0 and whole and self.forever:
            self.notes.append(TreeError(el.at(attr), "warning: %s of %s is %s (for ever): written as %d (--forever)"
                                        % (attr, kind, raw.strip(), self.forever)))
            return self.forever
        if value < 0:
            self.err(el.at(attr), "%s of %s is %s (for ever): every bmtree loop and wait is bounded; give the most "
                                  "it may take%s" % (attr, kind, raw.strip(), ", or --forever N to write N for each"
                                                     if whole else ""))
            return None
        return value

    def use_key(self, el: Element, attr: str, ref: str, scope: Scope, write: bool,
                use: Any = None) -> Union[str, Lit, None]:
        """The tree key a port's ``{ref}`` names (or the literal a SubTree gave it); None after reporting.
        ``use``: the port's definition (or "whole"/"number"), which types a SetBlackboard literal of the key."""
        value, root = scope.resolve(attr if ref in ("=", "") else ref)
        if isinstance(value, Lit):
            return value
        if not value.isidentifier():
            self.err(el.at(attr), "blackboard key %r is no bmtree tree key (letters, digits and _, not starting "
                                  "with a digit): rename it in the XML" % value)
            return None
        if write:
            self.written.add(value)
        elif root:
            self.reads.add(value)
        if use is not None:
            self.uses.setdefault(value, []).append(use)
        return value

    # leaves -----------------------------------------------------------------------------------
    def action(self, el: Element, node_id: str, scope: Scope) -> Optional[Out]:
        word = "Condition" if el.tag == "Condition" else "Action"
        fn, why = find_function(node_id, self.definitions, self.maps)
        if fn is None:
            if node_id in self.trees:
                why += "; %r is a BehaviorTree of this file, which format 4 includes with <SubTree ID=\"%s\"/>" % (
                    node_id, node_id)
            self.err(el.pos, "%s %r %s" % (word, node_id, why))
            return None
        inputs: Dict[str, Any] = {}
        outputs: Dict[str, str] = {}
        said = "%s %r (%s)" % (word, node_id, fn.qualified)
        renamed = self.renames.get(node_id, {})
        for port, name in renamed.items():
            if name is not None and fn.input(name) is None and fn.output(name) is None:
                self.err(el.pos, "--map %s renames port %s to %r, which %s does not have: its inputs: %s; its "
                                 "outputs: %s" % (node_id, port, name, fn.qualified,
                                                  ", ".join(p.name for p in fn.inputs) or "none",
                                                  ", ".join(p.name for p in fn.outputs) or "none"))
                return None
        given = set()
        for port, v in el.attrs.items():
            if self.skipped(el, port, node_id) or (port in renamed and renamed[port] is None):
                continue
            k = renamed.get(port) or port   # the function's name for it (the XML's for positions and messages)
            given.add(k)
            p_in, p_out, ref = fn.input(k), fn.output(k), key_ref(v)
            if p_in is None and p_out is None:
                names = [p.name for p in fn.inputs + fn.outputs]
                self.err(el.at(port), "%s has no port %r: its inputs: %s; its outputs: %s%s" % (
                    said, k, ", ".join(p.name for p in fn.inputs) or "none",
                    ", ".join(p.name for p in fn.outputs) or "none",
                    did_you_mean(k, names) or (" (rename it: --map '%s=%s(%s=INPUT)', or drop it: -%s)"
                                               % (node_id, fn.qualified, port, port) if port == k else "")))
                continue
            if p_in is not None:
                self.input(el, port, v, ref, p_in, scope, said, inputs)
                if port != k and port in inputs:
                    inputs[k] = inputs.pop(port)
            if p_out is None:
                continue
            if ref is None and self.version < 4 and v.strip() and p_in is None:
                ref = v.strip()   # BehaviorTree.CPP 3 writes an output to the key its bare word names
            if ref is None:
                if v.strip() and p_in is None:
                    self.err(el.at(port), "%s: %r is an output: give it the blackboard key to write, %s=\"{key}\", "
                                          "not %r" % (said, port, port, v))
                continue   # "" (Groot 1 writes it for a port left empty): BehaviorTree.CPP keeps no output either
            key = self.use_key(el, port, ref, scope, True, "text" if is_text(p_out) else p_out)
            if isinstance(key, Lit):
                self.err(el.at(port), "%s: %r is an output, but the SubTree gives it the literal %r (%s): give it a "
                                      "{key}" % (said, port, key.text, key.where))
            elif key is not None:
                outputs[k] = key
        for p in fn.inputs:
            if p.name in _IGNORED:
                self.err(el.pos, "%s: the function's input %r cannot be a port in BehaviorTree.CPP XML (%s= is the "
                                 "node's own there): --map %s to another function, or write this node in the YAML "
                                 "by hand" % (said, p.name, p.name, node_id))
            elif p.name not in given:
                self.err(el.pos, "%s: no port %s, the function's input: give %s=\"…\" or %s=\"{key}\"" % (
                    said, p.name, p.name, p.name))
        items: List[Tuple[str, Any]] = [("call", fn.qualified)]
        items += [("inputs", inputs)] if inputs else []
        items += [("outputs", outputs)] if outputs else []
        return Out(el.pos, *items)

    def input(self, el: Element, k: str, v: str, ref: Optional[str], param: Any, scope: Scope, said: str,
              inputs: Dict[str, Any]) -> None:
        """One input port's value into ``inputs`` (``$key``, or the literal typed by the definition)."""
        text, where = v, el.at(k)
        if ref is not None:
            key = self.use_key(el, k, ref, scope, False, "text" if is_text(param) else param)
            if not isinstance(key, Lit):
                if key is not None:
                    inputs[k] = "$" + key
                return
            text, where = key.text, key.where
        try:
            value, want = typed_literal(text, param)
        except OutOfRange as exc:
            self.err(el.at(k), "%s: input %r is %s%s" % (said, k, exc, _from(where, el.at(k))))
            return
        if want:
            self.err(el.at(k), "%s: input %r takes %s, got %r%s" % (said, k, want, text, _from(where, el.at(k))))
        else:
            inputs[k] = value

    def _SetBlackboard(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        a = self.attrs(el, kind, ("output_key", "value"))
        for need in ("output_key", "value"):
            if need not in a:
                self.err(el.pos, "SetBlackboard needs %s" % need)
        if len(a) < 2:
            return None
        target = key_ref(a["output_key"]) or a["output_key"].strip()
        key = self.use_key(el, "output_key", target, scope, True)
        if isinstance(key, Lit):
            self.err(el.at("output_key"), "SetBlackboard: output_key is given the literal %r by the SubTree (%s): "
                                          "give it a {key}" % (key.text, key.where))
            return None
        ref = key_ref(a["value"])
        text: Optional[str] = a["value"]
        where = str(el.at("value"))
        got: Union[str, Lit, None] = None
        if ref is not None:
            got = self.use_key(el, "value", ref, scope, False)
            if isinstance(got, Lit):
                text, where = got.text, got.where
            elif got is None:
                return None
        if key is None:
            return None
        if isinstance(got, str):   # a copy of another key
            return Out(el.pos, ("set", {key: "$" + got}))
        table: Dict[str, Any] = {key: text}
        self.literals.append((table, key, text or "", el, where))   # typed by finish(), once every reader is known
        return Out(el.pos, ("set", table))

    def set_literal(self, key: str, text: str, el: Element, where: str) -> Any:
        """A SetBlackboard literal as the ports that use its key take it: BehaviorTree.CPP stores the string, which
        each reader converts; text when one reads text or none says (a number, when only numbers are read)."""
        uses = self.uses.get(key, [])
        if not uses or "text" in uses:
            return escape_text(text)
        try:
            if isinstance(uses[0], str):   # a count or milliseconds
                value = plain_literal(text)
                return value if isinstance(value, (int, float)) and not isinstance(value, bool) else escape_text(text)
            value, bad = typed_literal(text, uses[0])
        except OutOfRange as exc:
            self.err(el.at("value"), "value of SetBlackboard is %s%s" % (exc, _from(where, el.at("value"))))
            return None
        return escape_text(text) if bad else value   # the check then says which reader cannot take text

    def _Sleep(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ("msec",))
        ms = self.number(el, kind, "msec", scope, False)
        self.from_ms.add((el.pos.line, el.pos.column))
        return Out(el.pos, ("wait", seconds(ms))) if ms is not None else None

    def _AlwaysSuccess(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ())
        return Out(el.pos, ("check", "true"))

    def _AlwaysFailure(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ())
        return Out(el.pos, ("fail", escape_text(el.attrs.get("name") or kind)))

    # subtrees ---------------------------------------------------------------------------------
    def subtree(self, el: Element, kind: str, scope: Scope, implicit: str = "") -> Optional[Out]:
        """A SubTree inlined (``implicit``: BehaviorTree.CPP 3's ``<Talk/>`` for ``<SubTree ID="Talk"/>``)."""
        sid = implicit or el.attrs.get("ID", "")
        if sid not in self.trees:
            self.err(el.at("ID"), "SubTree %r: no BehaviorTree of that ID in the file (%s)%s" % (
                sid, ", ".join(sorted(self.trees)), did_you_mean(sid, self.trees)))
            return None
        plain = self.version < 4 and kind == "SubTree"   # v3: a port's value is the caller's key, braces or not
        flags = {"_autoremap", "__autoremap", "__shared_blackboard"}
        auto = any(el.attrs.get(f, "").strip().lower() in ("true", "1") for f in flags)
        remap: Dict[str, Tuple[Union[str, Lit], bool]] = {}
        for k, v in el.attrs.items():
            if k in _IGNORED or k in flags:
                continue
            if k.lower() in CONDITIONS:
                self.err(el.at(k), "%s of SubTree (a BehaviorTree.CPP pre/post condition) is not converted: write %s"
                         % (k, CONDITIONS[k.lower()]))
                continue
            ref = key_ref(v)
            ref = v.strip() if ref is None and plain else ref
            if ref is None:
                remap[k] = (Lit(v, str(el.at(k))), False)
                continue
            value, root = scope.resolve(k if ref in ("=", "") else ref)
            if isinstance(value, str) and not value.isidentifier():
                self.err(el.at(k), "blackboard key %r is no bmtree tree key (letters, digits and _, not starting with "
                                   "a digit): rename it in the XML" % value)
                continue
            remap[k] = (value, root)
        out = self.tree(sid, Scope(scope, remap, auto, _snake(sid) + "_"), el)
        if out is None:
            return None
        # the caller's name, as BehaviorTree.CPP shows the SubTree node; else the subtree's root's, else its ID
        return out.named(el.attrs.get("name"), replace=True).named(sid)


def _from(where: Any, at: Pos) -> str:
    """`` (given by the SubTree at …)`` when a literal came from elsewhere."""
    return "" if str(where) == str(at) else " (given by the SubTree at %s)" % where
