"""What the tree parser says to fix a mistake: where a mis-indented option belongs, how to quote text
YAML read as a mapping or a list, the closest name, how to split a node with two kinds."""
from __future__ import annotations

import json
import os
import re
from typing import Any, Dict, List, Mapping, Tuple

import yaml

from comm.errors import did_you_mean
from coordinator.nodes import REGISTRY
from coordinator.othernames import foreign_option, option_hint, takes
from coordinator.yamlsrc import LMap

__all__ = ["LEAF_OPTIONS", "XML_HINT", "closest", "foreign_hint", "foreign_option", "include_hint", "key_fix", "looks_like_xml",
           "misplaced", "nearby", "nest_hint", "quoted_mapping", "quoted_mapping_message", "unquoted"]

_KINDS = frozenset(REGISTRY)
_OPTION_NAMES = {k: frozenset(o.name for o in nk.options) for k, nk in REGISTRY.items()}
# the options of leaves, by option: a decorator or composite given one likely holds a leaf's option mis-indented
_LEAF_KINDS = tuple(k for k, nk in REGISTRY.items() if nk.family == "leaf")
LEAF_OPTIONS: Dict[str, Tuple[str, ...]] = {o: tuple(k for k in _LEAF_KINDS if o in _OPTION_NAMES[k])
                                            for o in set().union(*(_OPTION_NAMES[k] for k in _LEAF_KINDS))}


def nearby(raw: LMap, kind: str) -> List[Tuple[str, LMap]]:
    """The nodes written inside a decorator or composite (its child, its value, its children, its cases),
    with their kinds: where an option it does not take most likely belongs."""
    found: List[Tuple[str, LMap]] = []
    for value in (raw.get(kind), raw.get("child"), raw.get("default"), raw.get("cases")):
        if isinstance(value, list):
            items = value
        elif isinstance(value, LMap) and not any(k in _KINDS for k in value):   # switch's cases: label -> node
            items = list(value.values())
        else:
            items = [value]
        for item in items:
            if isinstance(item, LMap):
                kinds = [k for k in item if k in _KINDS]
                if kinds:
                    found.append((kinds[0], item))
    return found


def _either(names: Tuple[str, ...]) -> str:
    """``call, wait_event or include``."""
    return names[0] if len(names) == 1 else "%s or %s" % (", ".join(names[:-1]), names[-1])


def misplaced(option: str, kind: str, allowed: Tuple[str, ...], nearby: List[Tuple[str, LMap]]) -> str:
    """The hint for a leaf's option given to a decorator or composite: what it takes, and which node inside
    it the option belongs to (indented one level too little)."""
    for leaf, node in nearby:
        if option in _OPTION_NAMES[leaf]:
            return "%s: %r is an option of the %s at line %d: indent it under that %s" % (
                takes(kind, allowed), option, leaf, node.pos.line, leaf)
    return "%s: %r is an option of %s: indent it under the node it is for" % (
        takes(kind, allowed), option, _either(LEAF_OPTIONS[option]))


_HOLE = re.compile(r"\$?([^\W\d][\w.\[\]]*)$")


def unquoted(raw: Any, key: Any, value: Any) -> str:
    """The hint for text that YAML read as a flow mapping or list because it was not quoted: ``text: {object}``
    is the mapping {object: null}, ``text: [object]`` a list ('' for anything else)."""
    if isinstance(value, LMap):
        name = next(iter(value)) if len(value) == 1 else None
        m = _HOLE.match(name) if isinstance(name, str) and value[name] is None else None
        if m is None:
            return ""
        hint = ": YAML reads an unquoted {%s} as a mapping; quote it: %s: \"{%s}\"%s" % (
            name, key, m.group(1), " (or $%s)" % m.group(1) if m.group(1).isidentifier() else "")
    elif value and all(isinstance(v, str) for v in value):
        shown = "[%s]" % ", ".join(value)
        hint = ": YAML reads an unquoted %s as a list; quote it: %s: \"%s\"" % (shown, key, shown)
    else:
        return ""
    if not isinstance(raw, LMap) or not isinstance(key, str) or value.pos.line != raw.key_pos[key].line:
        return ""   # a block mapping or list starts below its key: written so on purpose
    return hint


def closest(word: Any, choices: Mapping[str, Any], what: str) -> str:
    """`` (did you mean 'position'?)`` also for a shortened name (``pos``, which difflib finds too far), else
    the names there are: an unknown name is never left without what would do."""
    hint = did_you_mean(word, choices)
    if hint:
        return hint
    text = str(word).lower()
    starting = [c for c in choices if len(text) >= 2 and c.lower().startswith(text)]
    if len(starting) == 1:
        return " (did you mean %r?)" % starting[0]
    return " (%ss: %s)" % (what, ", ".join(choices) or "none")


