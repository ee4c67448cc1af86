"""Checks over a whole tree, asked of each node's kind (``coordinator.nodes``).

Data flow: every key a node reads is written earlier on every path by which the nodes before it
succeed, or is a declared input (a branch that never succeeds is no such path); a read is reported
at its reference, with where the key is written, and a key that no node writes is told apart (likely
misspelt: a close name is suggested). A ``switch`` case that only a call's status ``succeeded`` reaches may
read that call's outputs (:mod:`coordinator.statusflow`); a subtree's read that only its caller's keys let
pass is a warning at the include (:mod:`coordinator.subtreereads`).
Types: a ``$reference`` whose value's ROS type (known from the definitions of the nodes that
write the key) cannot be converted to the input it is passed to, or whose path names a field that
type does not have (``coordinator.values.follow``); a count, duration or ``for_each`` list of a type
that cannot be one (``coordinator.nodes.base.param_type_errors``). A key is typed only when all its
writers give one type: a node's definition gives it, or the reference whose value it copies (a ``set``
or an include argument of ``$pose``, ``for_each``'s element: the list's element type); a tree input, a
literal or an expression gives none. What a ``set`` of a literal, a template or an expression writes has a
kind (a number, text...), which the expressions are checked with when every writer of the key agrees on it
(:mod:`coordinator.keykinds`; a tree input may be given any value). A tree input that nothing else writes
is checked, as a count, duration or list, with the literals it is given (its default, the includes'
arguments), and in the call inputs it is passed to with those literals (:mod:`coordinator.inputvalues`).
"""
from __future__ import annotations

from typing import Any, Dict, FrozenSet, List, Mapping, Optional, Sequence, Set, Tuple

from coordinator.errors import Pos, TreeError
from coordinator.exprtypes import static_kind
from coordinator.keykinds import copied_kind
from coordinator.nodes.base import SET_ARG, Flow
from coordinator.refs import Computed, Ref, kind_of
from coordinator.treeast import REQUIRED, TreeFile, TreeNode, kinds_in, nodes_of, top_of
from coordinator.values import Binding, ExprValue, KeyTypes, Template, ref_kind, ref_type

__all__ = ["check_flow", "check_types", "key_types"]


def check_flow(tree: TreeFile, given: FrozenSet[str] = frozenset()) -> List[TreeError]:
    """Every read of a key not surely written before it, for a whole tree."""
    errors: List[TreeError] = []
    avail = frozenset(k for k, v in tree.inputs.items() if v is not REQUIRED) | given | tree.required_inputs
    flow = Flow(errors, tree)
    flow.of(top_of(tree), avail)
    if flow.missed:   # the keys written anywhere tell a misspelt key from one written too late
        flow.report(set(key_types(tree)) | avail)
    return errors


def key_types(tree: TreeFile, nodes: Optional[Sequence[TreeNode]] = None,
              given: FrozenSet[str] = frozenset()) -> KeyTypes:
    """For each tree key, the ROS types written to it (None: not known statically), and the literals the
    tree inputs that nothing else writes are given (``bound``; ``given``: inputs the caller sets, whose
    defaults are not used)."""
    return _key_types(tree, nodes, given)[0]


def _key_types(tree: TreeFile, nodes: Optional[Sequence[TreeNode]], given: FrozenSet[str],
               values: Optional[Mapping[str, Any]] = None) -> Tuple[KeyTypes, List[TreeNode], Dict[str, List[TreeNode]]]:
    """:func:`key_types`, with the nodes that bind a file's inputs (includes) and the writers of the keys
    that are inputs of a file; ``values``: those the run gives (``--set``), bound as such."""
    types = KeyTypes((k, {None}) for k in tree.inputs)
    kinds = types.kinds   # for each writer that gives no ROS type, one entry: the kind of its value, or None
    kinds.update((k, {None}) for k in tree.inputs)   # (any value may be given)
    nodes = nodes_of(top_of(tree)) if nodes is None else nodes
    node_kinds = kinds_in(nodes)
    binders = [n for n in nodes if n.nodekind.own_binds] if any(nk.own_binds for nk in node_kinds) else []
    inputs = set(tree.inputs)   # the keys that are inputs of a file
    for b in binders:
        bound = b.nodekind.binds(b)
        inputs.update(bound[0].inputs if bound is not None else ())
    writers: Dict[str, List[TreeNode]] = {}   # of those keys
    copies: List[Tuple[str, Any]] = []
    if any(nk.own_writes for nk in node_kinds):
        for n in nodes:
            nk = n.nodekind
            written = nk.writes(n) if nk.own_writes else None   # the base writes nothing
            if not written:
                continue
            like = nk.copies(n) if nk.own_copies else None
            for key, rostype in written.items():
                if like and key in like and isinstance(like[key], (Ref, ExprValue)):
                    copies.append((key, like[key]))
                    types.setdefault(key, set())
                else:
                    types.setdefault(key, set()).add(rostype)
                    if rostype is None:
                        kinds.setdefault(key, set()).add(_literal_kind(like[key]) if like and key in like else None)
                if key in inputs:
                    writers.setdefault(key, []).append(n)
        if copies:
            _settle(types, copies)
    if inputs:
        types.bound = _bindings(tree, binders, writers, given, values or {})
    types.why_not = _Choices(nodes, inputs)
    return types, binders, writers


