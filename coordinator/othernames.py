"""Hints for trees written as another tool writes them: BehaviorTree.CPP, py_trees and SMACH names of
node kinds and options, the bmtree kind (or idiom) each is, and the forms a decorator is written in.

``bmtree check`` puts these in its errors: ``unknown node kind 'Fallback' (BehaviorTree.CPP's
Fallback is bmtree's selector)``. Only kinds of the registry are named (a test holds the table to it).
"""
from __future__ import annotations

import re
from typing import Any, Dict, List, Optional, Tuple

from coordinator.yamlsrc import LList, LMap

__all__ = ["check_inside", "CONDITIONS", "OTHER_KINDS", "OTHER_OPTIONS", "decorator_mapping", "foreign_option", "kind_hint",
           "one_child", "option_hint", "takes", "top_key_hint"]

_BT, _PT, _SM, _N2 = "BehaviorTree.CPP", "py_trees", "SMACH", "Nav2"
_MEMORY = "sequence, whose memory: true (its default) does not tick again a child that succeeded"
_REACTIVE = ("%s with memory: false (the earlier children are checked again on every tick, so only its last child "
             "may take more than one tick; to react while an action runs, see 'Reacting while an action runs' in "
             "trees/README.md)")

# (name there, tools, the bmtree kinds it becomes, what it is in bmtree): with a kind it is that kind
# ("bmtree's …"); without one, bmtree writes it with other kinds (the text says how)
_TABLE: Tuple[Tuple[str, Tuple[str, ...], Tuple[str, ...], str], ...] = (
    ("Fallback", (_BT,), ("selector",), "selector"),
    ("Selector", (_PT,), ("selector",), "selector"),
    ("ReactiveFallback", (_BT,), ("selector",), _REACTIVE % "selector"),
    ("Sequence", (_BT, _PT, _SM), ("sequence",), "sequence"),
    ("ReactiveSequence", (_BT,), ("sequence",), _REACTIVE % "sequence"),
    ("SequenceStar", (_BT,), ("sequence",), _MEMORY),
    ("SequenceWithMemory", (_BT,), ("sequence",), _MEMORY),
    ("Parallel", (_BT, _PT), ("parallel",), "parallel, with policy: all, one or first_success (success_count 1 "
                                            "and failure_count all)"),
    ("ParallelAll", (_BT,), ("parallel",), "parallel"),
    ("Concurrence", (_SM,), ("parallel",), "parallel, with policy: all, one or first_success, or succeed_on: "
                                           "[child names] (its outcome map); ended_by: KEY and a switch: $KEY "
                                           "after it for several outcomes"),
    ("Inverter", (_BT, _PT), ("inverter",), "inverter"),
    ("ForceSuccess", (_BT,), ("force_success",), "force_success"),
    ("FailureIsSuccess", (_PT,), ("force_success",), "force_success"),
    ("ForceFailure", (_BT,), ("force_failure",), "force_failure"),
    ("SuccessIsFailure", (_PT,), ("force_failure",), "force_failure"),
    ("RetryUntilSuccessful", (_BT,), ("retry",), "retry: N (attempts in all), with child: beside it"),
    ("RetryUntilSuccesful", (_BT,), ("retry",), "retry: N (attempts in all), with child: beside it"),
    ("Retry", (_PT,), ("retry",), "retry: N (attempts in all), with child: beside it"),
    ("Repeat", (_BT, _PT), ("repeat",), "repeat: N, with child: beside it"),
    ("Timeout", (_BT, _PT), ("timeout",), "timeout: SECONDS (not msec), with child: beside it"),
    ("SubTree", (_BT,), ("include",), "include: file.yaml, with args: for its inputs"),
    ("SubTreePlus", (_BT,), ("include",), "include: file.yaml, with args: for its inputs"),
    ("Iterator", (_SM,), ("for_each",), "for_each: LIST, with as: KEY and child: beside it"),
    ("SimpleActionState", (_SM,), ("call",), "call: module.function"),
    ("ServiceState", (_SM,), ("call",), "call: module.function"),
    ("MonitorState", (_SM,), ("wait_event",), "wait_event: module.event, with where: 'expression' on its params and tree keys"),
    ("AlwaysFailure", (_BT,), ("fail",), "fail: \"why\""),
    ("Sleep", (_BT,), ("wait",), "wait: SECONDS"),
    ("SetBlackboard", (_BT,), ("set",), "set: {key: value}"),
    ("ScriptCondition", (_BT,), ("check",), "check: 'expression'"),
    ("UnsetBlackboard", (_BT,), ("set",), "set: {key: null} (a key cannot be removed; a check reads it as null)"),
) + tuple(("Switch%d" % n, (_BT,), ("switch",), "switch: $key, with cases: {case: node} and default:")
          for n in range(2, 7)) + tuple(
    (loop, (_BT,), ("for_each",), "for_each: LIST (a list, $key or $( … )), with as: KEY and child: beside it "
                                  "(the queue is the list, the value the as key)")
    for loop in ("LoopNode", "LoopString", "LoopDouble", "LoopInt", "LoopBool"))

