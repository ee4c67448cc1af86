"""``include``: a subtree from another file, its ``inputs`` bound by ``args``."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Dict, FrozenSet, Iterable, List, Optional, Set, Tuple

import py_trees

from comm.errors import did_you_mean
from coordinator.errors import Pos, TreeError
from coordinator.nodes.base import NEVER, Flow, NodeKind, Option, fixed, join, meet, repeated_outputs, where
from coordinator.nodes.leaves import SetKeys
from coordinator.refs import Ref, refs_in
from coordinator.subtreereads import Alone, caller_key_reads
from coordinator.treeast import REQUIRED, TreeFile, TreeNode
from coordinator.values import at_value_errors, read_at

__all__ = ["IncludeSpec", "KINDS"]


@dataclass
class IncludeSpec:
    path: Any
    args: Dict[str, Any] = field(default_factory=dict)
    tree: Optional[TreeFile] = None
    arg_pos: Dict[str, Pos] = field(default_factory=dict)   # where each argument's value is written
    outputs: Dict[str, str] = field(default_factory=dict)   # subtree key -> caller key, copied on success
    output_pos: Dict[str, Pos] = field(default_factory=dict)   # where each subtree key is written
    # its warnings, found by the data-flow walk (which runs before the warnings): the keys of the caller it
    # replaces, and those the subtree reads without declaring them (coordinator.subtreereads)
    clashes: Set[TreeError] = field(default_factory=set, compare=False, repr=False)
    clashes_of: Any = field(default=None, compare=False, repr=False)   # the walk that found them: a new one starts afresh

    def bound(self) -> Dict[str, Any]:
        """What the include sets when it starts: the subtree's defaults, then the arguments."""
        values = {k: v for k, v in self.tree.inputs.items() if v is not REQUIRED} if self.tree else {}
        values.update(self.args)
        return values