class _Choices:
    """``KeyTypes.why_not``: why ``$key`` can never be (or contain) a text, as the nodes that write the key
    say of the values they write there (a call's ``status``: how it ended; ``never_matches``, which the
    ``switch`` check asks of its cases too); '' when one of them may write it, or says nothing (a ``set``),
    and for a key an input gives (any value may be given). The writers are found on first use."""

    def __init__(self, nodes: Sequence[TreeNode], inputs: Set[str]):
        self.nodes, self.inputs = nodes, inputs
        self.checking: Optional[TreeNode] = None   # the node whose values are checked: where messages are seen
        self._writers: Optional[Dict[str, List[TreeNode]]] = None

    def __call__(self, key: str, text: str, contains: bool) -> str:
        if key in self.inputs:
            return ""
        if self._writers is None:
            self._writers = {}
            for n in self.nodes:
                nk = n.nodekind
                written = nk.writes(n) if nk.own_writes else None
                for k in written if written else ():
                    self._writers.setdefault(k, []).append(n)
        writers = self._writers.get(key)
        if not writers or not all(hasattr(w.nodekind, "never_matches") for w in writers):
            return ""
        seen_from = self.checking.pos if self.checking is not None else Pos("", 0, 0)
        why = [w.nodekind.never_matches(w, key, text, contains, seen_from) for w in writers]
        if not all(why):   # (None: any value; '': it may be)
            return ""
        said = "case %r never matches: " % text   # the switch's words for its case
        return why[0][len(said):] if why[0].startswith(said) else why[0]


def _settle(types: KeyTypes, copies: List[Tuple[str, Any]]) -> None:
    """Add the type each copy gives its key: the type its reference holds (with, when it has none, the kind
    of the key it reads), or for an expression the kind of its value. A copy of a key only copies write waits
    until one of them gave a type (a loop of copies of one value holds its type); keys that still have none at
    the end (copies of each other only) are not known. An expression of no known kind with an operand of the
    wrong kind (an error of the tree) fails when it runs: it gives nothing (``who + 1`` after ``who: ana``)."""
    kinds = types.kinds
    while True:
        changed = True
        while changed:
            changed = False
            for key, value in copies:
                reads = [value] if isinstance(value, Ref) else value.refs
                if any(types.get(r.key) is not None and not types[r.key] for r in reads):
                    continue
                if isinstance(value, Ref):
                    t = ref_type(types, value)
                    kind = copied_kind(types, value) if t is None else None
                else:
                    errors: List[Tuple[int, str]] = []
                    t, kind = None, static_kind(value.expr.tree, lambda r: ref_kind(types, r), errors)
                    if kind is None and errors:
                        continue
                    kind = None if kind == "null" else kind
                if t not in types[key] or (t is None and kind not in kinds.get(key, ())):
                    types[key].add(t)
                    if t is None:
                        kinds.setdefault(key, set()).add(kind)
                    changed = True
        stuck = [key for key, _ in copies if not types[key]]
        if not stuck:
            return
        for key in stuck:
            types[key].add(None)
            kinds.setdefault(key, set()).add(None)


def _literal_kind(value: Any) -> Optional[str]:
    """The kind of a literal or a ``{…}`` template a ``set`` writes (None for a mapping and null: not checked)."""
    if isinstance(value, Template):
        return "string"
    kind = None if isinstance(value, Computed) else kind_of(value)
    return kind if kind in ("number", "string", "bool", "list") else None