def nest_hint(raw: LMap, first: str, second: str) -> str:
    """How to split a node with two kinds: a leaf beside a decorator goes under its ``child:`` (or its value)."""
    outer, inner = (second, first) if REGISTRY[first].family != "decorator" else (first, second)
    if REGISTRY[outer].family != "decorator":
        return "split it or nest it"
    where = "'child:'" if "child" in _OPTION_NAMES[outer] else "'%s:'" % outer
    moved = [k for k in raw if k != inner and k in _OPTION_NAMES[inner] and k not in _OPTION_NAMES[outer]]
    return "nest the %s%s under %s" % (inner, " and its %s" % ", ".join(moved) if moved else "", where)


XML_HINT = ("this looks like BehaviorTree.CPP XML (<root BTCPP_format=…>); bmtree trees are YAML: 'bmtree import "
            "FILE.xml -o FILE.yaml' converts it, and trees/README.md's 'Nodes' section names what each BehaviorTree.CPP "
            "node is in bmtree")


def looks_like_xml(text: str) -> bool:
    """Whether a tree file's text is XML (a BehaviorTree.CPP or Groot file), not YAML: it starts with ``<``."""
    return text.lstrip("\ufeff \t\r\n").startswith("<")


def foreign_hint(option: Any, kind: str, allowed: Tuple[str, ...], raw: Any, definitions: Mapping[str, Any]) -> str:
    """The hint for an option that is another tool's (``_successIf``, ``success_count``), or an input of the
    function a ``call`` calls written beside it instead of under ``inputs:`` (a param of ``wait_event``'s
    event, beside it instead of under ``outputs:``); '' for any other."""
    if foreign_option(option):
        return option_hint(option, kind, allowed)
    target = raw.get(kind) if kind in ("call", "wait_event") else None
    if not isinstance(target, str) or target.count(".") != 1:
        return ""
    mod_name, member = target.split(".")
    mod = definitions.get(mod_name)
    if mod is None:
        return ""
    if kind == "call":
        fn = mod.functions.get(member)
        if fn is not None and any(q.name == option for q in fn.inputs):
            return ": %r is an input of %s: move it under inputs: (inputs: {%s: …})" % (option, target, option)
        return ""
    ev = mod.events.get(member)
    if ev is not None and any(q.name == option for q in ev.params):
        return ": %r is a param of %s: take it with outputs: {%s: KEY}" % (option, target, option)
    return ""


def key_fix(value: Any) -> Tuple[str, Any]:
    """For a tree key of ``outputs`` that is not an identifier: the hint and the key meant (``"{obj_pos}"``,
    ``"$obj_pos"``, an unquoted ``{obj_pos}``: ``obj_pos``, a plain name as BehaviorTree.CPP's ports write it
    with braces), or ('', None)."""
    name = None
    if isinstance(value, str):
        m = re.match(r"^\s*(?:\$|\{\s*)([^\W\d]\w*)\s*\}?\s*$", value)
        if m and (value.strip().startswith("$") != value.strip().endswith("}")):
            name = m.group(1)
    elif isinstance(value, dict) and len(value) == 1:
        only = next(iter(value))
        if isinstance(only, str) and only.isidentifier() and value[only] is None:
            name = only
    if name is None:
        return "", None
    return ": an output is written to a tree key by its plain name: write %s" % name, name


def quoted_mapping(text: Any) -> str:
    """A YAML flow mapping written in quotes, so text: ``{x: 1, y: 2}`` for ``"{x: 1, y: 2}"`` (a ``{…}``
    template whose hole is no expression); '' for anything else (``"{pos}"`` is a template)."""
    if not isinstance(text, str):
        return ""
    shown = text.strip()
    if not (shown.startswith("{") and shown.endswith("}")) or shown.startswith("{{") or ":" not in shown:
        return ""
    from coordinator.expr import Expr, ExprError

    try:
        if Expr.parse(shown[1:-1]) is not None:
            return ""
    except ExprError:
        pass
    try:
        value = yaml.safe_load(shown)
    except yaml.YAMLError:
        return ""
    if not isinstance(value, dict) or not value or any(":" in str(k) for k in value):
        return ""   # ({pct:.1f}: YAML's key 'pct:.1f', Python's format; a mapping is written {k: v})
    return shown


def quoted_mapping_message(text: str, key: Any = None) -> str:
    """Why a mapping in quotes is not taken as one, and what to write (``key: {x: 1, y: 2}``)."""
    shown = quoted_mapping(text)
    return ("%s is text in quotes (a {…} template), not a mapping: write the mapping without quotes: %s%s"
            % (json.dumps(text, ensure_ascii=False), "" if key is None else "%s: " % key, shown))


def include_hint(path: str, stack: Tuple[str, ...]) -> str:
    """For an include that is not there but would be from the working folder: that its path is relative to
    the including file's folder, and what to write (``include: trees/ask.yaml`` in trees/main.yaml)."""
    if not stack or os.path.exists(path):
        return ""
    here = os.path.dirname(os.path.abspath(stack[-1]))
    written = os.path.relpath(path, here)
    if written.startswith("..") or not os.path.isfile(written):
        return ""
    return " (an include's path is relative to the folder of the file that includes it, %s: write %s)" % (
        os.path.relpath(here) + os.sep, os.path.relpath(os.path.abspath(written), here))
