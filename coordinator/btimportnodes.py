"""``bmtree import``: BehaviorTree.CPP nodes (XML elements) turned into bmtree nodes.

Each node becomes an :class:`Out` (its YAML keys in order, and the element it came from, so that a problem
the tree checks find later is said at the XML's line). Every problem is collected, never a placeholder
written. SubTrees are inlined (see ``btimport``'s docstring for why).
"""
from __future__ import annotations

import re
from typing import Any, Dict, List, Mapping, Optional, Set, Tuple, Union

from comm.errors import did_you_mean
from coordinator.btimportports import (
    Lit,
    Scope,
    escape_text,
    find_function,
    key_ref,
    plain_literal,
    typed_literal,
)
from coordinator.btxml import Element
from coordinator.errors import Pos, TreeError
from coordinator.language import MAX_REPEATED_NODES, MAX_TREE_DEPTH
from coordinator.othernames import CONDITIONS, OTHER_KINDS
from modules.definition import ModuleDefinition

__all__ = ["Out", "Converter"]

_IGNORED = ("name", "ID", "_description", "_uid", "_fullpath")   # Groot's notes: nothing to run
_COMPOSITES = {"Sequence": ("sequence", None), "SequenceStar": ("sequence", None),
               "SequenceWithMemory": ("sequence", None), "ReactiveSequence": ("sequence", False),
               "Fallback": ("selector", None), "ReactiveFallback": ("selector", False)}
_SIMPLE_DECORATORS = {"Inverter": "inverter", "ForceSuccess": "force_success", "ForceFailure": "force_failure"}
_WRAPPERS = ("Action", "Condition", "Control", "Decorator")


class Out:
    """A converted node: its YAML keys in order (the kind first), and the element it came from."""

    __slots__ = ("pos", "items")

    def __init__(self, pos: Pos, *items: Tuple[str, Any]):
        self.pos = pos
        self.items = list(items)

    def named(self, name: Optional[str]) -> Out:
        if name and not any(k == "name" for k, _v in self.items):
            self.items.insert(1, ("name", name))
        return self


def _snake(name: str) -> str:
    s = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name)
    s = re.sub(r"\W+", "_", s).strip("_").lower()
    return s if s and not s[0].isdigit() else "t_" + s


