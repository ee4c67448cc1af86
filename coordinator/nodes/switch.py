"""``switch``: run the one child whose case matches a value (the answer heard, a room, a count)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, FrozenSet, Iterable, Iterator, List, Optional, Tuple

import py_trees
from py_trees.common import Status

from coordinator.errors import Pos, TreeError
from coordinator.expr import kind_of, text_of
from coordinator.exprfuncs import apply_function
from coordinator.nodes.base import Flow, NodeKind, Option, check_choice, fixed, join, meet
from coordinator.nodes.call import STATUS_TEXTS
from coordinator.refs import Ref, RefError, refs_in, resolve, unwrap
from coordinator.statusflow import sure_when_status
from coordinator.treeast import TreeNode
from coordinator.values import at_value_errors, read_at, value_kind

__all__ = ["KINDS", "Switch", "SwitchSpec"]


@dataclass
class SwitchSpec:
    value: Any                                           # a literal, Ref, ExprValue or Template
    labels: List[Any] = field(default_factory=list)      # case values, one per child (the default is last)
    has_default: bool = False
    match: str = "equals"
    label_pos: List[Pos] = field(default_factory=list, compare=False, repr=False)   # where each case is written
    match_pos: Optional[Pos] = field(default=None, compare=False, repr=False)


def matches(value: Any, label: Any, how: str) -> bool:
    """Whether a case label matches the value (``contains``: the label's text, in any case, is in the value).

    ``equals``: a value of the case's own kind (text, a number, true/false) matches when equal (3 and 3.0);
    of another kind, when the value written as text (as a template or ``str()`` writes it: ``3``, ``true``)
    is the case's text: ``3:`` matches the text "3", ``"true":`` a true. This is ``str(value) == "case"``
    in an expression; ``==`` itself does not convert (``bmtree check`` reports ``door_open == "true"``).
    """
    value = unwrap(value)
    if how == "contains":
        return isinstance(value, str) and text_of(label).lower() in value.lower()
    if how == "words":   # the case's words, in order, among the value's: "no" in "No, thanks", not "I don't know"
        if not isinstance(value, str):
            return False
        want, got = apply_function("words", [text_of(label)]), apply_function("words", [value])
        return bool(want) and any(got[i:i + len(want)] == want for i in range(len(got) - len(want) + 1))
    if kind_of(label) != kind_of(value):   # (a true/false value is no number here: true is not 1)
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
                                        "value (any case), e.g. `yes` in \"yes, please\"; `words`: the case's "
                                        "words are words of the value, in order (any case, punctuation aside): "
                                        "`no` matches \"No, thanks.\" but not \"I don't know\"",
                                        default="equals"))

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> SwitchSpec:
        spec = SwitchSpec(value=p.literal_at(raw, self.name, at),
                          match=check_choice(p, raw, "match", ("equals", "contains", "words"), "equals"),
                          match_pos=raw.val_pos["match"] if "match" in raw else None)
        cases = raw.get("cases")
        if "cases" in raw and (not isinstance(cases, dict) or not cases):
            p.err(raw.val_pos["cases"], "'cases' must be a non-empty mapping of case value: node")
            cases = {}
        for label, sub in (cases or {}).items():
            if label is None:
                p.err(cases.key_pos[label], "this case is read by YAML as null (unquoted null or ~): quote it, "
                                            "e.g. \"null\":")
                continue
            if not isinstance(label, (str, int, float)):
                p.err(cases.key_pos[label], "a case is a string or a number, got %r" % (label,))
                continue
            before = len(node.children)
            p.child(node, sub, cases.val_pos[label])
            if len(node.children) > before:
                spec.labels.append(label)
                spec.label_pos.append(cases.key_pos[label])
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
        is no default, or when its value cannot be worked out. A case run only when ``$key`` is a call's
        status ``succeeded`` may read that call's outputs (:mod:`coordinator.statusflow`)."""
        f.need(node, self.reads(node), avail)
        _cases_never_matching(node, f)
        outs = []
        for c, sure in zip(node.children, _sure_in_cases(node, f)):
            cs, cf = f.outcome(c, avail | sure if sure else avail)
            outs.append((join(sure, cs), join(sure, cf)) if sure else (cs, cf))
        ok = meet(cs for cs, _ in outs)
        failed = meet(cf for _, cf in outs)
        if not node.spec.has_default or not fixed(node.spec.value):
            failed = meet((failed, frozenset()))
        return ok, failed

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        before = len(errors)
        at_value_errors(node.spec.value, node.value_pos or node.pos, types, errors)
        if len(errors) == before:   # (a value of the wrong kind inside: its kind says nothing of the cases)
            _cases_of_another_kind(node, types, errors)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        return read_at(node.spec.value, node.value_pos, key) if node.value_pos is not None else None

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        return Switch(node.name, [child(c) for c in node.children], node.spec, ctx)


def _cases_never_matching(node: TreeNode, f: Flow) -> None:
    """An error at each case that can never match ``$key`` when every node that writes the key says
    which values it writes (a call's ``status``: how it ended, ``never_matches``): a misspelt status
    (``timed_out``) would silently never run its case."""
    spec: SwitchSpec = node.spec
    value = spec.value
    if not isinstance(value, Ref) or value.path or not spec.label_pos:
        return
    key = value.key
    if any(key in t.inputs for t in f.files):   # a tree input: any value may be given
        return
    writers = f.writers(key)
    if not writers or not all(hasattr(w.nodekind, "never_matches") for w in writers):
        return
    contains = spec.match in ("contains", "words")   # (a case whose text is in no status is in none as words)
    for label, at in zip(spec.labels, spec.label_pos):
        if label is None or isinstance(label, bool):   # an unquoted yes/no/null: the type check says so
            continue
        why = [w.nodekind.never_matches(w, key, label, contains, at) for w in writers]
        if all(why):   # (None, any value: no error; '': it may match)
            f.errors.append(TreeError(at, why[0]))


def _sure_in_cases(node: TreeNode, f: Flow) -> List[FrozenSet[str]]:
    """For each child (the default last), the keys surely written when it runs, known from the value: on
    ``$key`` that only calls' ``status`` writes, a case that matches no status but ``succeeded`` (those an
    earlier case matches aside) runs after such a call succeeded. The default gets nothing."""
    spec: SwitchSpec = node.spec
    none: List[FrozenSet[str]] = [frozenset()] * len(node.children)
    if not isinstance(spec.value, Ref) or spec.value.path or not spec.labels:
        return none
    left = list(STATUS_TEXTS)   # the statuses no earlier case matches
    out = []
    for label in spec.labels:
        taken = [s for s in left if matches(s, label, spec.match)]
        left = [s for s in left if s not in taken]
        out.append(sure_when_status(f, spec.value.key, taken) if taken else frozenset())
    return out + none[len(out):]


_YAML_BOOL = "this case is read by YAML as %s (unquoted yes/no/on/off/null)"
_KINDS_SAID = {"bool": "true or false", "number": "a number", "string": "text", "list": "a list", "message": "a message"}


def _cases_of_another_kind(node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
    """What the value's kind, when the definitions give it, says of the cases (see :func:`matches`): an
    error at each case that can never match it (``ok:`` for a ``std_msgs/Int32``, ``"yes":`` for a
    ``std_msgs/Bool``), at ``match: contains`` of a value that is not text, and at a case YAML read as
    true/false (``yes:`` unquoted) unless the value is true or false itself."""
    spec: SwitchSpec = node.spec
    kind, said = value_kind(types, spec.value)
    if kind == "string":
        said = ""   # a text value: every case may match (a number case matches its text)
    elif kind is not None and spec.match in ("contains", "words") and spec.match_pos is not None:
        errors.append(TreeError(spec.match_pos, "match: %s looks for the case's %s in the value, but %s: "
                                                "use match: equals" % (spec.match, "text" if spec.match == "contains"
                                                                       else "words", said)))
        return
    elif kind in ("list", "message") and spec.labels:
        errors.append(TreeError(node.value_pos or node.pos, "no case can match: %s, and a case is text or a "
                                                            "number: switch on one of its fields" % said))
        return
    for label, at in zip(spec.labels, spec.label_pos):
        why = ""
        if isinstance(label, bool) and kind in (None, "string") and _written(at).lower() in ("true", "false"):
            continue   # true: matches a true value and the text "true" alike (see matches)
        if isinstance(label, bool) and kind != "bool":
            why = _YAML_BOOL % text_of(label) + (
                ": quote it, e.g. \"yes\": or \"no\":" if not said else ", and %s: it never matches" % said)
            if kind is None:
                why += " (a value that is true or false is matched by true: and false:)"
        elif kind == "bool" and not isinstance(label, bool) and text_of(label) not in ("true", "false"):
            why = "case %r never matches: %s: its cases are true: and false:" % (label, said)
        elif kind == "number" and isinstance(label, str) and not _number_text(label):
            fix = _write_number(label)
            why = "case %r never matches: %s, %s" % (label, said, "whose text is never %r%s" % (label, fix)
                                                          if fix else "not text")
        if why:
            errors.append(TreeError(at, why))


def _written(at: Pos) -> str:
    """The case's key as written at ``at`` in its file ('' when it cannot be read): YAML made both
    ``true:`` and ``yes:`` a true, and only the second never matches the text it says."""
    import itertools

    try:
        with open(at.file, encoding="utf-8", errors="replace") as fh:
            line = next(itertools.islice(fh, at.line - 1, None), "")
    except OSError:
        return ""
    return line[at.column - 1:at.column + 7].split(":")[0].strip().strip("'\"")


def _number_text(text: str) -> bool:
    """Whether a number's text (as :func:`text_of` writes it) can be ``text``: ``3``, ``-2.5``; not ``3.0``."""
    try:
        return text_of(int(text)) == text if text.strip().lstrip("-").isdigit() else text_of(float(text)) == text
    except ValueError:
        return False


def _write_number(text: str) -> str:
    """`` (write 3:)`` for a case ``"3.0"`` or ``"03"``: the case that matches the number it spells."""
    try:
        num = float(text)
    except ValueError:
        return ""
    return " (write %s:)" % text_of(num) if num == num and abs(num) != float("inf") else ""


KINDS = (SwitchKind(),)
