"""``bmtree import``: ReactiveSequence and ReactiveFallback (and WhileDoElse) as bmtree's own idiom.

BehaviorTree.CPP ticks a reactive node's children again from the first on every tick, so its Conditions are
re-checked while the one child that runs (the last that can be RUNNING) goes on, and halted when a check
says so. bmtree's ``memory: false`` does the same only for nodes that end in the tick they start (``check``,
``set``, ``fail``): a Condition is a module call here, which a re-tick would restart. So the Conditions are
checked once (BehaviorTree.CPP's first tick: the running child is not started when they say no), then polled
every ``--poll`` seconds in a ``parallel`` beside the running child ("Reacting while an action runs" in
trees/README.md). A child before the running one that can run itself (an action, a Sleep, a nested reactive
node running its action) cannot be polled: BehaviorTree.CPP restarts it and halts the running child on
every tick, so it is refused with what to write instead.

Whether a node can run comes from the XML: a ``<Condition>`` (or one TreeNodesModel declares) and
BehaviorTree.CPP's own leaves that end at once cannot, an ``<Action>``, Sleep, Delay and
KeepRunningUntilFailure can, a control can when a child can; a leaf nothing declares may be either (a
Condition before the running child, the running child when last).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Dict, List, Optional, Set, Tuple

from coordinator.btimportports import Out, Scope, escape_text
from coordinator.btxml import Element

if TYPE_CHECKING:   # the mixin's host
    from coordinator.btimportnodes import Converter

__all__ = ["Reactive", "model_kinds", "POLL_DEFAULT", "WATCHED_FOR"]

POLL_DEFAULT = 0.5
WATCHED_FOR = 86400.0   # the watch's bound: every bmtree loop is bounded, and a day outlasts any action
INSTANT, UNKNOWN, LASTS = 0, 1, 2
_INSTANT_LEAVES = ("AlwaysSuccess", "AlwaysFailure", "SetBlackboard", "UnsetBlackboard", "Script", "ScriptCondition")
_LASTING = {"Sleep": " (it waits)", "Delay": " (it waits before its child)",
            "KeepRunningUntilFailure": " (it runs until its child fails)"}
_WRAPPERS = ("Action", "Condition", "Control", "Decorator")
_BM_INSTANT = ("check", "set", "fail")
_BM_COMPOSITE = ("sequence", "selector", "inverter", "force_success", "force_failure", "switch")
Lasting = Tuple[int, str, Optional[Element]]   # INSTANT/UNKNOWN/LASTS, and for LASTS what runs and why


def model_kinds(root: Element) -> Dict[str, str]:
    """The IDs TreeNodesModel declares as Action or Condition (which says whether a bare ``<IsDoorOpen/>``
    can run)."""
    out: Dict[str, str] = {}
    for top in root.children:
        if top.tag == "TreeNodesModel":
            for m in top.children:
                if m.tag in ("Action", "Condition") and m.attrs.get("ID"):
                    out[m.attrs["ID"]] = m.tag
    return out


def _kind(el: Element) -> str:
    return el.attrs.get("ID", "") if el.tag in _WRAPPERS else el.tag


def _label(el: Element) -> str:
    """The node's name as BehaviorTree.CPP shows it: its name, else its ID (a SubTree's, an Inverter's child's
    after "not")."""
    kind = _kind(el)
    if (el.attrs.get("name") or "").strip():
        return el.attrs["name"].strip()
    if kind in ("SubTree", "SubTreePlus"):
        return el.attrs.get("ID", "") or kind
    return "not " + _label(el.children[0]) if kind == "Inverter" and len(el.children) == 1 else kind or el.tag


def _instant_out(node: Out) -> bool:
    """True when the converted node ends in the tick it starts (what ``memory: false`` may re-tick)."""
    kind, value = node.items[0]
    if kind in _BM_INSTANT:
        return True
    if kind not in _BM_COMPOSITE:
        return False
    kids = [v for _k, v in node.items if isinstance(v, Out)]
    for _k, v in node.items:
        if isinstance(v, list):
            kids += [c for c in v if isinstance(c, Out)]
        elif isinstance(v, dict):
            kids += [c for c in v.values() if isinstance(c, Out)]
    return all(_instant_out(c) for c in kids)


class Reactive:
    """The reactive controls of :class:`Converter` (see the module's docstring)."""

    def _ReactiveSequence(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        return self.reactive(el, kind, scope, "sequence")

    def _ReactiveFallback(self: Converter, el: Element, kind: str, scope: Scope) -> Optional[Out]:
        return self.reactive(el, kind, scope, "selector")

    def reactive(self: Converter, el: Element, kind: str, scope: Scope, bm: str,
                 kids: Optional[List[Out]] = None) -> Optional[Out]:
        """``kind`` (its children ``kids`` when converted already) as bmtree's idiom (the module's docstring)."""
        if kids is None:
            self.attrs(el, kind, ())
            self.rerun += 1   # an earlier child ends a later one, ticked again later
            try:
                kids = self.kids(el, kind, scope, 1)
            finally:
                self.rerun -= 1
        states = [self.lasting(c, set()) for c in el.children]
        running = max((i for i, (s, _w, _e) in enumerate(states) if s != INSTANT), default=-1)
        bad = [(c, st) for c, st in zip(el.children[:max(running, 0)], states) if st[0] == LASTS]
        for c, (_s, why, where) in bad:   # reported even when a child is not converted: all problems at once
            where = where or c   # LASTS always says where
            said = "%s can run%s" % (self.what(c), why) if where is c else "%s can run (%s at line %d)" % (
                self.what(c), self.what(where), where.pos.line)
            self.err(c.pos, "%s, but it comes before %s, the last child that runs in %s (line %d): BehaviorTree.CPP "
                            "ticks it again on every tick while that one runs, and halts that one whenever it runs; "
                            "bmtree import polls Conditions there, not nodes that run: put only Conditions before the "
                            "running child, run this one before the %s (both in a Sequence), or write this part in "
                            "the YAML by hand ('Reacting while an action runs' in trees/README.md)" % (
                                said, self.what(el.children[running]), kind, el.pos.line, kind))
        if kids is None or bad:
            return None
        checked, p = kids[:max(running, 0)], el.pos
        if not checked:   # nothing before the running child (or none runs): ticked once each, in order
            return Out(p, (bm, kids))
        action, tail = kids[running], kids[running + 1:]
        if all(_instant_out(c) for c in checked):   # checks: bmtree re-ticks them as BehaviorTree.CPP does
            inner = Out(p, (bm, checked + [action]), ("memory", False))
            return Out(p, (bm, [inner] + tail)) if tail else inner
        labels = [_label(c) for c in el.children[:running]]
        watch = self.watcher(el, kind, bm, checked, labels)
        action.named(_label(el.children[running]))
        name = next(v for k, v in action.items if k == "name")
        if watch.items[1][1] == name:
            watch.items[1] = ("name", name + " (watch)")
        both = Out(p, ("parallel", [action, watch]),
                   ("succeed_on", [name]) if bm == "sequence" else ("policy", "one"))
        return Out(p, (bm, checked + [both] + tail))

    def watcher(self: Converter, el: Element, kind: str, bm: str, checked: List[Out], labels: List[str]) -> Out:
        """The branch that polls ``checked`` every ``poll`` seconds: ReactiveSequence's fails when one of them
        fails, ReactiveFallback's succeeds when one succeeds; after a day of polling it fails, saying so."""
        p, poll = el.pos, self.poll
        polls = int(math.ceil(WATCHED_FOR / poll))
        said = ", ".join(labels[:-1]) + (" %s " % ("and" if bm == "sequence" else "or") if len(labels) > 1 else "")
        said += labels[-1]
        wait = Out(p, ("wait", int(poll) if poll == int(poll) else poll))
        given_up = Out(p, ("fail", escape_text("stopped watching %s after a day (%d checks, one every %gs): bmtree "
                                               "import's bound" % (said, polls, poll))))
        if bm == "sequence":   # until one fails
            loop = Out(p, ("repeat", polls), ("child", Out(p, ("sequence", [wait] + checked))))
            return Out(p, ("sequence", [loop, given_up]), ("name", "while " + said))
        any_one = checked[0] if len(checked) == 1 else Out(p, ("selector", checked))
        loop = Out(p, ("retry", polls), ("child", Out(p, ("sequence", [wait, any_one]))))   # until one succeeds
        return Out(p, ("selector", [loop, given_up]), ("name", "until " + said))

    def what(self: Converter, el: Element) -> str:
        """``the Action 'LookAt'``, ``the Sleep``, ``the ReactiveFallback``."""
        kind = _kind(el)
        if kind in ("SubTree", "SubTreePlus"):
            return "the %s %r" % (kind, el.attrs.get("ID", ""))
        declared = el.tag if el.tag in _WRAPPERS else "" if el.children else self.models.get(kind, "")
        if declared:
            return "the %s %r" % (declared, kind)
        return "the " + kind if el.children or kind in _LASTING or kind in _INSTANT_LEAVES else repr(kind)

    def lasting(self: Converter, el: Element, seen: Set[str]) -> Lasting:
        """Whether ``el`` can be RUNNING in BehaviorTree.CPP (INSTANT, UNKNOWN: a leaf nothing declares, LASTS),
        and for LASTS what runs (``the Action 'LookAt' at line 49``). Kept per element: a subtree included
        many times, or under nested reactive nodes, is looked at once."""
        got = self.lastings.get(id(el))
        if got is None:
            got = self.lastings[id(el)] = self._lasting(el, seen)
        return got

    def _lasting(self: Converter, el: Element, seen: Set[str]) -> Lasting:
        kind = _kind(el)
        if kind in _LASTING:
            return LASTS, _LASTING[kind], el
        if kind in _INSTANT_LEAVES:
            return INSTANT, "", None
        sub = el.attrs.get("ID", "") if kind in ("SubTree", "SubTreePlus") else (
            kind if self.version < 4 and kind in self.trees and kind not in self.maps and not el.children else "")
        if sub:
            if sub not in self.trees or sub in seen or len(self.trees[sub].children) != 1:
                return UNKNOWN, "", None   # reported where it is converted
            return self.lasting(self.trees[sub].children[0], seen | {sub})
        if el.children:
            worst: Lasting = (INSTANT, "", None)
            for c in el.children:
                got = self.lasting(c, seen)
                if got[0] > worst[0]:
                    worst = got
            return worst
        declared = el.tag if el.tag in ("Action", "Condition") else self.models.get(kind, "")
        if declared == "Condition":
            return INSTANT, "", None
        if declared == "Action":
            return LASTS, "" if el.tag == "Action" else " (TreeNodesModel declares it)", el
        return UNKNOWN, "", None

