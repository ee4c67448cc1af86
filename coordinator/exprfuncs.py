"""Expressions at run time: what their operators and functions do to values, and how a value is
written as text (a template, ``str()``, a reason). The parser is :mod:`coordinator.exprparse`,
the checks before running :mod:`coordinator.exprtypes`, the whole :mod:`coordinator.expr`.
"""
from __future__ import annotations

import re
from typing import Any, Dict, List, Tuple

from coordinator.refs import MAX_NESTING, RefError, check_size, kind_of, unwrap

__all__ = ["ExprError", "FUNCTIONS", "BRIEF", "brief", "MAX_TEXT", "check_text_size", "text_of", "described",
           "arithmetic", "apply_function", "compare", "list_hint", "VERB", "ORDER", "MAX_DECIMALS", "decimals_problem"]


class ExprError(RefError):
    """A malformed expression (``offset``: where in its text), or one that cannot be evaluated."""


# name -> (arity (min, max), argument kind or "" for any, result kind)
FUNCTIONS: Dict[str, Tuple[Tuple[int, int], str, str]] = {
    "len": ((1, 1), "", "number"),
    "lower": ((1, 1), "string", "string"),
    "upper": ((1, 1), "string", "string"),
    "str": ((1, 1), "", "string"),
    "abs": ((1, 1), "number", "number"),
    "round": ((1, 2), "number", "number"),
    "min": ((1, 8), "number", "number"),
    "max": ((1, 8), "number", "number"),
    "at": ((2, 2), "", ""),
    "join": ((1, 2), "", "string"),
    "split": ((1, 2), "string", "list"),
    "words": ((1, 1), "string", "list"),
    "if": ((3, 3), "", ""),   # lazy: coordinator.expr evaluates only the branch chosen
}
MAX_DECIMALS = 15   # round(x, n): a float64 holds about 15 significant decimal digits


BRIEF = 40   # characters of a value said in a reason


def brief(v: Any, limit: int = BRIEF) -> str:
    """A value in a reason, short: ``'kitchen'``, ``3``, ``true``, ``{x: 1.0, y: 2.0, z: 0.0}``; longer than
    ``limit`` characters, cut with ``…`` (a camera image must not fill the log)."""
    text = _brief(unwrap(v), limit + 1)
    return text if len(text) <= limit else text[:limit - 1] + "\u2026"


def _brief(v: Any, limit: int) -> str:
    """``v`` as :func:`brief` writes it, built no longer than about ``limit`` characters."""
    if isinstance(v, bool) or v is None:
        return text_of(v)
    if isinstance(v, str):
        return repr(v[:limit])
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, (bytes, bytearray)):
        return "%d bytes" % len(v)
    if isinstance(v, (list, tuple)):
        parts: List[str] = []
        for item in v:
            if sum(len(p) + 2 for p in parts) > limit:
                break
            parts.append(_brief(unwrap(item), limit))
        return "[%s]" % ", ".join(parts)
    slots = getattr(v, "__slots__", None)
    if slots is not None and not isinstance(v, dict):
        items = [(name, getattr(v, name, None)) for name in slots]
    elif isinstance(v, dict):
        items = list(v.items())
    else:
        return repr(v)[:limit]
    parts = []
    for name, item in items:
        if sum(len(p) + 2 for p in parts) > limit:
            break
        parts.append("%s: %s" % (name, _brief(unwrap(item), limit)))
    return "{%s}" % ", ".join(parts)


def described(v: Any) -> str:
    """A value in an error: its kind, and the value itself when it is short by nature."""
    return "%s %r" % (kind_of(v), v) if kind_of(v) in ("number", "string", "bool") else kind_of(v)


MAX_TEXT = 1 << 20  # characters a computed text may have (a call's whole payload is 1 MiB)
MAX_INT_BITS = 1024   # a computed whole number (about 308 digits, a float64's range): beyond, it only grows
MAX_INT_DIGITS = 308


def check_text_size(text: str) -> str:
    """``text``, unless it is longer than :data:`MAX_TEXT` (a text doubled in a loop would take all memory)."""
    if len(text) > MAX_TEXT:
        raise ExprError("the text would be %d characters long, more than the %d a value may have" % (
            len(text), MAX_TEXT))
    return text


