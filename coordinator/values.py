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

from comm.errors import did_you_mean
from coordinator.errors import Pos, TreeError
from coordinator.expr import Expr, ExprError, check_text_size, text_of
from coordinator.exprtypes import never_true
from coordinator.keykinds import KIND_WORDS, agreed_kind, kind_of_type
from coordinator.keykinds import NUMBERS as _NUMBERS  # (coordinator.inputvalues reads them here)
from coordinator.keykinds import field_type as _field_type
from coordinator.keykinds import stands_for as _stands_for
from coordinator.refs import Computed, Ref, RefError, parse_ref, refs_in

__all__ = ["Binding", "ExprValue", "KeyTypes", "Template", "at_value_errors", "expr_errors", "follow", "held", "literal", "loose_dollars",
           "read_at", "ref_errors", "ref_kind", "ref_type", "template_fix", "template_hint", "templates_as_text", "value_kind",
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
            from coordinator.parsehints import quoted_mapping, quoted_mapping_message

            if quoted_mapping(text):   # "{x: 1, y: 2}": a mapping in quotes
                raise RefError(quoted_mapping_message(text), base)
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


_PLAIN_REF = re.compile(r"[^\W\d]\w*(\.[^\W\d]\w*|\[-?\d+\])*$")


def template_hint(value: Any) -> str:
    """Why a ``{…}`` template cannot be where a value other than text goes, and what to write: ``a {…}
    template makes text; write $obj_pos`` (``$( … )`` for a hole that is an expression); '' when
    ``value`` holds no template."""
    found = _templates(value)
    if not found:
        return ""
    fix = template_fix(found[0])
    if fix:
        return "a {…} template makes text; write %s" % fix
    return "a {…} template makes text, which this value cannot be: write a $reference or a $( … ) expression"


def template_fix(t: Template) -> str:
    """What a template of one hole is meant as: ``$obj_pos`` for ``"{obj_pos}"``, ``$(len(x))`` for
    ``"{len(x)}"``; '' for text around holes."""
    if len(t.parts) == 1 and not isinstance(t.parts[0], str):
        inner = t.parts[0][0].text.strip()
        return "$" + inner if _PLAIN_REF.match(inner) else "$(%s)" % inner
    return ""


def _templates(value: Any) -> List[Template]:
    if isinstance(value, Template):
        return [value]
    if isinstance(value, dict):
        return [t for v in value.values() for t in _templates(v)]
    if isinstance(value, list):
        return [t for v in value for t in _templates(v)]
    return []


def templates_as_text(value: Any) -> Any:
    """``value`` with each ``{…}`` template replaced by its text as written (what a check converts to say
    that text is not taken: a template always makes text)."""
    if isinstance(value, Template):
        return value.text
    if isinstance(value, dict):
        return {k: templates_as_text(v) for k, v in value.items()}
    if isinstance(value, list):
        return [templates_as_text(v) for v in value]
    return value


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


Binding = Tuple[Any, str, Optional[Pos]]
"""A literal a tree input is given: the value, the include argument's name ('' for the input's default),
and where the include that gives it is (None: the default of the tree checked)."""


class KeyTypes(dict):  # type: ignore[type-arg]
    """For each tree key, the ROS types written to it (None: not known statically); ``kinds``: for a key
    some writers of which give no ROS type, what each of those gives (a ``set``: the kind of its value; see
    :mod:`coordinator.keykinds`); and ``bound``: for a key that only its files' inputs give (no node but an
    include of that file writes it), the literals it starts with in each file, by the path of the file
    (``coordinator.dataflow.key_types``)."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.kinds: Dict[str, Set[Optional[str]]] = {}
        self.bound: Dict[str, Dict[str, List[Binding]]] = {}
        # why_not(key, text, contains): why $key can never be (contain) that text, '' when it may or is not
        # known (a call's status: coordinator.dataflow.key_types), for the comparisons of expressions
        self.why_not: Optional[Callable[[str, str, bool], str]] = None


def held(t: str) -> str:
    """What a value of ROS type ``t`` is, in an error: ``a geometry_msgs/Pose``, ``text (std_msgs/String)``,
    ``a number (float64)``, ``a list (string[])``."""
    from comm.rostypes import resolve_type
    from comm.typewords import type_words

    cls = None if t.endswith("]") else resolve_type(t)
    if cls is not None and len(cls.__slots__) != 1:
        return "a %s" % t
    return "%s (%s)" % (type_words(t), t)


def _shown(ref: Ref, steps: int) -> str:
    """The reference as an expression writes it (no ``$``), up to ``steps`` steps of its path."""
    return str(Ref(ref.key, ref.path[:steps]))[1:]


def follow(types: Dict[str, Set[Optional[str]]], ref: Ref) -> Tuple[Optional[str], str]:
    """The ROS type a reference will hold (None: not known), and why its path cannot be followed in the
    type its key holds ('' when it can, or when that is not known).

    Only what surely fails when running is said: a field that the message type does not have, a field of
    text, a number or a list, an index into a message that is not a list (also of a key only ``set`` writes,
    whose values are of one kind); a key whose writers do not all give one known type, or a type not known
    here (``time``, a message not installed), is left alone.
    """
    known = types.get(ref.key)
    if not known or len(known) != 1 or None in known:
        if ref.path and known == {None}:
            kind, plain = agreed_kind(types, ref.key)
            if plain and kind is not None:
                return None, _plain_path(kind, ref)
        return None, ""
    t: str = next(iter(known))
    if not ref.path:
        return t, ""
    cache_key = (t, ref)
    done = _FOLLOWED.get(cache_key)
    if done is None:
        if len(_FOLLOWED) > 4096:
            _FOLLOWED.clear()
        done = _FOLLOWED[cache_key] = _follow(t, ref)
    return done


_FOLLOWED: Dict[Tuple[str, Ref], Tuple[Optional[str], str]] = {}   # trees repeat their references


def _follow(t: str, ref: Ref) -> Tuple[Optional[str], str]:
    for i, step in enumerate(ref.path):
        if isinstance(step, int):
            inner = _stands_for(t)
            if inner.endswith("]"):
                t = inner[:inner.rindex("[")]
                continue
            if inner in _NUMBERS or inner == "bool" or _message(inner):
                return None, _not_a_list(ref, i, held(t))
            return None, ""   # text (indexed by character), time, a type not known here
        cls = _message(t)
        if cls is not None:
            slots = list(cls.__slots__)
            if step in slots:
                t = cls._slot_types[slots.index(step)]
                continue
            inner_t = _field_type(cls._slot_types[0], step) if len(slots) == 1 else None
            if inner_t is not None:   # a one-field message stands for its value
                t = inner_t
                continue
            hint = did_you_mean(step, slots) or (" (its fields: %s)" % ", ".join(slots) if slots else
                                                 " (it has no fields)")
            return None, "reads %s, but %s holds %s, which has no field %r%s" % (
                _shown(ref, i + 1), _shown(ref, i), held(t), step, hint)
        if t.endswith("]") or t in _NUMBERS or t in ("string", "bool"):
            return None, _no_fields(ref, i, held(t), t.endswith("]"))
        return None, ""   # time, duration, a type not known here
    return t, ""


def _plain_path(kind: str, ref: Ref) -> str:
    """Why the first step of ``ref``'s path cannot be followed in a plain value of ``kind`` ('' when it can,
    or what it reaches is not known: a character of text, an element of a list)."""
    said = KIND_WORDS.get(kind, "")
    if isinstance(ref.path[0], int):
        return _not_a_list(ref, 0, said) if kind in ("number", "bool") else ""
    return _no_fields(ref, 0, said, kind == "list") if kind in ("number", "bool", "string", "list") else ""


def _not_a_list(ref: Ref, i: int, said: str) -> str:
    return "reads %s, but %s holds %s, which is not a list" % (_shown(ref, i + 1), _shown(ref, i), said)


def _no_fields(ref: Ref, i: int, said: str, a_list: bool) -> str:
    return "reads %s, but %s holds %s, which has no fields%s" % (
        _shown(ref, i + 1), _shown(ref, i), said, " (an element is %s[0])" % _shown(ref, i) if a_list else "")


def _message(t: str) -> Any:
    """The message class of ``t`` (None for field types, lists and types not known here)."""
    from comm.rostypes import resolve_type

    return None if t.endswith("]") else resolve_type(t)


def ref_type(types: Dict[str, Set[Optional[str]]], ref: Ref) -> Optional[str]:
    """The ROS type (or field type) a reference will hold, when the definitions say."""
    return follow(types, ref)[0]


def ref_kind(types: Dict[str, Set[Optional[str]]], ref: Ref) -> Optional[str]:
    """What a reference will hold (number, string, bool, list, message), when the definitions or the values
    ``set`` writes say: the kind of its ROS type, or, for a key whose writers give several types or none, the
    kind they all agree on (:func:`coordinator.keykinds.agreed_kind`)."""
    t = ref_type(types, ref)
    if t is not None:
        return kind_of_type(t)
    return None if ref.path else agreed_kind(types, ref.key)[0]


def value_kind(types: Dict[str, Set[Optional[str]]], value: Any) -> Tuple[Optional[str], str]:
    """What a parameter's value (a reference or an expression) will hold, when the definitions say:
    its kind (number, string, bool, list, message, null) and how to say it (``$answer holds text
    (std_msgs/String)``, ``$(a + "s") is text``, ``$n holds a number`` after ``set: {n: 0}``); (None, '')
    when not known."""
    if isinstance(value, Ref):
        t = ref_type(types, value)
        if t is not None:
            return kind_of_type(t), "%s holds %s" % (value, held(t))
        k = ref_kind(types, value)
        return (k, "%s holds %s" % (value, KIND_WORDS.get(k, "a " + k))) if k is not None else (None, "")
    if isinstance(value, ExprValue):
        k = value.expr.kind(lambda r: ref_kind(types, r))
        return (k, "%s is %s" % (value, KIND_WORDS.get(k, "a " + k))) if k is not None else (None, "")
    if isinstance(value, Template):
        return "string", "%r is text" % value.text
    return None, ""


def ref_errors(refs: List[Ref], offsets: List[int], types: Dict[str, Set[Optional[str]]]) -> List[Tuple[int, str]]:
    """(offset, message) for each reference whose path cannot be followed in the type its key holds."""
    out: List[Tuple[int, str]] = []
    for r, off in zip(refs, offsets):
        if r.path:
            why = follow(types, r)[1]
            if why:
                out.append((off, why))
    return out


def expr_errors(expr: Expr, types: Dict[str, Set[Optional[str]]]) -> List[Tuple[int, str]]:
    """(offset, message) for an expression's references into fields that its keys' types do not have, and
    for its operands of the wrong kind."""
    if not expr.refs:
        return expr.type_errors(lambda r: ref_kind(types, r))
    return ref_errors(expr.refs, expr.ref_offsets, types) + expr.type_errors(lambda r: ref_kind(types, r)) \
        + _never_true(expr, types)


def _never_true(expr: Expr, types: Dict[str, Set[Optional[str]]]) -> List[Tuple[int, str]]:
    """(offset, message) for each comparison of a key with text that the key's values never pass."""
    why_not = getattr(types, "why_not", None)
    if why_not is None or not expr.refs:
        return []
    found: List[Tuple[int, str]] = []
    never_true(expr.tree, why_not, found)
    return found


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