def _literal(value: Any) -> bool:
    """A number, text, true/false or a list, written in the tree (a mapping is not checked this way)."""
    return (isinstance(value, (bool, int, float, str, list)) and not isinstance(value, (Ref, Computed))
            or isinstance(value, Template))   # a {…} template: text, whatever its keys hold


def _bindings(tree: TreeFile, binders: List[TreeNode], writers: Dict[str, List[TreeNode]],
              given: FrozenSet[str], values: Mapping[str, Any]) -> Dict[str, Dict[str, List[Binding]]]:
    """The literals each file's inputs start with, where no node but the includes of that file writes them:
    the values its counts, durations and lists read as ``$input`` (see ``KeyTypes``). An include that
    gives a value another one gave already is not listed again (its fix is the same)."""
    out: Dict[str, Dict[str, List[Binding]]] = {}
    here = tree.root.pos.file
    for k, default in tree.inputs.items():
        if k in values and k not in writers and _literal(values[k]):   # --set: its value, said so
            out.setdefault(k, {}).setdefault(here, []).append((values[k], SET_ARG, None))
        elif k not in given and k not in writers and _literal(default):
            out.setdefault(k, {}).setdefault(here, []).append((default, "", None))
    files, sole = _included(binders, writers)
    seen: Set[Tuple[str, str, str, str]] = set()
    for sub, args, b in files.values():
        for k, default in sub.inputs.items():
            value = args.get(k, default)
            if sole.get(k) is not sub or not _literal(value):   # (nor REQUIRED)
                continue
            arg = k if k in args else ""
            said = (k, arg, type(value).__name__, repr(value))
            if said not in seen:
                seen.add(said)
                out.setdefault(k, {}).setdefault(sub.root.pos.file, []).append((value, arg, b.pos))
    return out


_Includes = Dict[int, Tuple[TreeFile, Dict[str, Any], TreeNode]]


def _included(binders: List[TreeNode], writers: Dict[str, List[TreeNode]]
              ) -> Tuple[_Includes, Dict[str, Optional[TreeFile]]]:
    """Each include node once, as (its subtree, its arguments, itself); and for each key that is an input
    of a file, the one file whose includes are all its writers (None: another node writes it too)."""
    files: _Includes = {}
    for b in binders:
        bound = b.nodekind.binds(b)
        if bound is not None:
            files.setdefault(id(b), (bound[0], bound[1], b))
    sole: Dict[str, Optional[TreeFile]] = {}
    for k, ws in writers.items():
        subs = {id(files[id(w)][0]) if id(w) in files else 0 for w in ws}
        sole[k] = files[id(ws[0])][0] if len(subs) == 1 and 0 not in subs else None
    return files, sole


def check_types(tree: TreeFile, nodes: Optional[Sequence[TreeNode]] = None, given: FrozenSet[str] = frozenset(),
                defaults: Optional[Mapping[str, Any]] = None, values: Optional[Mapping[str, Any]] = None
                ) -> List[TreeError]:
    """References that cannot fit the input they are passed to (``given``: inputs the caller sets); a
    ``warning: `` among them is one (the tree's default of an input that cannot be used as it is). And the
    literals tree inputs are given (their defaults, the includes' arguments) that a call input they are
    passed to (``$x``, ``$x.field``, anywhere in its value) could never take, at the literal: the call would
    refuse them when built, after the calls before it ran; only where no node writes the key (a key some node
    may write could hold another value by then). ``defaults``: each file's ``inputs:`` as written, by file
    (where a default is). ``values``: the inputs the run gives (``--set``), checked where counts and durations read
    them."""
    errors: List[TreeError] = []
    nodes = nodes_of(top_of(tree)) if nodes is None else nodes
    types, binders, writers = _key_types(tree, nodes, given, values)
    choices = types.why_not if isinstance(types.why_not, _Choices) else None
    for n in nodes:
        nk = n.nodekind
        if nk.own_check_types:   # the base checks nothing
            if choices is not None:
                choices.checking = n
            nk.check_types(n, types, errors)
    if tree.inputs or binders or any(n.nodekind.name == "for_each" for n in nodes):   # (its list's elements too)
        from coordinator.inputvalues import default_misfits  # it reads the data flow: imported here

        errors.extend(default_misfits(tree, nodes, binders, writers, given, defaults))
    return errors
