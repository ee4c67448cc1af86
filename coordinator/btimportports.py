"""``bmtree import``: which module function a BehaviorTree.CPP action is, and what its ports become.

An action's ID is matched against the definitions' functions (``GoTo``, ``go_to``, ``Navigation.GoTo``),
since a robot's BehaviorTree.CPP actions are mostly its modules' functions under another spelling; a
literal port is typed by the definition, as BehaviorTree.CPP's ``convertFromString`` types it from the
port's C++ type.
"""
from __future__ import annotations

import math
import re
from typing import Any, Dict, List, Mapping, Optional, Tuple, Union

from coordinator.errors import Pos
from modules.definition import FunctionDefinition, ModuleDefinition, Param

__all__ = ["Lit", "Out", "Scope", "OutOfRange", "MAX_DIGITS", "find_function", "typed_literal", "plain_literal",
           "key_ref", "escape_text", "is_text", "whole_number", "bool_literal"]

_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")
_INTS = ("int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64", "byte", "char")
_FLOATS = ("float32", "float64", "time", "duration")
_TRUE, _FALSE = ("true", "True", "TRUE", "1"), ("false", "False", "FALSE", "0")
_REF = re.compile(r"^\{([^{}]*)\}$")
MAX_DIGITS = 308
"""The most digits of a number literal: bmtree's own bound on a whole number (trees/README.md), and about
float's range; Python 3.11 refuses to read a whole number of more than 4,300 digits at all."""


class OutOfRange(ValueError):
    """A number literal bmtree cannot hold: infinite as a float (``1e400``) or of more than MAX_DIGITS digits;
    its text says so after the literal (``1e400: out of range …``)."""

    def __init__(self, text: str):
        t = text.strip()
        shown = t if len(t) <= 24 else "%s… (%d characters)" % (t[:20], len(t))
        super().__init__("%s: out of range (a number has at most %d digits)" % (shown, MAX_DIGITS))


class Out:
    """A converted node: its YAML keys in order (the kind first), and the element it came from, so that a
    problem the tree's check finds later is said at the XML's line."""

    __slots__ = ("pos", "items")

    def __init__(self, pos: Pos, *items: Tuple[str, Any]):
        self.pos = pos
        self.items = list(items)

    def named(self, name: Optional[str], replace: bool = False) -> Out:
        """The node with ``name`` (a name it has already kept, unless ``replace``)."""
        if name:
            mine = [i for i, (k, _v) in enumerate(self.items) if k == "name"]
            if not mine:
                self.items.insert(1, ("name", name))
            elif replace:
                self.items[mine[0]] = ("name", name)
        return self


class Lit:
    """A literal a SubTree gives one of its ports (``goal="kitchen"``), with where it is written."""

    def __init__(self, text: str, where: str):
        self.text = text
        self.where = where


class Scope:
    """How the blackboard keys of one (sub)tree are named in the converted tree: BehaviorTree.CPP gives a
    subtree its own blackboard, so a key it does not remap is its own (prefixed here), unless
    ``_autoremap`` shares the caller's."""

    def __init__(self, parent: Optional[Scope] = None, remap: Optional[Dict[str, Tuple[Union[str, Lit], bool]]] = None,
                 auto: bool = False, prefix: str = ""):
        self.parent = parent
        self.remap = remap or {}
        self.auto = auto
        self.prefix = prefix

    def resolve(self, key: str) -> Tuple[Union[str, Lit], bool]:
        """The key (or literal) ``key`` stands for, and whether it is a key of the main tree's own."""
        scope = self
        if key.startswith("@"):   # v4: the root blackboard
            key = key[1:]
            while scope.parent is not None:
                scope = scope.parent
        while True:
            if key in scope.remap:   # the caller's key (and whether it is the main tree's), or a literal
                return scope.remap[key]
            if scope.parent is None:
                return key, True
            if not scope.auto:
                return scope.prefix + key, False
            scope = scope.parent


def key_ref(value: str) -> Optional[str]:
    """``{key}`` → ``key`` (``{=}``: the port's own name, said by the caller), else None: a literal."""
    m = _REF.match(value.strip())
    return m.group(1).strip() if m else None


def _norm(name: str) -> str:
    return re.sub(r"[_.\-]", "", name).lower()