# names with no kind of their own: how bmtree writes them
_IDIOMS: Tuple[Tuple[str, Tuple[str, ...], Tuple[str, ...], str], ...] = (
    ("Delay", (_BT,), ("sequence", "wait", "retry"), "a wait before the node, in a sequence: [{wait: SECONDS}, "
                                                     "node] (or retry's delay: between attempts)"),
    ("KeepRunningUntilFailure", (_BT,), ("repeat",), "repeat: N runs the child again while it succeeds, at "
                                                     "most N times (every bmtree loop is bounded)"),
    ("EternalGuard", (_PT,), ("sequence", "check"), "a sequence with memory: false whose first child is the "
                                                    "check: the condition is checked again on every tick"),
    ("Precondition", (_BT,), ("sequence", "check"), "a sequence of a check and the node"),
    ("IfThenElse", (_BT,), ("selector", "sequence", "check"),
     "a selector of a sequence [check, then-node] and the else-node"),
    ("StateMachine", (_SM,), ("sequence", "switch", "selector"),
     "a sequence of the states, in order; a state's outcome is the status key of its call (its status "
     "option), a transition on it a switch on that key, a fallback state a selector"),
    ("CBState", (_SM,), ("check", "set"), "write the callback in the tree, as check: 'expression' for a "
                                          "condition or set: {key: \"$( … )\"} for a value"),
    ("Script", (_BT,), ("set", "check"), "set: {key: \"$( … )\"} for an assignment (counter := counter + 1 is "
                                         "set: {counter: \"$(counter + 1)\"}), check: 'expression' for a condition"),
    ("RunOnce", (_BT,), ("selector", "sequence", "check", "set"),
     "a selector of check: 'done' and a sequence of the node and set: {done: true}, with done false at first (a "
     "tree input's default)"),
    ("AlwaysSuccess", (_BT,), ("check",), "check: 'true' succeeds at once (force_success over a node, for "
                                          "ForceSuccess)"),
    ("WhileDoElse", (_BT,), ("selector", "sequence", "check"),
     "a selector with memory: false of a sequence [check, do-node] and the else-node (the check is read again on "
     "every tick, and the do-node takes over once it holds)"),
    ("Action", (_BT,), ("call",), "call: module.function (your action is a function of a module, whose definition "
                                  "names its inputs and outputs)"),
    ("Condition", (_BT,), ("check", "call"), "check: 'expression' over tree keys, or call: module.function of a "
                                             "function whose success output answers true or false"),
    # navigation2's own controls and decorators (nav2_behavior_tree), met in its navigator trees
    ("RecoveryNode", (_N2,), ("repeat", "selector", "sequence", "set"),
     "repeat: N+1 (number_of_retries + 1) with until: done, of a selector of a sequence [the first child, set: "
     "{done: true}] and the recovery, with done false before it (the recovery succeeding runs the first child "
     "again, failing ends it)"),
    ("PipelineSequence", (_N2,), ("parallel",),
     "a parallel with succeed_on: [the last child's name] of its children, the earlier ones each a repeat of "
     "itself (ComputePathToPose keeps replanning while FollowPath runs)"),
    ("RoundRobin", (_N2,), ("switch", "set"),
     "a switch on a key counting the turns, cases 0, 1, … the children, with set: {turn: \"$(turn + 1)\"} "
     "after it and the key set back to 0 after the last case"),
    ("RateController", (_N2,), ("repeat", "sequence", "wait"),
     "a repeat of a sequence of the child and wait: 1/hz seconds"),
    ("DistanceController", (_N2,), ("repeat", "sequence", "call", "check"),
     "a repeat that reads the distance travelled (a call's output) and runs the child when a check of it says so"),
    ("SpeedController", (_N2,), ("repeat", "sequence", "wait"),
     "a repeat of a sequence of the child and a wait computed from the speed (wait: $(…))"),
    ("GoalUpdater", (_N2,), ("wait_event", "recall"),
     "a wait_event (or a recall) that writes the new goal to the key the call reads"),
    ("SingleTrigger", (_N2,), ("selector", "sequence", "check", "set"),
     "a selector of check: 'done' and a sequence of the node and set: {done: true}, as BehaviorTree.CPP's "
     "RunOnce"),
)


