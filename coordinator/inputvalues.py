"""The values tree inputs are given against the call inputs they are passed to: a tree input that no
node writes holds its default, an include's argument, or a ``--set`` value of a run, and a call input
that reads it (``$x``, ``$x.field``, anywhere in its value) converts it as the call does when it is
built (``typed_inputs`` of a kind: the call's). One that could never fit is an error before the run,
not a call refused after the calls before it ran."""
from __future__ import annotations

from typing import Any, Dict, FrozenSet, List, Mapping, NamedTuple, Optional, Sequence, Set, Tuple

from comm.errors import ProtocolError
from comm.rostypes import resolve_type
from comm.typewords import ValueMisfit
from coordinator.dataflow import _included, _key_types
from coordinator.errors import Pos, TreeError
from coordinator.expr import brief, text_of
from coordinator.nodes.base import where
from coordinator.refs import Computed, Ref, RefError, refs_in
from coordinator.treeast import REQUIRED, TreeFile, TreeNode, nodes_of, top_of
from coordinator.values import _NUMBERS, _field_type, _stands_for
from coordinator.yamlsrc import pos_of

__all__ = ["Source", "default_misfits", "set_value_errors"]


def default_misfits(tree: TreeFile, nodes: Sequence[TreeNode], binders: List[TreeNode],
                    writers: Dict[str, List[TreeNode]], given: FrozenSet[str],
                    defaults: Optional[Mapping[str, Any]]) -> List[TreeError]:
    """The literals tree inputs are given (defaults, include arguments) that a call input could never take,
    each at the literal (``defaults``: each file's ``inputs:`` as written, by file)."""
    sources = _elements(nodes, writers, _sources(tree, binders, writers, {}, given, defaults))
    return [TreeError(src.at, text) for src, text in _misfits(nodes, sources) if src.at is not None]


def _written(node: TreeNode) -> Set[str]:
    writes = getattr(node.nodekind, "writes", None)
    try:
        return set(writes(node)) if writes is not None else set()
    except (AttributeError, TypeError):   # a kind that writes nothing of its spec
        return set()


def _elements(nodes: Sequence[TreeNode], writers: Dict[str, List[TreeNode]], sources: _Sources) -> _Sources:
    """``sources`` and, for a ``for_each`` whose ``as`` key only it writes, over a list literal or a bare
    ``$key`` of them, that key's values: each element of the list, or of each list the key may hold
    (``[0.2, "slow"]`` passed on to a number)."""
    for n in nodes:
        copies = getattr(n.nodekind, "copies", None)
        if n.nodekind.name != "for_each" or copies is None:
            continue
        key, items = getattr(n.spec, "key", ""), getattr(n.spec, "items", None)
        if key and isinstance(items, list) and key not in sources and not any(
                w is not n for w in writers.get(key, [])) and not any(m is not n and key in _written(m) for m in nodes):
            held = [Source(v, "element %d of the for_each's list" % i, n.value_pos or n.pos)
                    for i, v in enumerate(items[:_MOST_SOURCES]) if not refs_in(v)]
            if held:
                sources[key] = {n.pos.file: held}
        for key, ref in copies(n).items():
            if ref.path != (0,) or key in sources or any(w is not n for w in writers.get(key, [])) or any(
                    m is not n and key in _written(m) for m in nodes):
                continue
            file = n.pos.file
            held = [Source(v, "element %d of %s" % (i, src.said), src.at, src.via)
                    for src in sources.get(ref.key, {}).get(file, ()) if isinstance(src.value, list)
                    for i, v in enumerate(src.value[:_MOST_SOURCES])]
            if held:
                sources[key] = {file: held}
    return sources


class Source(NamedTuple):
    """A value a tree input holds where its file's nodes read it (no node writes its key)."""

    value: Any
    said: str                # what gives it: "input x's default", "include argument x", "--set x"
    at: Optional[Pos]        # where it is written (None: on the command line)
    via: str = ""            # ", passed on as argument 'tx' of the include at line 14"


_Sources = Dict[str, Dict[str, List[Source]]]   # key -> file -> the values it may hold there
_MOST_SOURCES = 32   # values followed per key and file (includes of includes passing a value on multiply them)


