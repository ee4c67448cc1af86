"""Values written in a tree: YAML literals holding ``$references``, ``$( … )`` expressions and
``"… {key} …"`` templates, parsed once when the tree loads and worked out when the node runs.

    "$key.field"           the value of a reference (any type)
    "$( len(people) + 1 )" the value of an expression (coordinator.expr)
    "I found the {object} in the {room}"   text; each {…} is an expression; {{ and }} are braces
    "$$5"                  a leading $$ is a literal dollar
"""
from __future__ import annotations

import re
from typing import Any, Callable, Dict, List, Optional, Set, Tuple, Union

from coordinator.errors import Pos, TreeError
from coordinator.expr import Expr, ExprError, check_text_size, text_of
from coordinator.refs import Computed, Ref, RefError, parse_ref, refs_in

__all__ = ["ExprValue", "Template", "at_value_errors", "literal", "loose_dollars", "read_at", "ref_kind", "ref_type",
           "value_type_errors"]

_LOOSE = re.compile(r"(?<![$\w])\$([^\W\d]\w*)")


class ExprValue(Computed):
    """``$( expr )``: the expression's value when the node runs."""

    def __init__(self, expr: Expr):
        self.expr = expr
        self.refs = list(expr.refs)

    def resolve(self, lookup: Callable[[str], Any]) -> Any:
        return self.expr.value(lookup)

    def __repr__(self) -> str:
        return "$(%s)" % self.expr.text


class Template(Computed):
    """Text with ``{expr}`` holes, filled when the node runs."""

    def __init__(self, text: str, parts: List[Union[str, Tuple[Expr, int]]]):
        self.text = text
        self.parts = parts
        self.refs = [r for p in parts if not isinstance(p, str) for r in p[0].refs]

    def resolve(self, lookup: Callable[[str], Any]) -> str:
        return check_text_size("".join(p if isinstance(p, str) else text_of(p[0].value(lookup)) for p in self.parts))

    def exprs(self) -> List[Tuple[Expr, int]]:
        return [p for p in self.parts if not isinstance(p, str)]

    def __repr__(self) -> str:
        return repr(self.text)


def template(text: str, base: int = 0) -> Union[str, Template]:
    """``text`` with its ``{…}`` holes parsed; plain text (braces unescaped) if it has none."""
    if "{" not in text and "}" not in text:
        return text
    parts: List[Union[str, Tuple[Expr, int]]] = []
    buf: List[str] = []
    i = 0
    while i < len(text):
        c = text[i]
        if c in "{}" and text.startswith(c * 2, i):
            buf.append(c)
            i += 2
            continue
        if c == "}":
            raise RefError("a lone '}' in text (write '}}' for a brace)", base + i)
        if c != "{":
            buf.append(c)
            i += 1
            continue
        end = _closing(text, i + 1)
        if end < 0:
            raise RefError("'{' without its '}' in text (write '{{' for a brace)", base + i)
        inner = text[i + 1:end]
        if not inner.strip():
            raise RefError("an empty '{}' in text (write '{{}}' for braces)", base + i)
        try:
            expr = Expr.parse(inner)
        except ExprError as exc:
            raise RefError("in {%s}: %s" % (inner, exc), base + i + 1 + exc.offset)
        if buf:
            parts.append("".join(buf))
            buf = []
        parts.append((expr, base + i + 1))
        i = end + 1
    if buf:
        parts.append("".join(buf))
    if all(isinstance(p, str) for p in parts):
        return "".join(parts)  # type: ignore[arg-type]
    return Template(text, parts)


def _closing(text: str, i: int) -> int:
    """Where the ``}`` that ends a hole is (quotes inside the expression skipped), -1 if none."""
    quote = ""
    while i < len(text):
        c = text[i]
        if quote:
            if c == "\\":
                i += 1
            elif c == quote:
                quote = ""
        elif c in "\"'":
            quote = c
        elif c == "}":
            return i
        elif c == "{":
            return -1
        i += 1
    return -1


def _expr_value(text: str) -> ExprValue:
    body = text[2:-1]
    try:
        return ExprValue(Expr.parse(body))
    except ExprError as exc:
        raise RefError("bad expression in %r: %s" % (text, exc), 2 + exc.offset)


def _constant(value: Any, offset: int) -> Any:
    """A computed value that reads no key is worked out once, now (its errors are load errors)."""
    if isinstance(value, Computed) and not value.refs:
        try:
            return value.resolve(_no_keys)
        except RefError as exc:
            raise RefError(str(exc), offset)
    return value


def _no_keys(key: str) -> Any:
    raise KeyError(key)