def _norm(name: Any) -> str:
    """``ReactiveFallback``, ``reactive_fallback``, ``py_trees.composites.Selector``: one spelling."""
    return str(name).rsplit(".", 1)[-1].replace("_", "").replace("-", "").lower()


def _whose(tools: Tuple[str, ...]) -> str:
    owners = ["%s'%s" % (t, "" if t.endswith("s") else "s") for t in tools]
    return owners[0] if len(owners) == 1 else "%s and %s" % (", ".join(owners[:-1]), owners[-1])


OTHER_KINDS: Dict[str, Tuple[Tuple[str, ...], str]] = {}
"""By name (lower case, without ``_``): the bmtree kinds it is written with, and the hint."""
for _name, _tools, _kinds, _text in _TABLE:
    OTHER_KINDS[_norm(_name)] = (_kinds, "%s %s is bmtree's %s" % (_whose(_tools), _name, _text))
for _name, _tools, _kinds, _text in _IDIOMS:
    OTHER_KINDS[_norm(_name)] = (_kinds, "%s %s has no kind of its own in bmtree: %s" % (_whose(_tools), _name,
                                                                                          _text))

# options of other tools: (the bmtree options it is written with, the kinds that take those, the hint)
OTHER_OPTIONS: Dict[str, Tuple[Tuple[str, ...], str]] = {
    "remapping": (("inputs", "outputs"), "SMACH's remapping is inputs: (input name: $key) and outputs: "
                                         "(output name: key)"),
    "transitions": (("status",), "SMACH's transitions are a sequence's order (the next state when one succeeds) "
                                 "and, to route on how a call ended, its status: KEY with a switch: $KEY over the "
                                 "outcomes after it"),
    "outcome_map": (("policy", "succeed_on"), "SMACH's outcome_map is parallel's succeed_on: [child names] (those "
                                              "children succeed: it succeeds, halting the others) or policy: all, "
                                              "one or first_success; for several outcomes, ended_by: KEY (the name "
                                              "of the child that ended it) and a switch: $KEY after it"),
    "num_attempts": (("child",), "BehaviorTree.CPP's num_attempts is retry's value: retry: N"),
    "num_cycles": (("child",), "BehaviorTree.CPP's num_cycles is repeat's value: repeat: N"),
    "msec": (("child",), "BehaviorTree.CPP's msec is timeout's value, in seconds: timeout: SECONDS"),
    "success_count": (("policy",), "BehaviorTree.CPP's success_count and failure_count are parallel's policy: "
                                   "all (every child succeeds), one (the first success wins, the first failure "
                                   "fails it), first_success (the first success wins, it fails only when all "
                                   "failed), or succeed_on: [names]"),
    "variable": (("cases",), "BehaviorTree.CPP's variable is switch's value, and its case_N ports its cases: "
                             "switch: $key, with cases: {value: node} and default: node"),
}
OTHER_OPTIONS["failure_count"] = OTHER_OPTIONS["success_count"]
OTHER_OPTIONS["child_termination_cb"] = OTHER_OPTIONS["outcome_map"]
OTHER_OPTIONS.update(("case_%d" % n, OTHER_OPTIONS["variable"]) for n in range(1, 10))

# BehaviorTree.CPP's pre- and post-conditions, which any node takes there (by name, in lower case): what bmtree
# writes instead
_SUBTREES = "see 'Subtrees' in trees/README.md"
CONDITIONS: Dict[str, str] = {
    "_skipif": "a selector of check: 'condition' and the node (it is skipped, as SUCCESS, while the condition holds)",
    "_successif": "a selector of check: 'condition' and the node (SUCCESS without running it when the condition "
                  "holds)",
    "_failureif": "a sequence of check: 'not (condition)' and the node (FAILURE without running it when the "
                  "condition holds)",
    "_while": "a sequence with memory: false of check: 'condition' and the node: the node is halted once the "
              "condition is false (see 'Reacting while an action runs' in trees/README.md)",
    "_onhalted": "what it does as the tree's cleanup: (a node beside root:), which runs once after root ends, "
                 "however it ended, also when it was halted (see 'Cleaning up' in trees/README.md)",
    "_onsuccess": "a sequence of the node and set: {key: value} (what comes after the node runs only when it "
                  "succeeded)",
    "_onfailure": "a selector of the node and a sequence of set: {key: value} and fail: \"why\" (the branch still "
                  "fails)",
    "_post": "a sequence of the node and set: {key: value}, or force_success over the node first, to set it "
             "however the node ended",
    "_autoremap": "include alone: it shares the tree blackboard (the subtree reads and writes the caller's keys by "
                  "their own names); args: sets its inputs and outputs: copies its keys to other names (%s)" % _SUBTREES,
}


