"""The expression grammar (see :mod:`coordinator.expr`): the tokenizer and the recursive-descent
parser that turns a text into a tree of tuples, noting the references it reads.

A function's result or a parenthesised expression may be followed by fields and indexes as a key is
(``at(ps.poses, i).position.z``, ``split(heard)[0]``): a ``("path", value, steps, offset, written)`` node,
or, after a reference in parentheses, the longer reference itself (``(pos).x`` is ``pos.x``).
"""
from __future__ import annotations

import re
from typing import Any, List, Set, Tuple

from comm.errors import did_you_mean
from coordinator.exprfuncs import FUNCTIONS, ExprError
from coordinator.refs import Ref, RefError, kind_of, scan_ref

__all__ = ["Parser", "tokens"]


_TOKEN = re.compile(r"""\s*(?:
    (?P<num>\d+\.\d*(?:[eE][-+]?\d+)?|\d*\.\d+(?:[eE][-+]?\d+)?|\d+[eE][-+]?\d+|\d+)|
    (?P<str>"(?:[^"\\]|\\.)*"|'(?:[^'\\]|\\.)*')|
    (?P<op>==|!=|<=|>=|<|>|\(|\)|\.|\[|\]|\+|-|\*|/|,)|
    (?P<name>\$?[A-Za-z_][A-Za-z0-9_]*)|
    (?P<bad>\S))""", re.X)
_OPEN_PAREN = re.compile(r"\s*\(")
_DECIMALS = re.compile(r"\s*:\s*\.(\d+)[fF]\s*$")   # Python's {pct:.1f}
_IF = "unexpected 'if' (a choice is written if(condition, then, else))"
_INSTEAD = {"range": ": to count, write repeat: N with index: KEY (its run's number, 0 for the first)",
            "filter": ": to keep some elements, for_each over the list with a check and set: {kept: $(kept + [x])}"}

_KEYWORDS = {"and", "or", "not", "in", "true", "false", "null", "True", "False", "None"}
_CMP = {"==", "!=", "<", "<=", ">", ">=", "in"}


def tokens(text: str) -> List[Tuple[str, Any, int]]:
    """``(kind, value, offset)`` of each token of ``text``, then an ``end`` one; a reference is one token
    (:func:`coordinator.refs.scan_ref`), and a name before ``(`` must be a known function."""
    out = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            break
        kind = m.lastgroup or ""
        value = m.group(kind)
        start = m.start(kind)
        if kind == "bad":
            hint = {"=": " (compare with '==')", "&": " (use 'and')", "|": " (use 'or')",
                    "!": " (use 'not', or '!=')", ":": _decimals_hint(text, start)}.get(value, "")
            raise ExprError("unexpected character %r%s" % (value, hint), start)
        if kind == "name" and out and out[-1][:2] == ("op", "."):   # a field of a function's result
            if value.startswith("$"):
                raise ExprError("expected a field name after '.'", start)
            try:
                ref, end = scan_ref(text, start, dollar=False, spaces=True)
            except RefError as exc:
                raise ExprError(str(exc), exc.offset)
            out.append(("field", (ref.key,) + ref.path, start))
            pos = end
            continue
        if kind == "name" and value in _KEYWORDS:
            kind = "kw"
        elif kind == "name" and not value.startswith("$") and _OPEN_PAREN.match(text, m.end()):
            if value not in FUNCTIONS:
                raise ExprError("unknown function %r%s%s" % (value, did_you_mean(value, FUNCTIONS)
                                                             or " (functions: %s)" % ", ".join(FUNCTIONS),
                                                             _INSTEAD.get(value, "")), start)
            kind = "func"
        elif kind == "name":  # a reference: the one grammar of coordinator.refs, '$' optional here
            try:
                ref, end = scan_ref(text, start, dollar=False, spaces=True)
            except RefError as exc:
                raise ExprError(str(exc), exc.offset)
            out.append(("ref", (ref, text[start:end]), start))
            pos = end
            continue
        out.append((kind, value, start))
        pos = m.end()
    out.append(("end", "", len(text)))
    return out


def _decimals_hint(text: str, colon: int) -> str:
    """`` (for 1 decimal write round(pct, 1))``: Python's format ``{pct:.1f}`` as the expression's
    ``round(x, n)``, which a template writes without trailing zeros."""
    m = _DECIMALS.match(text, colon)
    before = text[:colon].strip()
    if m is None or not before:
        return " (a number is rounded to n decimals with round(x, n), not with ':')"
    n = int(m.group(1))
    if n == 0:
        return " (for a whole number write round(%s))" % before
    return " (for %d decimal%s write round(%s, %d))" % (n, "" if n == 1 else "s", before, n)


def _shown(tok: Tuple[str, Any, int]) -> str:
    if tok[0] == "field":
        return str(Ref(tok[1][0], tok[1][1:]))[1:]
    return tok[1][1] if tok[0] == "ref" else tok[1]


def _is_if(tok: Tuple[str, Any, int]) -> bool:
    """Whether ``tok`` is a Python-style ``if`` (``a if c else b``), where an operator or the end is due."""
    return tok[0] == "func" and tok[1] == "if" or tok[0] == "ref" and tok[1][0] == Ref("if")