def set_value_errors(tree: TreeFile, values: Mapping[str, Any]) -> List[str]:
    """Why values given on the command line (``bmtree run --set``) could never be a call input the tree
    passes them to, checked as :func:`check_types` checks the defaults: ``--set x: 'abc' is text, but
    navigation.approach's target.x at t.yaml:6:24 takes a number (float64)``."""
    if not values:
        return []
    nodes = nodes_of(top_of(tree))
    _, binders, writers = _key_types(tree, nodes, frozenset())
    sources = _elements(nodes, writers, _sources(tree, binders, writers, values, frozenset(), None, literals=False))
    return [text for src, text in _misfits(nodes, sources) if src.at is None] + _param_misfits(tree, values)


def _param_misfits(tree: TreeFile, values: Mapping[str, Any]) -> List[str]:
    """The counts, durations and lists of the tree (``retry: $n``, ``timeout: $secs``) that a given value could
    never be, checked as a default is (``bmtree check`` warns of one)."""
    from coordinator.dataflow import check_types

    given = {k: v for k, v in values.items() if k in tree.inputs}
    return ["%s: %s" % (e.pos, e.message) for e in check_types(tree, given=frozenset(given), values=given)
            if "(--set " in e.message]


def _sources(tree: TreeFile, binders: List[TreeNode], writers: Dict[str, List[TreeNode]], values: Mapping[str, Any],
             skip: FrozenSet[str], defaults: Optional[Mapping[str, Any]], literals: bool = True) -> _Sources:
    """For each key that only its file's inputs give (no node writes it; in a subtree, no node but the
    includes of that file), the values it holds where that file's nodes read it: the run tree's ``values``
    (``--set``) or defaults (not those of ``skip``), an include's argument or the subtree's default it
    leaves, and an argument ``$key`` of the including file: the values that key holds there. A value that
    reads keys (a ``$( … )``, a template) is not known; ``literals`` False: only ``values`` and what passes
    them on."""
    out: _Sources = {}
    here = tree.root.pos.file
    files, _ = _included(binders, {})
    changing: Dict[str, List[TreeNode]] = {}   # the writers that may change a key (not an include passing it on)
    for k, ws in writers.items():
        kept = [w for w in ws if id(w) not in files or not _passes_on(files[id(w)][1], k)]
        if kept:
            changing[k] = kept
    writers = changing
    for k, default in tree.inputs.items():
        if k in writers:
            continue
        if k in values:
            out[k] = {here: [Source(values[k], "--set %s" % k, None)]}
        elif literals and k not in skip and default is not REQUIRED and not refs_in(default):
            out[k] = {here: [Source(default, "input %s's default" % k, _default_pos(defaults, here, k, tree))]}
    if not binders:
        return out
    files, sole = _included(binders, writers)
    chains: List[Tuple[str, str, Ref, TreeNode]] = []
    seen: Set[Tuple[Any, ...]] = set()
    for sub, args, b in files.values():
        file = sub.root.pos.file
        for k, default in sub.inputs.items():
            value = args.get(k, default)
            if sole.get(k) is not sub and not (k not in writers and _passes_on(args, k)):
                continue
            if k in args and isinstance(value, Ref):
                chains.append((k, file, value, b))
            elif literals and value is not REQUIRED and not refs_in(value):
                src = (Source(value, "include argument %s" % k, getattr(b.spec, "arg_pos", {}).get(k, b.pos))
                       if k in args else Source(value, "input %s's default" % k, _default_pos(defaults, file, k, sub)))
                if (k, file, src.at) not in seen:   # a default that several includes leave: once
                    seen.add((k, file, src.at))
                    out.setdefault(k, {}).setdefault(file, []).append(src)
    for _ in range(len(chains)):   # each round follows the values one include further
        more = False
        for k, file, ref, b in chains:
            held = out.setdefault(k, {}).setdefault(file, [])
            for s in list(out.get(ref.key, {}).get(b.pos.file, ())):
                try:
                    value = ref.resolve(lambda _key, s=s: s.value)
                except RefError:   # (the include cannot set it: its own failure)
                    continue
                via = "%s, passed on as argument %r of the include at %s" % (
                    s.via, k, where(b.pos, s.at) if s.at is not None else "%s:%d" % (b.pos.file, b.pos.line))
                if (k, file, s.said, s.at, via) not in seen and len(held) < _MOST_SOURCES:
                    seen.add((k, file, s.said, s.at, via))
                    held.append(Source(value, s.said, s.at, via))
                    more = True
        if not more:
            break
    return out