def foreign_option(option: Any) -> bool:
    """Whether ``option`` is another tool's option or a BehaviorTree.CPP pre/post condition that has a hint
    of its own (a "did you mean" would mislead: ``_successIf`` is not ``check_success``)."""
    text = str(option).lower()
    return text in OTHER_OPTIONS or text in CONDITIONS


def kind_hint(name: Any, definitions: Any = None) -> str:
    """`` (BehaviorTree.CPP's Fallback is bmtree's selector)`` for a kind of another tool, `` (did you mean
    'for_each'?)`` for a kind written otherwise (``ForEach``), how to call a function written as the kind
    (``speech.say: {text: hi}``; ``definitions``: the modules'), else ''."""
    from coordinator.nodes import REGISTRY

    if isinstance(name, str) and re.match(r"^\w+\.\w+$", name):
        mod_name, member = name.split(".")
        mod = (definitions or {}).get(mod_name)
        if mod is not None and member in mod.events:
            return " (an event is waited for by a wait_event node: write wait_event: %s, with outputs: {param: " \
                   "KEY} to keep its params)" % name
        if mod is None or member in mod.functions:
            return " (a function is called by a call node: write call: %s with inputs: {...} beside it)" % name
    found = OTHER_KINDS.get(_norm(name))
    if found:
        return " (%s)" % found[1]
    same = [k for k in REGISTRY if _norm(k) == _norm(name)]   # ForEach, WAIT
    return " (did you mean %r?)" % same[0] if same else ""


# top-level keys others write for what runs after the task however it ended (SMACH's "preempted" handling,
# a ``finally``): bmtree's ``cleanup:``
_CLEANUP_NAMES = frozenset(("cleanup", "finally", "onstop", "onhalt", "onpreempt", "onpreempted", "preempted",
                            "onexit", "teardown", "shutdown", "onabort", "onend", "onfinish", "always", "ensure"))


def top_key_hint(key: Any) -> str:
    """`` (did you mean 'cleanup'? …)`` for a top-level key written for a clean-up (``clean_up``,
    ``finally``, ``on_stop``, ``on_halt``), else ''."""
    if _norm(key) in _CLEANUP_NAMES:
        return (" (did you mean 'cleanup'? cleanup: holds the node run once after root ends, however it ended: "
                "succeeded, failed or stopped)")
    return ""


def takes(kind: str, allowed: Tuple[str, ...]) -> str:
    """`` (retry takes child, delay, name)``: the options a kind has, from its option table."""
    return " (%s takes %s)" % (kind, ", ".join(sorted(allowed)))


def option_hint(option: Any, kind: str, allowed: Tuple[str, ...]) -> str:
    """The hint for an option the kind does not take: the options it takes and, for another tool's option
    that this kind writes otherwise, how."""
    text = str(option).lower()
    if text in CONDITIONS:
        what = "" if text == "_autoremap" else " condition"   # a port option, not a pre/post condition
        return " (BehaviorTree.CPP's %s%s has no option in bmtree: write %s)" % (option, what, CONDITIONS[text])
    other = OTHER_OPTIONS.get(text)
    return takes(kind, allowed) + (": %s" % other[1] if other and set(other[0]) & set(allowed) else "")


def one_child(kind: str, under_child: bool, items: int) -> str:
    """The error for a list where one node goes: a decorator's child (``under_child``: its ``child:``
    option, else its value), a case of a switch."""
    if kind == "switch":
        whose, where = "a case of switch runs", '"case": {sequence: [...]}'
    else:
        whose, where = "a decorator (%s) has" % kind, "%s: {sequence: [...]}" % ("child" if under_child else kind)
    return "%s one child, not a list: %s" % (whose, "write the node without [ ]" if items == 1 else
                                             "wrap several nodes in a sequence, %s" % where)


_STAND_INS: Dict[str, Any] = {"count": 1, "seconds": 1.0, "seconds0": 0.0, "list": []}
"""A value that a kind's parse takes without an error, for a decorator whose value is missing (reported)."""
_PLACEHOLDERS = {"count": "N", "seconds": "SECONDS", "seconds0": "SECONDS", "list": "LIST"}


