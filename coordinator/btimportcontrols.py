"""``bmtree import``: BehaviorTree.CPP's built-in decorators and controls turned into bmtree nodes.

A mixin of :class:`coordinator.btimportnodes.Converter` (which holds the state and the helpers used here),
kept apart so that each file stays readable. Where BehaviorTree.CPP keeps state in a node that bmtree's
kind does not (IfThenElse's outcome, SequenceWithMemory's progress), the node is written with generated
keys, ``set`` and ``check``, rather than refused.
"""
from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any, Dict, List, Optional

from coordinator.btimportports import (
    Lit,
    Out,
    OutOfRange,
    Scope,
    bool_literal,
    escape_text,
    key_ref,
    plain_literal,
    whole_number,
)
from coordinator.btxml import Element

if TYPE_CHECKING:   # the mixin's host
    from coordinator.btimportnodes import Converter

__all__ = ["Controls", "seconds"]

_LOOPS = {"LoopString": "text", "LoopInt": "whole number", "LoopDouble": "number", "LoopBool": "true or false"}


def seconds(ms: Any) -> Any:
    """Milliseconds (a number, or ``$key``) as bmtree's seconds."""
    if isinstance(ms, str):   # $key: milliseconds on the blackboard
        return "$(%s / 1000)" % ms[1:]
    s = ms / 1000.0
    return int(s) if s == int(s) and abs(s) < 1e15 else s