def _passes_on(args: Dict[str, Any], key: str) -> bool:
    """Whether an include's arguments pass the caller's ``key`` on as its own (``args: {x: $x}``)."""
    v = args.get(key)
    return isinstance(v, Ref) and v.key == key and not v.path


def _default_pos(defaults: Optional[Mapping[str, Any]], file: str, key: str, tree: TreeFile) -> Pos:
    """Where input ``key``'s default is written in ``file`` (the top of the file when not known)."""
    raw = defaults.get(file) if defaults else None
    if raw is None or key not in raw:
        return tree.root.pos
    return pos_of(raw[key], "default", raw.val_pos[key])


def _misfits(nodes: Sequence[TreeNode], sources: _Sources) -> List[Tuple[Source, str]]:
    """Each value of ``sources`` that a node's typed input reading it could never take (the kinds with such
    inputs have ``typed_inputs``: a call), with why."""
    out: List[Tuple[Source, str]] = []
    if not sources:
        return out
    done: Set[int] = set()
    for n in nodes:
        typed = getattr(n.nodekind, "typed_inputs", None)
        if typed is None or id(n) in done:   # (a subtree included twice: its nodes twice)
            continue
        done.add(id(n))
        for slot, param, value, at, places in typed(n):
            for loc, ref in _refs_placed(value, ()):
                for src in sources.get(ref.key, {}).get(at.file, ()):
                    found = _misfit(param, value, loc, ref, src.value)
                    if found is not None:
                        out.append((src, _misfit_text(src, ref, slot + _steps(loc), places.get(loc, at), *found)))
    return out


def _refs_placed(value: Any, loc: Tuple[Any, ...]) -> List[Tuple[Tuple[Any, ...], Ref]]:
    """The references of a value, each with its place in it (mapping keys and list indices); those inside
    ``$( … )`` expressions and templates are not (what they make is not known here)."""
    if isinstance(value, Ref):
        return [(loc, value)]
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in _refs_placed(v, loc + (k,))]
    if isinstance(value, list):
        return [p for i, v in enumerate(value) for p in _refs_placed(v, loc + (i,))]
    return []


def _steps(loc: Tuple[Any, ...]) -> str:
    return "".join("[%d]" % s if isinstance(s, int) else ".%s" % s for s in loc)


class _Unknown(Exception):
    """A place in a value whose ROS type is not known here: nothing to check there."""


def _misfit(param: Any, value: Any, loc: Tuple[Any, ...], ref: Ref, held: Any) -> Optional[Tuple[str, Any, str]]:
    """Why ``param`` (a definition's input: ``convert``, ``rostype``) could not take ``value`` with ``ref`` (at
    ``loc`` in it) reading a key that holds ``held``: (how it is said, the value read, the converter's words),
    or None when it could. The conversion is the call's own; the rest of the value is given the defaults of
    its places, and converts by itself first (else something else there is wrong: not this value's doing)."""
    try:
        got = ref.resolve(lambda _key: held)
    except RefError as exc:
        return "read", held, str(exc)
    if got is None:   # null: no value given, which the tree may look at before the call (check: 'x != null')
        return None
    sample = got
    try:
        if loc:
            sample, base = _filled(value, param.rostype, (), loc, got)
            param.convert(base)
    except (_Unknown, ProtocolError):
        return None
    try:
        param.convert(sample)
    except ProtocolError as exc:
        return _reason(param.rostype, loc, exc, got)
    return None