def _shown(value: Any) -> str:
    if isinstance(value, (dict, list)):
        return "…"
    return "%s" % (value,) if not isinstance(value, str) or re.match(r"[\w.$]+$", value) else repr(value)


def decorator_mapping(p: Any, outer: LMap, kind: str, nk: Any, allowed: Tuple[str, ...]) -> Optional[LMap]:
    """``retry: {attempts: 3, child: …}``: a decorator written with a mapping where its value goes (as a
    composite's inline form). One error says the form; the node is then read as if written so (``retry: 3``
    with the options beside it; the one key of the mapping that is no option, if any, taken as the value;
    a node there as the child), so that its child is checked too. ``inverter: {child: node}``: the child
    is the value itself. None when the mapping is as it should be (an inverter's child node)."""
    from coordinator.nodes import REGISTRY

    inner: LMap = outer[kind]
    node_valued = nk.value[0] == "node"
    if node_valued and ("child" not in inner or not set(inner) <= set(allowed) | {"child"}):
        return None
    merged = LMap()
    merged.pos, merged.key_pos, merged.val_pos = outer.pos, {}, {}
    for k, v in outer.items():
        if k != kind:
            merged[k], merged.key_pos[k], merged.val_pos[k] = v, outer.key_pos[k], outer.val_pos[k]
    value, at = _STAND_INS.get(nk.value[0]), inner.pos
    if node_valued:
        value, at = inner["child"], inner.val_pos["child"]
        p.err(inner.pos, "%s takes its child node as its value, not under 'child:': %s: {…the node…}" % (kind, kind))
    elif any(k in REGISTRY for k in inner):   # retry: {call: …}: the child given as the value
        if "child" not in merged:
            merged["child"], merged.key_pos["child"], merged.val_pos["child"] = inner, outer.key_pos[kind], inner.pos
        p.err(inner.pos, "%s takes its %s as its value and the node under 'child:', beside it: {%s: %s, child: …}"
              % (kind, nk.label or nk.value[0], kind, _PLACEHOLDERS.get(nk.value[0], "…")))
    else:
        others = [k for k in inner if k not in allowed]
        if len(others) == 1 and isinstance(inner[others[0]], (int, float, str, list)):
            value, at = inner[others[0]], inner.val_pos[others[0]]   # attempts: 3
            shown = _shown(value)
        else:
            shown = _PLACEHOLDERS.get(nk.value[0], "…")
        for k, v in inner.items():
            if k not in allowed:
                continue
            if k in merged:
                p.err(inner.key_pos[k], "option %r given twice" % k)
            else:
                merged[k], merged.key_pos[k], merged.val_pos[k] = v, inner.key_pos[k], inner.val_pos[k]
        options = [k for k in inner if k in allowed]
        p.err(inner.pos, "%s takes its %s as its value and its options beside it, not in a mapping: {%s: %s%s}%s" % (
            kind, nk.label or nk.value[0], kind, shown, "".join(", %s: %s" % (k, _shown(inner[k])) for k in options),
            " (in block form, %s %s below %s:, at its indentation)" % (
                " and ".join("%s:" % k for k in options), "on a line of its own" if len(options) == 1
                else "each on a line of its own", kind) if options else ""))
    merged[kind], merged.key_pos[kind], merged.val_pos[kind] = value, outer.key_pos[kind], at
    return merged


def check_inside(p: Any, raw: LMap, key: str) -> None:
    """The nodes written inside a node of unknown kind ``key`` (``Fallback: [...]``, ``RetryUntilSuccessful:
    {num_attempts: 3, child: …}``, ``children:`` beside it) are checked as nodes all the same, so that every
    problem is reported at once, not one more after each renaming. Only what is plainly a node is: a
    mapping in a list, or under ``child``/``children``; a bare value (``Timeout: 5``) is not."""
    found: List[LMap] = []

    def take(value: Any) -> None:
        if value.__class__ is LList:
            found.extend(item for item in value if item.__class__ is LMap)
        elif value.__class__ is LMap:
            found.append(value)

    value = raw.get(key)
    if value.__class__ is LList:
        take(value)
    elif value.__class__ is LMap:
        for inner in ("children", "child"):
            take(value.get(inner))
    for inner in ("children", "child"):
        if inner != key:
            take(raw.get(inner))
    p.depth += 1   # they are one level down: the depth limit counts the unknown node too
    try:
        for item in found:
            p.node(item, item.pos)
    finally:
        p.depth -= 1

