"""``switch``: run the one child whose case matches a value (the answer heard, a room, a count)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, FrozenSet, Iterable, Iterator, List, Optional, Tuple

import py_trees
from py_trees.common import Status

from coordinator.errors import Pos, TreeError
from coordinator.expr import text_of
from coordinator.nodes.base import Flow, NodeKind, Option, check_choice, fixed, meet
from coordinator.refs import RefError, refs_in, resolve, unwrap
from coordinator.treeast import TreeNode
from coordinator.values import at_value_errors, read_at

__all__ = ["KINDS", "Switch", "SwitchSpec"]


@dataclass
class SwitchSpec:
    value: Any                                           # a literal, Ref, ExprValue or Template
    labels: List[Any] = field(default_factory=list)      # case values, one per child (the default is last)
    has_default: bool = False
    match: str = "equals"


def matches(value: Any, label: Any, how: str) -> bool:
    """Whether a case label matches the value (``contains``: the label's text, in any case, is in the value)."""
    value = unwrap(value)
    if how == "contains":
        return isinstance(value, str) and text_of(label).lower() in value.lower()
    if isinstance(label, str) != isinstance(value, str):
        return text_of(value) == text_of(label)
    return bool(value == label)


class Switch(py_trees.composites.Composite):
    """Ticks only the chosen child; its status is the switch's. No match and no default: FAILURE."""

    def __init__(self, name: str, children: List[py_trees.behaviour.Behaviour], spec: SwitchSpec, ctx: Any):
        super().__init__(name=name, children=children)
        self.spec = spec
        self.ctx = ctx

    def choose(self) -> Tuple[Optional[py_trees.behaviour.Behaviour], str]:
        """The child to run, and what the feedback says."""
        spec = self.spec
        try:
            value = unwrap(resolve(spec.value, self.ctx.lookup))
        except (KeyError, RefError) as exc:
            return None, "cannot read the value: %s" % (exc.args[0] if exc.args else exc)
        for label, child in zip(spec.labels, self.children):
            if matches(value, label, spec.match):
                return child, "case %r (value %r)" % (label, value)
        if spec.has_default:
            return self.children[-1], "default (value %r)" % (value,)
        return None, "no case %s %r (cases: %s) and no default" % (
            "matches" if spec.match == "equals" else "is contained in", value,
            ", ".join(repr(lab) for lab in spec.labels))

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        if self.status != Status.RUNNING:
            self.current_child, self.feedback_message = self.choose()
            if self.current_child is None:
                self.stop(Status.FAILURE)
                yield self
                return
        assert self.current_child is not None
        yield from self.current_child.tick()
        new_status = self.current_child.status
        if new_status == Status.FAILURE:
            self.feedback_message = ""   # the case's own reason is the reason
        if new_status != Status.RUNNING:
            self.stop(new_status)
        self.status = new_status
        yield self


class SwitchKind(NodeKind):
    name = "switch"
    family = "composite"
    value = ("value", "a value: `$key`, `$( … )`, text with `{…}`")
    summary = "run the child of the first case that matches the value, else `default`; no match and no " \
              "default is FAILURE"
    options = (Option("cases", "cases", "case value → node, tried in order", required=True),
               Option("default", "node", "the node run when no case matches"),
               Option("match", "match", "`equals`: the value is the case; `contains`: the case's text is in the "
                                        "value (any case), e.g. `yes` in \"yes, please\"", default="equals"))

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> SwitchSpec:
        spec = SwitchSpec(value=p.literal_at(raw, self.name, at),
                          match=check_choice(p, raw, "match", ("equals", "contains"), "equals"))
        cases = raw.get("cases")
        if "cases" in raw and (not isinstance(cases, dict) or not cases):
            p.err(raw.val_pos["cases"], "'cases' must be a non-empty mapping of case value: node")
            cases = {}
        for label, sub in (cases or {}).items():
            if isinstance(label, bool) or label is None:
                p.err(cases.key_pos[label], "this case is read by YAML as %s (unquoted yes/no/on/off/null): quote "
                                            "it, e.g. \"yes\": or \"no\":" % text_of(label))
                continue
            if not isinstance(label, (str, int, float)):
                p.err(cases.key_pos[label], "a case is a string or a number, got %r" % (label,))
                continue
            before = len(node.children)
            p.child(node, sub, cases.val_pos[label])
            if len(node.children) > before:
                spec.labels.append(label)
        if "default" in raw:
            before = len(node.children)
            p.child(node, raw["default"], raw.val_pos["default"])
            spec.has_default = len(node.children) > before
        return spec

    def default_name(self, node: TreeNode) -> str:
        return "switch %s" % (node.spec.value if not isinstance(node.spec.value, str) else repr(node.spec.value))

    def reads(self, node: TreeNode) -> Iterable[str]:
        return [r.key for r in refs_in(node.spec.value)]

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Ends as the chosen child does: a case that never succeeds (a ``force_failure`` default) is no
        way for the switch to succeed. It also fails with no child run, when nothing matches and there
        is no default, or when its value cannot be worked out."""
        f.need(node, self.reads(node), avail)
        outs = [f.outcome(c, avail) for c in node.children]
        ok = meet(cs for cs, _ in outs)
        failed = meet(cf for _, cf in outs)
        if not node.spec.has_default or not fixed(node.spec.value):
            failed = meet((failed, frozenset()))
        return ok, failed

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        at_value_errors(node.spec.value, node.value_pos or node.pos, types, errors)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        return read_at(node.spec.value, node.value_pos, key) if node.value_pos is not None else None

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return Switch(node.name, [child(c) for c in node.children], node.spec, ctx)


KINDS = (SwitchKind(),)