class IncludeKind(NodeKind):
    name = "include"
    family = "leaf"
    value = ("path", "a tree file (relative to this file)")
    summary = "the subtree, run as a sequence after setting its inputs"
    options = (Option("args", "inputs", "input name → value"),
               Option("outputs", "outputs", "subtree key → caller key: after the subtree succeeds, each key it "
                                            "surely wrote is copied to the caller's key (its own keys stay "
                                            "on the shared blackboard too)"))

    def parse(self, p: Any, node: TreeNode, raw: Any, value: Any, at: Pos) -> IncludeSpec:
        args_raw = p.mapping(raw, "args", at, "'args' must be a mapping of input name: value")
        spec = IncludeSpec(path=value, args={k: p.literal_at(args_raw, k, at) for k in args_raw},
                           arg_pos={k: args_raw.val_pos[k] for k in args_raw})
        _parse_outputs(p, raw, at, spec)
        if not isinstance(value, str) or not value:
            p.err(at, "include takes a file path")
            return spec
        sub = p.include(value, at)
        if sub is None:
            return spec
        spec.tree = sub
        if sub.cleanup is not None:   # only the run tree's cleanup runs (coordinator/cleanupparse.py)
            from coordinator.cleanupparse import included_cleanup_warning

            p.warn(at, included_cleanup_warning(sub))
        for k in spec.args:
            if k not in sub.inputs:
                p.err(args_raw.key_pos[k], "%s has no input %r%s" % (value, k, did_you_mean(k, sub.inputs)
                                                                      or " (inputs: %s)" % (", ".join(sub.inputs)
                                                                                            or "none")))
        for k in sorted(sub.required_inputs - set(spec.args)):
            p.err(at, "include of %s needs argument %r" % (value, k))
        return spec

    def default_name(self, node: TreeNode) -> str:
        spec = node.spec
        if spec.tree is None:
            return self.name
        args = spec.args
        return "%s%s" % (spec.tree.name, "(%s)" % ", ".join("%s=%s" % kv for kv in args.items()) if args else "")

    def reads(self, node: TreeNode) -> Iterable[str]:
        return [r.key for r in refs_in(node.spec.args)]

    def writes(self, node: TreeNode) -> Dict[str, Optional[str]]:
        out: Dict[str, Optional[str]] = dict.fromkeys(node.spec.bound())
        out.update(dict.fromkeys(node.spec.outputs.values()))
        return out

    def copies(self, node: TreeNode) -> Dict[str, Ref]:
        """An argument ``$pose`` gives the input what it holds; an output, what the subtree's key holds."""
        out = {k: v for k, v in node.spec.args.items() if isinstance(v, Ref)}
        out.update((caller, Ref(key)) for key, caller in node.spec.outputs.items())
        return out

    def binds(self, node: TreeNode) -> Optional[Tuple[TreeFile, Dict[str, Any]]]:
        return (node.spec.tree, node.spec.args) if node.spec.tree is not None else None

    def check_types(self, node: TreeNode, types: Dict[str, set], errors: List[TreeError]) -> None:
        where = node.spec.arg_pos
        for k, v in node.spec.args.items():
            at_value_errors(v, where[k] if k in where else node.pos, types, errors)

    def read_pos(self, node: TreeNode, key: str) -> Optional[Pos]:
        where = node.spec.arg_pos
        return next((p for p in (read_at(v, where[k], key) for k, v in node.spec.args.items() if k in where)
                     if p is not None), None)

    def outcome(self, node: TreeNode, avail: FrozenSet[str], f: Flow) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """A sequence: its inputs set (failing when an argument's reference cannot be read), the subtree,
        then its ``outputs`` copied (each a key the subtree surely wrote: else an error at the key). Inside,
        an input without its argument counts as given: that is reported by itself. The keys of the caller
        it replaces, and those it reads without declaring them, are warnings (``clashes``)."""
        f.need(node, self.reads(node), avail)
        spec = node.spec
        sub = spec.tree
        if sub is None:
            return frozenset(), frozenset()
        bound = frozenset(spec.bound())
        real = not isinstance(f, Alone)   # (a walk of the subtree by itself only wants what it writes)
        if real:
            if spec.clashes_of is not f:
                spec.clashes_of, spec.clashes = f, set()
            spec.clashes.update(_clashes(node, sub, avail, f))
        own = bound | sub.required_inputs
        start = len(f.missed)
        f.files.append(sub)
        try:
            ok, failed = f.outcome(sub.root, avail | own)
        finally:
            f.files.pop()
        if real and avail - own:   # (only the caller's keys can make a read pass that fails alone)
            spec.clashes.update(caller_key_reads(node, sub, own, avail, f.missed[start:], f))
        if spec.outputs and ok is not NEVER:   # (a subtree that never succeeds copies nothing)
            for e in _output_errors(node, sub, ok, bound, f):
                if e not in f.errors:   # (a subtree is walked once per include of it)
                    f.errors.append(e)
            ok = ok | frozenset(spec.outputs.values())
        failed = join(bound, failed)
        return join(bound, ok), failed if fixed(spec.bound()) else meet((failed, frozenset()))

    def warnings(self, node: TreeNode) -> List[TreeError]:
        return sorted(node.spec.clashes, key=lambda e: (e.pos.line, e.pos.column, e.message))

    def expand(self, node: TreeNode) -> List[TreeNode]:
        return [node.spec.tree.root] if node.spec.tree is not None else []

    def build(self, node: TreeNode, ctx: Any, child: Any) -> py_trees.behaviour.Behaviour:
        sub = node.spec.tree
        values = node.spec.bound()
        kids = []
        if values:
            setter = TreeNode("set", "arguments of %s" % sub.name, node.pos, spec=values)
            kids.append(SetKeys(setter, ctx))
        kids.append(child(sub.root))
        if node.spec.outputs:
            copier = TreeNode("set", "outputs of %s" % sub.name, node.pos,
                              spec={caller: Ref(key) for key, caller in node.spec.outputs.items()})
            kids.append(SetKeys(copier, ctx))
        return py_trees.composites.Sequence(name=node.name, memory=True, children=kids)


def _parse_outputs(p: Any, raw: Any, at: Pos, spec: IncludeSpec) -> None:
    """``outputs: {subtree key: caller key}``, both tree keys (whether the subtree writes its keys is
    known after the data-flow walk: see ``_output_errors``)."""
    m = p.mapping(raw, "outputs", at, "'outputs' must be a mapping of subtree key: caller key, e.g. "
                                      "outputs: {answer: guest_answer}")
    for k, v in m.items():
        if not isinstance(k, str) or not k.isidentifier():
            p.err(m.key_pos[k], "subtree key %r is not a tree key (an identifier)" % (k,))
        elif not isinstance(v, str) or not v.isidentifier():
            p.err(m.val_pos[k], "caller key %r is not a tree key (an identifier)" % (v,))
        else:
            spec.outputs[k] = v
            spec.output_pos[k] = m.key_pos[k]
    repeated_outputs(p, raw, spec.outputs)