def _filled(value: Any, t: Optional[str], here: Tuple[Any, ...], target: Tuple[Any, ...],
            got: Any) -> Tuple[Any, Any]:
    """``value`` (of ROS type ``t``, at ``here``) with ``got`` at ``target`` and every other reference or
    expression replaced by the default of its place, and the same with the default at ``target`` too."""
    if here == target:
        return got, _default_of(t)
    if isinstance(value, (Ref, Computed)):
        d = _default_of(t)
        return d, d
    if target[:len(here)] != here and not refs_in(value):
        return value, value
    if t is None or not isinstance(value, (dict, list)):
        raise _Unknown
    sample: Any = {} if isinstance(value, dict) else []
    base: Any = {} if isinstance(value, dict) else []
    for step, v in (value.items() if isinstance(value, dict) else enumerate(value)):
        ft = _field_type(t, step)
        if ft is None and isinstance(step, int) and not here:   # a list for a one-field message's list
            ft = _field_type(_stands_for(t), step)
        s, b = _filled(v, ft, here + (step,), target, got)
        if isinstance(value, dict):
            sample[step], base[step] = s, b
        else:
            sample.append(s)
            base.append(b)
    return sample, base


def _default_of(t: Optional[str]) -> Any:
    """A value of ROS type ``t`` that converts (a message's: an empty mapping, all its defaults)."""
    if t is None:
        raise _Unknown
    if t.endswith("]"):
        size = t[t.rindex("[") + 1:-1]
        return [_default_of(t[:t.rindex("[")])] * int(size) if size else []
    if t in ("string", "bool"):
        return "" if t == "string" else False
    if t in _NUMBERS or t in ("time", "duration"):
        return 0
    if resolve_type(t) is None:
        raise _Unknown
    return {}


def _reason(rostype: str, loc: Tuple[Any, ...], exc: ProtocolError, got: Any) -> Tuple[str, Any, str]:
    """The converter's words for a value at ``loc`` in an input of ``rostype``, as said of that place:
    ("takes", the value, ``takes a number (float64)``) when the place itself takes no such value, else
    ("fit", the value, the rest: ``field x takes a number (float64), got 'a'``)."""
    said = exc.said if isinstance(exc, ValueMisfit) else str(exc)
    head = "(%s): " % rostype
    if isinstance(exc, ValueMisfit) and said.startswith(head):
        said = said[len(head):]
        field = "field " + _steps(loc).lstrip(".")
        rest = said[len(field):] if loc and said.startswith(field) else ""
        if rest.startswith(" "):
            said = rest[1:]   # the place itself
        elif rest.startswith("."):
            said = "field " + rest[1:]
    cut = said.find("), got ")
    if said.startswith("takes ") and cut >= 0:
        return "takes", got, said[:cut + 1]
    return "fit", got, said


_KIND_WORDS = ((bool, "a boolean"), (int, "a whole number"), (float, "a number"), (str, "text"), (list, "a list"),
               (dict, "a mapping"))


def _misfit_text(src: Source, ref: Ref, slot: str, at: Pos, form: str, got: Any, reason: str) -> str:
    """``input x's default 'abc' is text, but navigation.approach's target.x at t.yaml:6:24 takes a number
    (float64)``; ``--set x: …``; ``input p's default makes $p.x 'abc', which is text, …``."""
    colon = ":" if src.at is None or src.said.startswith("include") else ""
    via = src.via + "," if src.via else ""
    if form == "read":
        return "%s%s %s%s cannot be read as %s by %s at %s: %s" % (src.said, colon, brief(got), via, ref, slot,
                                                                   at, reason)
    head = ("%s%s makes %s %s, which" % (src.said, via, ref, brief(got)) if ref.path
            else "%s%s %s%s" % (src.said, colon, brief(got), via))
    if form != "takes":
        return "%s does not fit %s at %s: %s" % (head, slot, at, reason)
    kind = next((w for t, w in _KIND_WORDS if isinstance(got, t)), "null")
    hint = ""
    if reason.startswith("takes text") and isinstance(got, (bool, int, float)):
        hint = (" (for text, quote it: %s='\"%s\"')" % (src.said, text_of(got)) if src.at is None and not via
                and not ref.path else " (for text, write it in quotes)")
    return "%s is %s, but %s at %s %s%s" % (head, kind, slot, at, reason, hint)