class Converter:
    """Converts the trees of one file, collecting every problem in ``errors``."""

    def __init__(self, trees: Mapping[str, Element], version: int, definitions: Mapping[str, ModuleDefinition],
                 maps: Mapping[str, str]):
        self.trees = trees
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
            bm, memory = _COMPOSITES[kind]
            self.attrs(el, kind, ())
            kids = self.kids(el, kind, scope, 1)
            return Out(el.pos, (bm, kids), *([("memory", memory)] if memory is not None else [])) \
                if kids is not None else None
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
        where = el.at(attr)
        if ref is not None:
            key = self.use_key(el, attr, ref, scope, False)
            if not isinstance(key, Lit):
                return None if key is None else "$" + key
            raw, where = key.text, key.where   # a SubTree gave the literal
        value = plain_literal(raw)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (whole and not isinstance(value, int)):
            self.err(el.at(attr), "%s of %s must be a %s, got %r%s" % (attr, kind, "whole number" if whole else
                                                                     "number", raw, _from(where, el.at(attr))))
            return None
        if value < 0:
            self.err(el.at(attr), "%s of %s is %s (for ever): every bmtree loop and wait is bounded; give the most "
                                  "it may take" % (attr, kind, raw.strip()))
            return None
        return value

    def use_key(self, el: Element, attr: str, ref: str, scope: Scope, write: bool) -> Union[str, Lit, None]:
        """The tree key a port's ``{ref}`` names (or the literal a SubTree gave it); None after reporting."""
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
        return value

    # leaves -----------------------------------------------------------------------------------
    def action(self, el: Element, node_id: str, scope: Scope) -> Optional[Out]:
        word = "Condition" if el.tag == "Condition" else "Action"
        fn, why = find_function(node_id, self.definitions, self.maps)
        if fn is None:
            self.err(el.pos, "%s %r %s" % (word, node_id, why))
            return None
        inputs: Dict[str, Any] = {}
        outputs: Dict[str, str] = {}
        said = "%s %r (%s)" % (word, node_id, fn.qualified)
        for k, v in el.attrs.items():
            if self.skipped(el, k, node_id):
                continue
            p_in, p_out, ref = fn.input(k), fn.output(k), key_ref(v)
            if p_in is None and p_out is None:
                names = [p.name for p in fn.inputs + fn.outputs]
                self.err(el.at(k), "%s has no port %r: its inputs: %s; its outputs: %s%s" % (
                    said, k, ", ".join(p.name for p in fn.inputs) or "none",
                    ", ".join(p.name for p in fn.outputs) or "none", did_you_mean(k, names)))
            elif p_in is not None:
                text, where = v, el.at(k)
                if ref is not None:
                    key = self.use_key(el, k, ref, scope, False)
                    if not isinstance(key, Lit):
                        if key is not None:
                            inputs[k] = "$" + key
                        continue
                    text, where = key.text, key.where
                value, want = typed_literal(text, p_in)
                if want:
                    self.err(el.at(k), "%s: input %r takes %s, got %r%s" % (said, k, want, text, _from(where, el.at(k))))
                else:
                    inputs[k] = value
            elif ref is None:
                self.err(el.at(k), "%s: %r is an output: give it the blackboard key to write, %s=\"{key}\", not %r"
                         % (said, k, k, v))
            else:
                key = self.use_key(el, k, ref, scope, True)
                if isinstance(key, Lit):
                    self.err(el.at(k), "%s: %r is an output, but the SubTree gives it the literal %r (%s): give it a "
                                       "{key}" % (said, k, key.text, key.where))
                elif key is not None:
                    outputs[k] = key
        for p in fn.inputs:
            if p.name in _IGNORED:
                self.err(el.pos, "%s: the function's input %r cannot be a port in BehaviorTree.CPP XML (%s= is the "
                                 "node's own there): --map %s to another function, or write this node in the YAML "
                                 "by hand" % (said, p.name, p.name, node_id))
            elif p.name not in el.attrs:
                self.err(el.pos, "%s: no port %s, the function's input: give %s=\"…\" or %s=\"{key}\"" % (
                    said, p.name, p.name, p.name))
        items: List[Tuple[str, Any]] = [("call", fn.qualified)]
        items += [("inputs", inputs)] if inputs else []
        items += [("outputs", outputs)] if outputs else []
        return Out(el.pos, *items)

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
        value: Any = plain_literal(a["value"])
        if ref is not None:
            got = self.use_key(el, "value", ref, scope, False)
            value = plain_literal(got.text) if isinstance(got, Lit) else None if got is None else "$" + got
        return Out(el.pos, ("set", {key: value})) if key is not None and value is not None else None

    def _Sleep(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ("msec",))
        ms = self.number(el, kind, "msec", scope, False)
        return Out(el.pos, ("wait", _seconds(ms))) if ms is not None else None

    def _AlwaysSuccess(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ())
        return Out(el.pos, ("check", "true"))

    def _AlwaysFailure(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ())
        return Out(el.pos, ("fail", escape_text(el.attrs.get("name") or kind)))

    # decorators -------------------------------------------------------------------------------
    def _loop(self, el: Element, kind: str, scope: Scope, attr: str, bm: str) -> Optional[Out]:
        self.attrs(el, kind, (attr,))
        n = self.number(el, kind, attr, scope, True)
        child = self.one_child(el, kind, scope)
        if n == 0:
            self.err(el.at(attr), "%s of %s is 0: bmtree's %s takes 1 or more" % (attr, kind, bm))
            return None
        return Out(el.pos, (bm, n), ("child", child)) if n is not None and child is not None else None

    def _RetryUntilSuccessful(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        return self._loop(el, kind, scope, "num_attempts", "retry")

    _RetryUntilSuccesful = _RetryUntilSuccessful   # BehaviorTree.CPP 3's spelling

    def _Repeat(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        return self._loop(el, kind, scope, "num_cycles", "repeat")

    def _Timeout(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ("msec",))
        ms = self.number(el, kind, "msec", scope, False)
        child = self.one_child(el, kind, scope)
        if ms == 0:
            self.err(el.at("msec"), "msec of Timeout is 0: bmtree's timeout takes more than 0 seconds")
            return None
        return Out(el.pos, ("timeout", _seconds(ms)), ("child", child)) if ms is not None and child else None

    def _Delay(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ("delay_msec",))
        ms = self.number(el, kind, "delay_msec", scope, False)
        child = self.one_child(el, kind, scope)
        if ms is None or child is None:
            return None
        return Out(el.pos, ("sequence", [Out(el.pos, ("wait", _seconds(ms))), child]))

    # controls ---------------------------------------------------------------------------------
    def _Parallel(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        names = ("success_count", "failure_count") if self.version >= 4 else ("threshold",)
        self.attrs(el, kind, names)
        kids = self.kids(el, kind, scope, 1)
        n = len(el.children)
        if self.version >= 4:
            succ = self._count(el, kind, "success_count", scope, "-1", n)
            fail = self._count(el, kind, "failure_count", scope, "1", n)
        else:
            succ = self._count(el, kind, "threshold", scope, None, n)
            fail = n - succ + 1 if isinstance(succ, int) else None   # v3 fails once threshold is out of reach
        if kids is None or not isinstance(succ, int) or not isinstance(fail, int):
            if isinstance(succ, str) or isinstance(fail, str):
                self.err(el.pos, "Parallel's counts from the blackboard are not converted: bmtree's parallel policy "
                                 "is written in the tree")
            return None
        if succ > n or fail > n or succ < 1 or fail < 1:
            self.err(el.pos, "Parallel counts %d success%s and %d failure%s of %d children: each must be from 1 to "
                             "the number of children" % (succ, "" if succ == 1 else "es", fail, "" if fail == 1 else "s", n))
            return None
        if succ == n:
            return Out(el.pos, ("parallel", kids))   # the first failure fails it, as success_count all does
        if succ == 1 and fail == 1:
            return Out(el.pos, ("parallel", kids), ("policy", "one"))
        if succ == 1 and fail == n:
            return Out(el.pos, ("parallel", kids), ("policy", "first_success"))
        self.err(el.pos, "Parallel with success_count %d and failure_count %d of %d children is not converted: bmtree's "
                         "parallel succeeds when all children do (policy: all), when the first does (policy: one, "
                         "failure_count 1; policy: first_success, failure_count %d) or when named children do "
                         "(succeed_on): it cannot count %s" % (
                             succ, fail, n, n, "%d successes" % succ if succ > 1 else "%d failures" % fail))
        return None

    def _count(self, el: Element, kind: str, attr: str, scope: Scope, default: Optional[str], n: int) -> Any:
        """A count of children, a negative one counted from the number of children (-1: all of them)."""
        raw = el.attrs.get(attr, default)
        if raw is not None and re.match(r"^\s*-\d+\s*$", raw):
            return n + 1 + int(raw)
        return self.number(el, kind, attr, scope, True, default)

    def _IfThenElse(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ())
        kids = self.kids(el, kind, scope, 2, 3)
        if kids is None:
            return None
        if len(kids) == 2:   # the condition fails: FAILURE, as a sequence
            return Out(el.pos, ("sequence", kids))
        self.flags += 1
        flag = "if_then_else_%d" % self.flags
        self.written.add(flag)
        cond, then, other = kids
        p = el.pos
        held = Out(p, ("force_success", Out(p, ("sequence", [cond, Out(p, ("set", {flag: True}))]))))
        branch = Out(p, ("selector", [Out(p, ("sequence", [Out(p, ("check", flag)), then])),
                                      Out(p, ("sequence", [Out(p, ("check", "not " + flag)), other]))]))
        return Out(p, ("sequence", [Out(p, ("set", {flag: False})), held, branch]))

    def _WhileDoElse(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ())
        kids = self.kids(el, kind, scope, 2, 3)
        if kids is None:
            return None
        if len(kids) == 3:
            self.err(el.pos, "WhileDoElse with an else branch is not converted: bmtree would have to tick its "
                             "condition twice a tick; write a selector with memory: false of a sequence with memory: "
                             "false [condition, do] and the else node, or give WhileDoElse two children")
            return None
        return Out(el.pos, ("sequence", kids), ("memory", False))

    def _switch(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        n = int(kind[-1])
        cases = ["case_%d" % i for i in range(1, n + 1)]
        a = self.attrs(el, kind, ("variable",) + tuple(cases))
        kids = self.kids(el, kind, scope, n + 1, n + 1)
        ref = key_ref(a.get("variable", ""))
        if ref is None:
            self.err(el.at("variable"), "%s needs variable=\"{key}\"" % kind)
            return None
        key = self.use_key(el, "variable", ref, scope, False)
        missing = [c for c in cases if c not in a]
        if missing:
            self.err(el.pos, "%s needs %s" % (kind, ", ".join(missing)))
        if kids is None or missing or not isinstance(key, str):
            if isinstance(key, Lit):
                self.err(el.at("variable"), "%s: the SubTree gives variable the literal %r (%s): give it a {key}"
                         % (kind, key.text, key.where))
            return None
        table = {escape_text(a[c]): kid for c, kid in zip(cases, kids)}
        if len(table) < n:
            self.err(el.pos, "%s has two cases of one value" % kind)
            return None
        return Out(el.pos, ("switch", "$" + key), ("cases", table), ("default", kids[-1]))

    # subtrees ---------------------------------------------------------------------------------
    def subtree(self, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        sid = el.attrs.get("ID", "")
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
        return out.named(el.attrs.get("name") or sid) if out is not None else None


def _from(where: Any, at: Pos) -> str:
    """`` (given by the SubTree at …)`` when a literal came from elsewhere."""
    return "" if str(where) == str(at) else " (given by the SubTree at %s)" % where


def _seconds(ms: Any) -> Any:
    if isinstance(ms, str):   # $key: milliseconds on the blackboard
        return "$(%s / 1000)" % ms[1:]
    s = ms / 1000.0
    return int(s) if s == int(s) else s