def find_function(node_id: str, definitions: Mapping[str, ModuleDefinition],
                  maps: Mapping[str, str]) -> Tuple[Optional[FunctionDefinition], str]:
    """The function an action ID stands for, or None and why (the fix in it)."""
    if node_id in maps:
        target = maps[node_id]
        mod_name, _, fn = target.partition(".")
        mod = definitions.get(mod_name)
        if mod is not None and fn in mod.functions:
            return mod.functions[fn], ""
        return None, "--map %s=%s names no function of the definitions (%s%s)" % (
            node_id, target, "module %r has: %s" % (mod_name, ", ".join(mod.functions)) if mod is not None else
            "no module %r; modules: %s" % (mod_name, ", ".join(sorted(definitions))),
            "" if mod is not None else "; give its definition with --modules")
    fns = [f for m in definitions.values() for f in m.functions.values()]
    exact = [f for f in fns if node_id in (f.name, f.qualified)]
    loose = exact or [f for f in fns if _norm(node_id) in (_norm(f.name), _norm(f.module + f.name))]
    if len(loose) == 1:
        return loose[0], ""
    if loose:
        return None, "matches several module functions (%s): give --map %s=module.function" % (
            ", ".join(f.qualified for f in loose), node_id)
    return None, "matches no module function: give --map %s=module.function (functions of the definitions: %s)" % (
        node_id, ", ".join(f.qualified for f in fns) or "none")


def _fields(param: Param) -> Optional[List[Tuple[str, str]]]:
    try:
        cls = param.msg_class
    except (AssertionError, ImportError, ValueError):
        return None
    return list(zip(cls.__slots__, cls._slot_types))


def escape_text(text: str) -> str:
    """Literal text as a bmtree value: its ``{`` ``}`` are no template, a leading ``$`` no reference."""
    text = text.replace("{", "{{").replace("}", "}}")
    return "$" + text if text.startswith("$") else text


def _number(text: str, whole: bool) -> Any:
    """The number ``text`` is (None: it is none; whole: an integer or None); OutOfRange past bmtree's bound."""
    t = text.strip()
    if not _NUMBER.match(t):
        return None
    if sum(c.isdigit() for c in re.split("[eE]", t)[0]) > MAX_DIGITS:
        raise OutOfRange(t)
    if whole:
        return int(t) if re.match(r"^[+-]?\d+$", t) else None
    value = float(t) if any(c in t for c in ".eE") else int(t)
    if not math.isfinite(value):
        raise OutOfRange(t)
    return value


def whole_number(text: str) -> Optional[int]:
    """A whole number written ``text`` (a count, maybe negative), None for any other text; OutOfRange."""
    value = _number(text, True)
    return value if isinstance(value, int) else None


def bool_literal(text: str) -> Optional[bool]:
    """True or false as BehaviorTree.CPP's convertFromString<bool> reads them ("1", "TRUE", …), else None."""
    t = text.strip()
    return True if t in _TRUE else False if t in _FALSE else None


def is_text(param: Param) -> bool:
    """Whether BehaviorTree.CPP would give the port the string itself (a std_msgs/String input)."""
    fields = _fields(param)
    return fields is not None and len(fields) == 1 and fields[0][1] == "string"


def typed_literal(text: str, param: Param) -> Tuple[Any, str]:
    """The YAML value of a literal port for ``param`` (typed as BehaviorTree.CPP's convertFromString would),
    or None and what it should be; OutOfRange for a number bmtree cannot hold."""
    fields = _fields(param)
    if fields is None:
        return plain_literal(text), ""
    if len(fields) == 1:
        ftype = fields[0][1]
        if ftype == "string":
            return escape_text(text), ""
        if ftype == "bool":
            if text.strip() in _TRUE + _FALSE:
                return text.strip() in _TRUE, ""
            return None, "true or false"
        if ftype in _INTS or ftype in _FLOATS:
            value = _number(text, ftype in _INTS)
            return (value, "") if value is not None else (None, "a %s (%s)" % (
                "whole number" if ftype in _INTS else "number", param.rostype))
        return plain_literal(text), ""
    parts = text.split(";")
    numeric = all(t in _INTS or t in _FLOATS for _n, t in fields)
    if numeric and len(parts) == len(fields):
        values = [_number(p, t in _INTS) for p, (_n, t) in zip(parts, fields)]
        if all(v is not None for v in values):
            return {n: v for (n, _t), v in zip(fields, values)}, ""
    names = ";".join(n for n, _t in fields)
    return None, "a %s: a {key} that holds one%s" % (param.rostype, ", or %s numbers" % names if numeric else "")


def plain_literal(text: str) -> Any:
    """A literal with no type to follow: a number, true or false, else text; OutOfRange."""
    t = text.strip()
    if t in ("true", "false"):
        return t == "true"
    value = _number(t, False)
    return value if value is not None else escape_text(text)
