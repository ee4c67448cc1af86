"""``$references`` to tree-blackboard keys: one grammar, one parser, one resolver.

    ref := '$' key ('.' field | '[' index ']')*

Call inputs, ``set`` values and include arguments hold references inside YAML literals
(``target: {x: $pos.x, y: 0.0}``, see ``coordinator.values``); expressions hold them without the ``$``.
Both are parsed by :func:`scan_ref` when the tree is loaded and resolved by
:meth:`Ref.resolve` when the node runs.
"""
from __future__ import annotations

import abc
import re
from dataclasses import dataclass
from typing import Any, Callable, List, Tuple

import genpy

from comm.errors import InvalidInput, did_you_mean

__all__ = ["Computed", "Ref", "RefError", "field_of", "kind_of", "parse_ref", "refs_in", "resolve", "scan_ref", "unwrap",
           "check_size", "MAX_SIZE", "MAX_NESTING"]

_NAME = re.compile(r"[^\W\d]\w*")
_INDEX = re.compile(r"-?\d+")
_SPACE = re.compile(r"\s*")


class RefError(InvalidInput, ValueError):
    """A malformed reference, or one that cannot be followed; ``offset`` is where, in its text."""

    def __init__(self, message: str, offset: int = 0):
        super().__init__(message)
        self.offset = offset


def unwrap(value: Any) -> Any:
    """The plain value of a one-field message; other values unchanged."""
    while isinstance(value, genpy.Message):
        slots = value.__slots__
        if len(slots) != 1:
            break
        value = getattr(value, slots[0])
    return value


def field_of(value: Any, step: Any, root: str) -> Any:
    """``value.step`` or ``value[step]`` for a message, a mapping or a list; RefError names ``root`` (what
    ``value`` is the value of) and, for a field it does not have, the closest one it has."""
    try:
        if isinstance(step, int):
            return unwrap(value)[step]
        if isinstance(value, dict):
            return value[step]
        if isinstance(value, genpy.Message) and step in value.__slots__:
            return getattr(value, step)
    except (IndexError, KeyError, TypeError):
        pass
    if isinstance(step, int):
        inner = unwrap(value)
        if isinstance(inner, (list, tuple, str, bytes)):
            what = "character" if isinstance(inner, str) else "element"
            raise RefError("%s has no index %d (it has %d %s%s)" % (root, step, len(inner), what,
                                                                    "" if len(inner) == 1 else "s"))
        raise RefError("%s has no index %d: it holds %s, not a list" % (root, step, _held(value)))
    if isinstance(value, genpy.Message):
        names = list(value.__slots__)
    elif isinstance(value, dict):
        names = [k for k in value if isinstance(k, str)]
    else:
        raise RefError("%s has no field %r: it holds %s, which has no fields" % (root, step, _held(value)))
    hint = did_you_mean(step, names) or (" (its fields: %s)" % ", ".join(names) if 0 < len(names) <= 12 else "")
    raise RefError("%s has no field %r%s" % (root, step, hint))


def kind_of(value: Any) -> str:
    """The expression-level type of a run-time value: number, string, bool, list, message, null."""
    value = unwrap(value)
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, (int, float)):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, (list, tuple, bytes)):
        return "list"
    if value is None:
        return "null"
    return "message"


_WORDS = {"bool": "true or false", "number": "a number", "string": "text", "list": "a list", "null": "null"}


def _held(value: Any) -> str:
    """What a run-time value is, in an error: ``a geometry_msgs/Pose``, ``a number``, ``text``."""
    kind = kind_of(value)
    if kind == "message":
        return "a %s" % getattr(unwrap(value), "_type", type(value).__name__)
    return _WORDS.get(kind, "a %s" % type(value).__name__)


@dataclass(frozen=True)
class Ref:
    """``$key.field[0]``: read from the tree blackboard when the node runs."""

    key: str
    path: Tuple[Any, ...] = ()

    def __str__(self) -> str:
        return "$" + self.key + "".join("[%d]" % p if isinstance(p, int) else "." + p for p in self.path)

    def resolve(self, lookup: Callable[[str], Any]) -> Any:
        """The value now; ``lookup`` raises KeyError for an unset key, a missing field is a RefError."""
        value = lookup(self.key)
        for i, step in enumerate(self.path):
            try:
                value = field_of(value, step, self.key)
            except RefError:
                if i == 0:
                    raise
                field_of(value, step, str(Ref(self.key, self.path[:i]))[1:])   # raises, naming the path so far
                raise
        return value