def value_type_errors(value: Any, types: Dict[str, Set[Optional[str]]], nested: bool = False) -> List[Tuple[int, str]]:
    """(offset in its text, message) for references into fields that the types of their keys do not have,
    and for operands of the wrong kind in a value's expressions (a reference inside a mapping or a list:
    offset 0, the mapping's own position)."""
    out: List[Tuple[int, str]] = []
    if isinstance(value, Ref):
        if value.path:
            why = follow(types, value)[1]
            if why:
                out.append((0, why))
    elif isinstance(value, ExprValue):
        out += [(0 if nested else 2 + off, msg) for off, msg in ref_errors(value.expr.refs, value.expr.ref_offsets,
                                                                           types)]
        out += [(2 + off, msg) for off, msg in value.expr.type_errors(lambda r: ref_kind(types, r))
                + _never_true(value.expr, types)]
    elif isinstance(value, Template):
        for expr, base in value.exprs():
            out += [(0 if nested else base + off, msg) for off, msg in ref_errors(expr.refs, expr.ref_offsets, types)]
            out += [(base + off, msg) for off, msg in expr.type_errors(lambda r: ref_kind(types, r))
                    + _never_true(expr, types)]
    elif isinstance(value, dict):
        for v in value.values():
            out += value_type_errors(v, types, True)
    elif isinstance(value, list):
        for v in value:
            out += value_type_errors(v, types, True)
    return out


def at_value_errors(value: Any, at: Pos, types: Dict[str, Set[Optional[str]]], errors: List[TreeError]) -> None:
    """:func:`value_type_errors` of a value written at ``at``, as tree errors."""
    for off, msg in value_type_errors(value, types):
        errors.append(TreeError(Pos(at.file, at.line, at.column + off), msg))