def arithmetic(op: str, a: Any, b: Any) -> Any:
    """``a op b`` for ``+ - * /``: numbers, two texts joined by ``+`` (bounded by :data:`MAX_TEXT`), or two
    lists put one after the other by ``+`` (bounded as any value built from references)."""
    ka, kb = kind_of(a), kind_of(b)
    if op == "+" and ka == kb == "string":
        if len(a) + len(b) > MAX_TEXT:
            return check_text_size(a + b[:MAX_TEXT + 1 - len(a)])  # raises without building it whole
        return a + b
    if op == "+" and ka == kb == "list":
        joined = list(a) + list(b)
        try:
            check_size(joined)   # a list added to itself in a loop doubles at each run
        except RefError as exc:
            raise ExprError(str(exc))
        return joined
    if ka != "number" or kb != "number":
        raise ExprError("cannot %s %s and %s%s" % (VERB[op], described(a), described(b), list_hint(op, ka, kb)))
    if op == "/" and b == 0:
        raise ExprError("division by zero")
    try:
        value = a + b if op == "+" else a - b if op == "-" else a * b if op == "*" else a / b
    except OverflowError:   # an int too large for a float (a / b)
        raise ExprError("cannot %s %s and %s: the result is too large" % (VERB[op], described(a), described(b)))
    if isinstance(value, int) and value.bit_length() > MAX_INT_BITS:   # a number squared in a loop
        raise ExprError("the result would have about %d digits, more than a number may have (%d)" % (
            value.bit_length() * 0.30103, MAX_INT_DIGITS))
    return value


VERB = {"+": "add", "-": "subtract", "*": "multiply", "/": "divide"}


def list_hint(op: str, ka: str, kb: str) -> str:
    """`` (to add an element to a list, write names + [x])``: the fix when ``+`` meets one list."""
    if op == "+" and (ka == "list") != (kb == "list") and None not in (ka, kb):
        return " (to add an element to a list, write it in brackets: names + [name])"
    return ""


def apply_function(name: str, args: List[Any]) -> Any:
    """The value of function ``name`` of :data:`FUNCTIONS` on ``args`` (their number checked when parsed)."""
    want = FUNCTIONS[name][1]
    for a in args:
        if want and kind_of(a) != want:
            raise ExprError("%s() takes a %s, got %s" % (name, want, described(a)))
    a = args[0]
    if name == "at":
        return _at(a, args[1])
    if name == "join":
        return _join(a, args[1] if len(args) > 1 else ", ")
    if name == "split":
        return _split(a, args[1] if len(args) > 1 else None)
    if name == "len":
        if kind_of(a) not in ("string", "list"):
            raise ExprError("len() takes a string or a list, got %s" % described(a))
        return len(a)
    if name == "lower":
        return a.lower()
    if name == "upper":
        return a.upper()
    if name == "str":
        return a if isinstance(a, str) else text_of(a)
    if name == "words":
        return _words(a)
    if name == "abs":
        return abs(a)
    if name == "round":
        return _round(a, args[1] if len(args) > 1 else 0)
    if name == "if":   # not lazy here: an expression's if() is evaluated by coordinator.expr, one branch only
        return args[1] if a else args[2]
    return min(args) if name == "min" else max(args)


def decimals_problem(n: Any) -> str:
    """Why ``n`` cannot be ``round()``'s number of decimals ('' when it can): a whole number 0 to 15."""
    if isinstance(n, bool) or not isinstance(n, (int, float)):
        return "round() takes a number of decimals, got %s" % described(n)
    if isinstance(n, float) and not n.is_integer() or not 0 <= n <= MAX_DECIMALS:
        return "round() takes a whole number of decimals from 0 to %d, got %s" % (MAX_DECIMALS, text_of(n))
    return ""


def _round(x: Any, n: Any) -> Any:
    """``round(x)``: the nearest integer; ``round(pct, 1)``: ``x`` with ``n`` decimals, for a robot to say
    (a template writes 42.5, not 42.4999…)."""
    why = decimals_problem(n)
    if why:
        raise ExprError(why)
    if n == 0:
        return int(round(x))
    return round(x, int(n))


_WORD_ENDS = re.compile(r"^[\W_]+|[\W_]+$")