def scan_ref(text: str, start: int = 0, dollar: bool = True, spaces: bool = False) -> Tuple[Ref, int]:
    """The reference that starts at ``text[start]`` and where it ends.

    Args:
        dollar: the leading ``$`` is required (YAML values) rather than optional (expressions).
        spaces: blanks may surround ``.`` and brackets (expressions).
    """
    i = start
    if text.startswith("$", i):
        i += 1
    elif dollar:
        raise RefError("a reference starts with '$'", i)
    m = _NAME.match(text, i)
    if m is None:
        raise RefError("expected a key name", i)
    key, i = m.group(), m.end()
    path: List[Any] = []
    while True:
        j = _SPACE.match(text, i).end() if spaces else i
        if text.startswith(".", j):
            j = _SPACE.match(text, j + 1).end() if spaces else j + 1
            m = _NAME.match(text, j)
            if m is None:
                raise RefError("expected a field name after '.'", j)
            path.append(m.group())
            i = m.end()
        elif text.startswith("[", j):
            j = _SPACE.match(text, j + 1).end() if spaces else j + 1
            m = _INDEX.match(text, j)
            if m is None:
                raise RefError("expected an integer index", j)
            k = _SPACE.match(text, m.end()).end() if spaces else m.end()
            if not text.startswith("]", k):
                raise RefError("expected ']'", k)
            path.append(int(m.group()))
            i = k + 1
        else:
            return Ref(key, tuple(path)), i


def parse_ref(text: str) -> Any:
    """A Ref for ``$…`` text, None for other text (``$$`` escapes a dollar); RefError if malformed."""
    if not text.startswith("$") or text.startswith("$$"):
        return None
    try:
        ref, end = scan_ref(text)
        if end != len(text):
            raise RefError("unexpected %r" % text[end:], end)
    except RefError as exc:
        raise RefError("%r is not a valid reference (expected $key, $key.field or $key[0]): %s" % (text, exc),
                       exc.offset)
    return ref


class Computed(abc.ABC):
    """A value worked out from references when the node runs (``coordinator.values``: templates,
    ``$( … )`` expressions); ``refs`` are the references it reads."""

    refs: List[Ref] = []

    @abc.abstractmethod
    def resolve(self, lookup: Callable[[str], Any]) -> Any:
        """The value now; ``lookup`` raises KeyError for an unset key."""


def refs_in(value: Any) -> List[Ref]:
    """Every Ref inside a literal."""
    if isinstance(value, Ref):
        return [value]
    if isinstance(value, Computed):
        return list(value.refs)
    if isinstance(value, dict):
        return [r for v in value.values() for r in refs_in(v)]
    if isinstance(value, list):
        return [r for v in value for r in refs_in(v)]
    return []


MAX_SIZE = 2 << 20
"""The most elements and characters a value built from references may hold: room for a text of the most
characters an expression may make (1 MiB, as a call's whole payload) and as many elements besides."""
MAX_NESTING = 100
"""The most levels a value built from references may nest (``set: {xs: [$xs]}`` in a loop adds one per run)."""


def resolve(value: Any, lookup: Callable[[str], Any]) -> Any:
    """A literal with every Ref (and computed value) replaced by its value now.

    A list or a mapping that holds references is checked to be no larger than :data:`MAX_SIZE` and to
    nest no deeper than :data:`MAX_NESTING` (RefError): ``set: {xs: [$xs, $xs]}`` in a loop doubles a value
    at each run, and writing it as text, or into the run's log, would take all memory and time."""
    out = _resolve(value, lookup)
    if isinstance(value, (dict, list)) and refs_in(value):
        check_size(out)
    return out


def _resolve(value: Any, lookup: Callable[[str], Any]) -> Any:
    if isinstance(value, (Ref, Computed)):
        return value.resolve(lookup)
    if isinstance(value, dict):
        return {k: _resolve(v, lookup) for k, v in value.items()}
    if isinstance(value, list):
        return [_resolve(v, lookup) for v in value]
    return value


def check_size(value: Any) -> None:
    """RefError when ``value`` holds more than :data:`MAX_SIZE` elements and characters (a part held twice
    counted twice, as writing it out would) or nests deeper than :data:`MAX_NESTING` levels; it stops
    counting there, so a value that doubled in a loop is refused at once."""
    size = 0
    stack: List[Tuple[Any, int]] = [(value, 0)]
    while stack:
        v, depth = stack.pop()
        size += 1
        items: Any = ()
        if isinstance(v, (str, bytes, bytearray)):
            size += len(v)
        elif isinstance(v, dict):
            items = v.values()
        elif isinstance(v, (list, tuple)):
            items = v
        elif isinstance(v, genpy.Message):
            items = [getattr(v, name, None) for name in v.__slots__]
        if items and depth >= MAX_NESTING:
            raise RefError("the value would nest more than %d levels deep (a list or a mapping that holds "
                           "itself, written again and again?)" % MAX_NESTING)
        if size + len(items) > MAX_SIZE:
            raise RefError("the value would hold more than %d elements and characters, more than a value may "
                           "(a list or a mapping that holds itself twice doubles each time it is written)" % MAX_SIZE)
        stack.extend((x, depth + 1) for x in items)