def _output_errors(node: TreeNode, sub: TreeFile, written: FrozenSet[str], inputs: FrozenSet[str],
                   f: Flow) -> List[TreeError]:
    """An error at each subtree key of ``outputs`` that the subtree does not surely hold when it succeeds
    (``written``: the keys it surely writes then; ``inputs``: those the include sets)."""
    name = os.path.basename(sub.path)
    sure = written | inputs
    out = []
    for key in node.spec.outputs:
        if key in sure:
            continue
        at = node.spec.output_pos.get(key, node.pos)
        writer = f.file_writes(sub).get(key)
        shown = ", ".join(sorted(written)[:8]) + (", …" if len(written) > 8 else "")
        listed = "it surely writes %s" % shown if written else "it surely writes no key when it succeeds"
        if writer is not None:
            message = ("%s writes %r (%s), but not on every path by which it succeeds: write it on every path "
                       "(%s)" % (name, key, where(writer.pos, at), listed))
        else:
            message = "%s does not write %r%s" % (name, key, did_you_mean(key, sure | set(f.file_writes(sub)))
                                                  or " (%s)" % listed)
        out.append(TreeError(at, "outputs: " + message))
    return out


def _clashes(node: TreeNode, sub: TreeFile, held: FrozenSet[str], f: Flow) -> List[TreeError]:
    """The caller's keys (``held``: surely written or declared before the include) that the include
    replaces on the one tree blackboard: an input the arguments leave to its default, an argument that
    is not the caller's own key passed on, a key a node of the subtree's file writes (unless ``outputs``
    copies the subtree's key to that same caller key: the replacement is meant). A key that only an
    earlier run of this same subtree holds is not the caller's."""
    spec = node.spec
    name = os.path.basename(sub.path)
    found: Dict[str, Tuple[Pos, str]] = {}
    for k, default in sub.inputs.items():
        if k in held and k not in spec.args and default is not REQUIRED:
            found[k] = (node.pos, "include of %s sets its input %r to its default %s, replacing the caller's %r "
                                  "(%%s): pass it on with args: {%s: $%s}, or rename one of them"
                        % (name, k, _shown(default), k, k, k))
    for k, v in spec.args.items():
        if k in held and not (isinstance(v, Ref) and v.key == k and not v.path):
            found[k] = (spec.arg_pos.get(k, node.pos), "argument %r of %s is set on the tree blackboard, replacing "
                                                       "the caller's %r (%%s): rename the caller's key or the "
                                                       "subtree's input" % (k, name, k))
    for k, writer in f.file_writes(sub).items():
        if k in held and k not in found and spec.outputs.get(k) != k:   # (outputs: {k: k} says to replace it)
            found[k] = (node.pos, "%s writes %r (%s), replacing the caller's %r (%%s): rename one of them"
                        % (name, k, where(writer.pos, node.pos), k))
    out = []
    for k, (at, message) in sorted(found.items()):
        place = _caller_place(node, sub, k, f)
        if place:
            out.append(TreeError(at, "warning: " + message % place))
    return out


def _caller_place(node: TreeNode, sub: TreeFile, key: str, f: Flow) -> str:
    """Where the caller's ``key`` comes from, as the warning at ``node`` names it ('' when it is not the
    caller's: only runs of ``sub`` itself, or of other subtrees, write it): an input of the including
    file, else a writer in the including file or a file further up the includes (one in the including
    file first; an include there counts by its ``outputs`` only; in the including file, only one before
    the include), else an input of a file further up. A key that only the nodes or arguments of other
    included files write (two subtrees that each write ``answer``, copied to the caller's keys by
    ``outputs``; two that each take an input ``question``) belongs to those subtrees."""
    caller = f.files[-1] if f.files else None
    here = node.pos.file
    if caller is not None and key in caller.inputs:
        return "an input of %s" % os.path.basename(caller.path)
    callers = {t.root.pos.file for t in f.files}
    at = (node.pos.line, node.pos.column)
    writers = [w for w in f.writers(key)   # not this include, nor another of the same file, nor one after it
               if w.pos.file in callers and not (w.kind == "include" and (
                   w.spec.tree is sub or key not in getattr(w.spec, "outputs", {}).values()))
               and not (w.pos.file == here and (w.pos.line, w.pos.column) > at)]
    if writers:
        w = next((w for w in writers if w.pos.file == here), writers[0])
        return "written at %s" % where(w.pos, node.pos)
    up = next((t for t in reversed(f.files) if key in t.inputs), None)
    return "an input of %s" % os.path.basename(up.path) if up is not None else ""


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


KINDS = (IncludeKind(),)