def _words(text: str) -> List[str]:
    """``words(heard)``: the words of a text in lower case, without the punctuation at their ends, so that
    ``"yes" in words(heard)`` matches "Yes, please!" but not "yesterday" (``"yes" in heard`` does), and
    ``"no"`` not "I don't know". Inner apostrophes stay (``don't``; a typographic ’ written '), and so do
    letters of any language (``¿Sí?`` is ``sí``)."""
    out = []
    for word in text.replace("\u2019", "'").split():
        word = _WORD_ENDS.sub("", word)
        if word:
            out.append(word.lower())
    return out


def _join(seq: Any, sep: Any) -> str:
    """``join(names)``, ``join(names, " and ")``: a list's elements as text, for a robot to say."""
    seq, sep = unwrap(seq), unwrap(sep)
    if kind_of(seq) != "list":
        raise ExprError("join() takes a list first, got %s" % described(seq))
    if not isinstance(sep, str):
        raise ExprError("join() takes text as separator, got %s" % described(sep))
    return check_text_size(sep.join(text_of(x) for x in seq))


def _split(text: str, sep: Any) -> List[str]:
    """``split(heard)``: the words of a text (at runs of spaces, none empty); ``split(text, ',')`` the
    pieces between each ``sep``."""
    if sep is None:
        return text.split()
    if sep == "":
        raise ExprError("split() takes a separator of at least one character, got ''")
    return text.split(sep)


def _at(seq: Any, i: Any) -> Any:
    """``at(xs, i)``: the element of ``xs`` at position ``i`` (0 the first, -1 the last), where ``i`` is
    worked out when the node runs (``xs[0]`` takes a fixed position only)."""
    seq = unwrap(seq)
    if kind_of(seq) not in ("list", "string"):
        raise ExprError("at() takes a list or a string first, got %s" % described(seq))
    n = unwrap(i)
    if kind_of(n) != "number" or isinstance(n, float) and not n.is_integer():
        raise ExprError("at() takes a whole number as position, got %s" % described(i))
    if not -len(seq) <= int(n) < len(seq):
        raise ExprError("at(): no position %d in a %s of %d" % (n, kind_of(seq), len(seq)))
    return seq[int(n)]


def text_of(v: Any, _depth: int = 0) -> str:
    """A value as a template or ``str()`` writes it (``3`` for 3.0, ``true``, ``null``; a list, a mapping
    or a message in YAML's flow style: ``[kitchen, hall]``, ``{x: 1, y: 2.5, z: 0}``). A value nested
    deeper than :data:`coordinator.refs.MAX_NESTING` levels is an ExprError (not a RecursionError)."""
    v = unwrap(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if v is None:
        return "null"
    if isinstance(v, float) and v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    if isinstance(v, (list, tuple, dict)) or hasattr(v, "__slots__") and hasattr(v, "_type"):
        if _depth >= MAX_NESTING:
            raise ExprError("the value nests more than %d levels deep, too deep to write as text" % MAX_NESTING)
    if isinstance(v, (list, tuple)):   # YAML's flow style, as a tree writes one: [kitchen, hall]
        return "[%s]" % ", ".join(text_of(x, _depth + 1) for x in v)
    if isinstance(v, dict):
        return "{%s}" % ", ".join("%s: %s" % (k, text_of(x, _depth + 1)) for k, x in v.items())
    if hasattr(v, "__slots__") and hasattr(v, "_type"):   # a message of several fields
        return text_of({k: getattr(v, k) for k in v.__slots__}, _depth)
    return str(v)


ORDER = {"<", "<=", ">", ">="}


def compare(op: str, a: Any, b: Any) -> bool:
    """``a op b`` for a comparison or ``in`` (text in text ignores case); TypeError when they do not compare."""
    if op == "==":
        return a == b
    if op == "!=":
        return a != b
    if op in ORDER and (kind_of(a) == "bool") != (kind_of(b) == "bool"):
        raise TypeError(op)
    if op == "<":
        return a < b
    if op == "<=":
        return a <= b
    if op == ">":
        return a > b
    if op == ">=":
        return a >= b
    if isinstance(a, str) and isinstance(b, str):
        return a.lower() in b.lower()
    return a in b