class Controls:
    """The decorators and controls of :class:`Converter` (see the module's docstring)."""

    # decorators -------------------------------------------------------------------------------
    def _loop(self: Converter, el: Element, kind: str, scope: Scope, attr: str, bm: str) -> Optional[Out]:
        self.attrs(el, kind, (attr,))
        n = self.number(el, kind, attr, scope, True)
        rerun = bm == "retry"   # its child is ticked again after a failure
        self.rerun += rerun
        try:
            child = self.one_child(el, kind, scope)
        finally:
            self.rerun -= rerun
        if n == 0:
            self.err(el.at(attr), "%s of %s is 0: bmtree's %s takes 1 or more" % (attr, kind, bm))
            return None
        return Out(el.pos, (bm, n), ("child", child)) if n is not None and child is not None else None

    def _RetryUntilSuccessful(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        return self._loop(el, kind, scope, "num_attempts", "retry")

    _RetryUntilSuccesful = _RetryUntilSuccessful   # BehaviorTree.CPP 3's spelling

    def _Repeat(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        return self._loop(el, kind, scope, "num_cycles", "repeat")

    def _Timeout(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ("msec",))
        ms = self.number(el, kind, "msec", scope, False)
        child = self.one_child(el, kind, scope)
        if ms == 0:
            self.err(el.at("msec"), "msec of Timeout is 0: bmtree's timeout takes more than 0 seconds")
            return None
        self.from_ms.add((el.pos.line, el.pos.column))
        return Out(el.pos, ("timeout", seconds(ms)), ("child", child)) if ms is not None and child else None

    def _Delay(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ("delay_msec",))
        ms = self.number(el, kind, "delay_msec", scope, False)
        child = self.one_child(el, kind, scope)
        if ms is None or child is None:
            return None
        self.from_ms.add((el.pos.line, el.pos.column))
        return Out(el.pos, ("sequence", [Out(el.pos, ("wait", seconds(ms))), child]))

    def _loop_queue(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        """LoopString, LoopInt, LoopDouble, LoopBool over a literal queue: a ``for_each`` (BehaviorTree.CPP runs
        the child once per element, FAILURE at the first failure, then ``if_empty``)."""
        a = self.attrs(el, kind, ("queue", "value", "if_empty"))
        child = self.one_child(el, kind, scope)
        raw = a.get("queue")
        if raw is None or key_ref(raw) is not None:
            self.err(el.at("queue"), "%s %s is not converted: bmtree's for_each runs over a list written in the tree "
                                     "(or a key holding a list): write for_each: $key, with as: and child: beside it, "
                                     "in the YAML by hand" % (kind, "without queue" if raw is None else
                                                              "over the queue of a blackboard key"))
            return None
        items = self.queue_items(el, kind, raw)
        when_empty = a.get("if_empty", "SUCCESS").strip()
        if when_empty not in ("SUCCESS", "FAILURE"):
            self.err(el.at("if_empty"), "if_empty of %s is %r: bmtree import converts SUCCESS and FAILURE" % (
                kind, when_empty))
            return None
        as_key: Optional[str] = None
        ref = key_ref(a.get("value", ""))
        if ref is not None:
            got = self.use_key(el, "value", ref, scope, True)
            if isinstance(got, Lit):
                self.err(el.at("value"), "%s: value is given the literal %r by the SubTree (%s): give it a {key}"
                         % (kind, got.text, got.where))
                return None
            as_key = got
        elif "value" in a:
            self.err(el.at("value"), "%s: value is an output: give it the blackboard key to write, value=\"{key}\", "
                                     "not %r" % (kind, a["value"]))
            return None
        else:
            self.flags += 1
            as_key = "loop_value_%d" % self.flags
        if items is None or child is None or as_key is None:
            return None
        loop = Out(el.pos, ("for_each", items), ("as", as_key), ("child", child),
                   *([("max", len(items))] if len(items) > 100 else []))
        return loop if when_empty == "SUCCESS" else Out(el.pos, ("force_failure", loop))   # if_empty at the end too

    _LoopString = _LoopInt = _LoopDouble = _LoopBool = _loop_queue

    def queue_items(self: Converter, el: Element, kind: str, raw: str) -> Optional[List[Any]]:
        """A literal queue's elements, split at ';' as BehaviorTree.CPP does, typed by the kind of loop."""
        parts: List[str] = []
        pos = 0
        while pos < len(raw):   # BehaviorTree.CPP's splitString: "a;;b" has an empty element, "a;" none after a
            end = raw.find(";", pos)
            end = len(raw) if end < 0 else end
            parts.append(raw[pos:end])
            pos = end + 1
        if kind == "LoopString":
            return [escape_text(p) for p in parts]
        out: List[Any] = []
        for p in parts:
            try:
                v = bool_literal(p) if kind == "LoopBool" else plain_literal(p)
            except OutOfRange as exc:
                self.err(el.at("queue"), "queue of %s holds %s" % (kind, exc))
                return None
            fits = v is not None if kind == "LoopBool" else not isinstance(v, bool) and (
                isinstance(v, int) if kind == "LoopInt" else isinstance(v, (int, float)))
            if not fits:
                self.err(el.at("queue"), "queue of %s holds %r, which is no %s" % (kind, p, _LOOPS[kind]))
                return None
            out.append(float(v) if kind == "LoopDouble" else v)
        return out

    # controls ---------------------------------------------------------------------------------
    def _Parallel(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
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

    def _count(self: Converter, el: Element, kind: str, attr: str, scope: Scope, default: Optional[str], n: int) -> Any:
        """A count of children, a negative one counted from the number of children (-1: all of them)."""
        raw = el.attrs.get(attr, default)
        if raw is not None and re.match(r"^\s*-\d+\s*$", raw):
            try:
                return n + 1 + (whole_number(raw) or 0)
            except OutOfRange as exc:
                self.err(el.at(attr), "%s of %s is %s" % (attr, kind, exc))
                return None
        return self.number(el, kind, attr, scope, True, default)

    def _IfThenElse(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
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

    def memory_sequence(self: Converter, el: Element, kids: List[Out]) -> Out:
        """SequenceWithMemory (SequenceStar) where an ancestor ticks it again after a failure (a retry, a reactive
        parent): BehaviorTree.CPP resumes at the child that failed, skipping those that succeeded, and starts
        over only once all have succeeded. Each child but the last is skipped once its flag is set; the flags
        are cleared when the sequence succeeds, and set false when the tree starts (``initial``)."""
        p = el.pos
        self.flags += 1
        flags = ["sequence_%d_done_%d" % (self.flags, i) for i in range(1, len(kids))]
        steps = [Out(p, ("selector", [Out(p, ("check", f)), Out(p, ("sequence", [kid, Out(p, ("set", {f: True}))]))]))
                 for f, kid in zip(flags, kids)]
        cleared: Dict[str, Any] = {f: False for f in flags}
        self.initial.update(cleared)
        self.written.update(flags)
        return Out(p, ("sequence", steps + [kids[-1], Out(p, ("set", dict(cleared)))]))

    def _WhileDoElse(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        self.attrs(el, kind, ())
        self.rerun += 1   # reactive: its children are ticked again on every tick
        try:
            kids = self.kids(el, kind, scope, 2, 3)
        finally:
            self.rerun -= 1
        if kids is None:
            return None
        if len(kids) == 3:
            self.err(el.pos, "WhileDoElse with an else branch is not converted: bmtree would have to tick its "
                             "condition twice a tick; write a selector with memory: false of a sequence with memory: "
                             "false [condition, do] and the else node, or give WhileDoElse two children")
            return None
        return self.reactive(el, kind, scope, "sequence", kids)   # [condition, do]: a ReactiveSequence

    def _switch(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
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
        values = [self.case_value(el, kind, c, a[c], scope) for c in cases if c in a]
        if kids is None or missing or not isinstance(key, str) or None in values:
            if isinstance(key, Lit):
                self.err(el.at("variable"), "%s: the SubTree gives variable the literal %r (%s): give it a {key}"
                         % (kind, key.text, key.where))
            return None
        table = {escape_text(v): kid for v, kid in zip(values, kids)}
        if len(table) < n:
            self.err(el.pos, "%s has two cases of one value" % kind)
            return None
        return Out(el.pos, ("switch", "$" + key), ("cases", table), ("default", kids[-1]))

    def case_value(self: Converter, el: Element, kind: str, case: str, raw: str, scope: Scope) -> Optional[str]:
        """A case's text: the literal, or the one a SubTree gives its ``{port}``; None (reported) for a key,
        whose value BehaviorTree.CPP reads at each tick but a bmtree case cannot."""
        ref = key_ref(raw)
        if ref is None:
            return raw
        got, _root = scope.resolve(case if ref in ("=", "") else ref)
        if isinstance(got, Lit):
            return got.text
        self.err(el.at(case), "%s of %s is the blackboard key %r: bmtree's switch cases are values written in the "
                              "tree: give the value itself, or write the choice in the YAML by hand (a selector of "
                              "sequences of check: \"variable == key\" and the node)" % (case, kind, got))
        return None

    def _UnsetBlackboard(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        a = self.attrs(el, kind, ("key",))
        raw = a.get("key", "").strip()
        if not raw or key_ref(raw) is not None:
            self.err(el.at("key"), "UnsetBlackboard needs key=\"NAME\" (the key's own name, no braces: {%s} names "
                                   "the key its value names, which bmtree cannot)" % (key_ref(raw) or "key")
                     if raw else "UnsetBlackboard needs key=\"NAME\"")
            return None
        key = self.use_key(el, "key", raw, scope, True)
        if isinstance(key, Lit):
            self.err(el.at("key"), "UnsetBlackboard: key is given the literal %r by the SubTree (%s): BehaviorTree.CPP "
                                   "unsets the subtree's own key %r; give it a {key}" % (key.text, key.where, raw))
            return None
        return Out(el.pos, ("set", {key: None})) if key is not None else None   # a key cannot be removed: null