def literal(value: Any) -> Any:
    """A YAML value with references, expressions and templates parsed (RefError if malformed)."""
    if isinstance(value, str):
        if value.startswith("$(") and value.endswith(")"):
            return _constant(_expr_value(value), 2)
        if value.startswith("$$"):
            return _constant(template(value[1:], 1), 0)
        if value.startswith("$"):
            return parse_ref(value)
        return _constant(template(value), 0)
    if isinstance(value, dict):
        return {k: literal(v) for k, v in value.items()}
    if isinstance(value, list):
        return [literal(v) for v in value]
    return value


def loose_dollars(value: Any) -> List[str]:
    """``$name`` written inside text (not a whole-value reference): sent as written, likely meant as ``{name}``."""
    if isinstance(value, str):
        rest = value[2:] if value.startswith("$$") else value
        if value.startswith("$") and not value.startswith("$$"):
            return []
        return _LOOSE.findall(rest)
    if isinstance(value, dict):
        return [n for v in value.values() for n in loose_dollars(v)]
    if isinstance(value, list):
        return [n for v in value for n in loose_dollars(v)]
    return []


# static kinds -------------------------------------------------------------------------------
_NUMBERS = {"int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float32", "float64",
            "byte", "char"}


def _kind_of_type(t: str) -> Optional[str]:
    from comm.rostypes import resolve_type

    if t.endswith("]"):
        return "list"
    if t in _NUMBERS:
        return "number"
    if t == "string":
        return "string"
    if t == "bool":
        return "bool"
    cls = resolve_type(t)
    if cls is None:
        return None
    if len(cls.__slots__) == 1:
        return _kind_of_type(cls._slot_types[0])
    return "message"


def _field_type(t: str, step: Any) -> Optional[str]:
    from comm.rostypes import resolve_type

    if isinstance(step, int):
        return t[:t.rindex("[")] if t.endswith("]") else None
    cls = resolve_type(t)
    if cls is None or step not in cls.__slots__:
        return None
    return cls._slot_types[list(cls.__slots__).index(step)]


def ref_type(types: Dict[str, Set[Optional[str]]], ref: Ref) -> Optional[str]:
    """The ROS type (or field type) a reference will hold, when the definitions say."""
    known = types.get(ref.key)
    if not known or len(known) != 1 or None in known:
        return None
    t: Optional[str] = next(iter(known))
    for step in ref.path:
        if t is None:
            return None
        inner = _field_type(t, step)
        if inner is None and not isinstance(step, int):
            from comm.rostypes import resolve_type

            cls = resolve_type(t)   # a one-field message stands for its value
            if cls is not None and len(cls.__slots__) == 1:
                inner = _field_type(cls._slot_types[0], step)
        t = inner
    return t


def ref_kind(types: Dict[str, Set[Optional[str]]], ref: Ref) -> Optional[str]:
    """What a reference will hold (number, string, bool, list, message), when the definitions say."""
    t = ref_type(types, ref)
    return _kind_of_type(t) if t is not None else None


# where a value reads a key ---------------------------------------------------------------------
def read_at(value: Any, at: Pos, key: str) -> Optional[Pos]:
    """Where ``value`` (written at ``at``; a reference, an expression, a template, or a literal holding
    them) reads ``key``: the reference's own column in one text, ``at`` for a mapping or a list; None
    if it does not read ``key``."""
    if isinstance(value, Ref):
        return at if value.key == key else None
    offset: Optional[int] = None
    if isinstance(value, Expr):
        offset = value.offset_of(key)
    elif isinstance(value, ExprValue):
        off = value.expr.offset_of(key)
        offset = None if off is None else 2 + off
    elif isinstance(value, Template):
        for expr, base in value.exprs():
            off = expr.offset_of(key)
            if off is not None:
                offset = base + off
                break
    elif any(r.key == key for r in refs_in(value)):
        return at
    return None if offset is None else Pos(at.file, at.line, at.column + offset)


def value_type_errors(value: Any, types: Dict[str, Set[Optional[str]]]) -> List[Tuple[int, str]]:
    """(offset in its text, message) for operands of the wrong kind in a value's expressions."""
    out: List[Tuple[int, str]] = []

    def kind(r: Ref) -> Optional[str]:
        return ref_kind(types, r)

    if isinstance(value, ExprValue):
        out += [(2 + off, msg) for off, msg in value.expr.type_errors(kind)]
    elif isinstance(value, Template):
        for expr, base in value.exprs():
            out += [(base + off, msg) for off, msg in expr.type_errors(kind)]
    elif isinstance(value, dict):
        for v in value.values():
            out += value_type_errors(v, types)
    elif isinstance(value, list):
        for v in value:
            out += value_type_errors(v, types)
    return out


def at_value_errors(value: Any, at: Pos, types: Dict[str, Set[Optional[str]]], errors: List[TreeError]) -> None:
    """:func:`value_type_errors` of a value written at ``at``, as tree errors."""
    for off, msg in value_type_errors(value, types):
        errors.append(TreeError(Pos(at.file, at.line, at.column + off), msg))