class Parser:
    """One parse of an expression's text: its ``tree``, and the references it reads in the order
    written (``refs``, where each starts: ``ref_offsets``, their ``keys``); ExprError if malformed."""

    def __init__(self, text: str):
        self._text = text
        self.keys: Set[str] = set()
        self.refs: List[Ref] = []
        self.ref_offsets: List[int] = []
        self._toks = tokens(text)
        self._i = 0
        self._depth = 0
        self.tree = self._or()
        if self._peek()[0] != "end":
            raise ExprError("unexpected %r" % _shown(self._peek()), self._peek()[2])
        del self._toks

    def _peek(self) -> Tuple[str, Any, int]:
        return self._toks[self._i]

    def _take(self) -> Tuple[str, Any, int]:
        tok = self._toks[self._i]
        self._i += 1
        return tok

    def _expect(self, value: str) -> None:
        tok = self._take()
        if tok[1] != value:
            raise ExprError("expected %r, found %r" % (value, _shown(tok) or "end of expression"), tok[2])

    def _or(self) -> Any:
        self._depth += 1
        if self._depth > 50:
            raise ExprError("expression nested too deeply", self._peek()[2])
        node = self._and()
        while self._peek()[1] == "or":
            self._take()
            node = ("or", node, self._and())
        if _is_if(self._peek()):
            raise ExprError(_IF, self._peek()[2])
        self._depth -= 1
        return node

    def _and(self) -> Any:
        node = self._not()
        while self._peek()[1] == "and":
            self._take()
            node = ("and", node, self._not())
        return node

    def _not(self) -> Any:
        if self._peek()[1] == "not":
            self._take()
            return ("not", self._not())
        return self._cmp()

    def _cmp(self) -> Any:
        left = self._sum()
        tok = self._peek()
        if tok[1] in _CMP and tok[0] in ("op", "kw"):
            self._take()
            return ("cmp", tok[1], left, self._sum(), tok[2])
        return left

    def _sum(self) -> Any:
        node = self._term()
        while self._peek()[0] == "op" and self._peek()[1] in ("+", "-"):
            tok = self._take()
            node = ("arith", tok[1], node, self._term(), tok[2])
        return node

    def _term(self) -> Any:
        node = self._unary()
        while self._peek()[0] == "op" and self._peek()[1] in ("*", "/"):
            tok = self._take()
            node = ("arith", tok[1], node, self._unary(), tok[2])
        return node

    def _unary(self) -> Any:
        tok = self._peek()
        if tok[0] == "op" and tok[1] == "-":
            self._take()
            inner = self._unary()
            if inner[0] == "lit" and kind_of(inner[1]) == "number":
                return ("lit", -inner[1])
            return ("neg", inner, tok[2])
        return self._value()

    def _value(self) -> Any:
        kind, value, at = self._take()
        if kind == "num":
            number = float(value) if any(c in value for c in ".eE") else int(value)
            if number in (float("inf"), -float("inf")):
                raise ExprError("the number %s is out of range (at most about 1.8e308)" % value, at)
            return ("lit", number)
        if kind == "str":
            # escapes read as Python's; a letter beyond Latin-1 kept (as UTF-8 bytes, "sí" was "sÃ\xad")
            return ("lit", value[1:-1].encode("latin-1", "backslashreplace").decode("unicode_escape"))
        if kind == "kw" and value in ("true", "True"):
            return ("lit", True)
        if kind == "kw" and value in ("false", "False"):
            return ("lit", False)
        if kind == "kw" and value in ("null", "None"):
            return ("lit", None)
        if value == "(" and kind == "op":
            node = self._or()
            self._expect(")")
            return self._path(node, at)
        if value == "[" and kind == "op":
            return self._list(at)
        if kind == "func":
            return self._path(self._call(value, at), at)
        if kind == "ref":
            self.keys.add(value[0].key)
            self.refs.append(value[0])
            self.ref_offsets.append(at)
            return ("ref", value[0], at)
        raise ExprError("expected a value, found %r" % (value or "end of expression"), at)

    def _items(self, close: str) -> List[Any]:
        """Expressions separated by commas up to ``close`` (taken): a list's elements, a call's arguments."""
        items = []
        if self._peek()[1] != close:
            items.append(self._or())
            while self._peek()[1] == ",":
                self._take()
                items.append(self._or())
        self._expect(close)
        return items

    def _path(self, node: Any, at: int) -> Any:
        """``node`` (written from ``at`` to the token just taken) with the fields and indexes that follow it:
        as a key's (a name after '.', an integer in brackets), read when it is evaluated."""
        end = self._toks[self._i - 1][2] + 1
        steps: List[Any] = []
        while self._peek()[0] == "op" and self._peek()[1] in (".", "["):
            if self._take()[1] == ".":
                tok = self._take()
                if tok[0] != "field":
                    raise ExprError("expected a field name after '.'", tok[2])
                steps.extend(tok[1])
                continue
            sign = -1 if self._peek()[:2] == ("op", "-") else 1
            if sign < 0:
                self._take()
            tok = self._take()
            if tok[0] != "num" or not tok[1].isdigit():
                raise ExprError("expected an integer index", tok[2])
            steps.append(sign * int(tok[1]))
            self._expect("]")
        if not steps:
            return node
        if node[0] == "ref":   # (pos).x is pos.x: one reference, typed and checked as one
            ref = Ref(node[1].key, node[1].path + tuple(steps))
            self.refs[-1] = ref
            return ("ref", ref, node[2])
        return ("path", node, tuple(steps), at, self._text[at:end])

    def _list(self, at: int) -> Any:
        """``[a, b]``: a list of the values of its expressions (``names + [heard]`` appends one)."""
        return ("list", tuple(self._items("]")), at)

    def _call(self, name: str, at: int) -> Any:
        self._expect("(")
        args = self._items(")")
        (lo, hi), _, _ = FUNCTIONS[name]
        if not lo <= len(args) <= hi:
            takes = "1 argument" if hi == 1 else "%d arguments" % hi if lo == hi else "%d to %d arguments" % (lo, hi)
            raise ExprError("%s() takes %s, got %d" % (name, takes, len(args)), at)
        return ("call", name, tuple(args), at)
