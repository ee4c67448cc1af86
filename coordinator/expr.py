"""The ``check`` leaf's expressions: a small grammar, parsed and evaluated without eval.

    expr  := or ;  or := and ('or' and)* ;  and := not ('and' not)*
    not   := 'not' not | cmp ;  cmp := value (('=='|'!='|'<'|'<='|'>'|'>='|'in') value)?
    value := number | string | true | false | null | ref | '(' expr ')'
    ref   := ['$'] name ('.' field | '[' index ']')*

A one-field ROS message (``std_msgs/String``, ``std_msgs/Bool``…) stands for its
value, so ``answer == "yes"`` works on the output of ``speech.listen``.
"""
from __future__ import annotations

import re
from typing import Any, Callable, List, Optional, Set, Tuple

import genpy

__all__ = ["Expr", "ExprError", "field_of", "parse", "unwrap"]


class ExprError(ValueError):
    def __init__(self, message: str, offset: int = 0):
        super().__init__(message)
        self.offset = offset


_TOKEN = re.compile(r"""\s*(?:
    (?P<num>-?\d+\.\d*(?:[eE][-+]?\d+)?|-?\d*\.\d+(?:[eE][-+]?\d+)?|-?\d+)|
    (?P<str>"(?:[^"\\]|\\.)*"|'(?:[^'\\]|\\.)*')|
    (?P<op>==|!=|<=|>=|<|>|\(|\)|\.|\[|\])|
    (?P<name>\$?[A-Za-z_][A-Za-z0-9_]*)|
    (?P<bad>\S))""", re.X)

_KEYWORDS = {"and", "or", "not", "in", "true", "false", "null", "True", "False", "None"}
_CMP = {"==", "!=", "<", "<=", ">", ">=", "in"}


def unwrap(value: Any) -> Any:
    """The plain value of a one-field message; other values unchanged."""
    if isinstance(value, genpy.Message):
        slots = value.__slots__
        if len(slots) == 1:
            return unwrap(getattr(value, slots[0]))
    return value


def _tokens(text: str) -> List[Tuple[str, str, int]]:
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
            raise ExprError("unexpected character %r" % value, start)
        if kind == "name" and value in _KEYWORDS:
            kind = "kw"
        out.append((kind, value, start))
        pos = m.end()
    out.append(("end", "", len(text)))
    return out


class Expr:
    """A parsed expression: ``keys`` are the tree-blackboard keys it reads."""

    def __init__(self, text: str):
        self.text = text
        self.keys: Set[str] = set()
        self._toks = _tokens(text)
        self._i = 0
        self.tree = self._or()
        if self._peek()[0] != "end":
            raise ExprError("unexpected %r" % self._peek()[1], self._peek()[2])
        del self._toks

    # parsing
    def _peek(self) -> Tuple[str, str, int]:
        return self._toks[self._i]

    def _take(self) -> Tuple[str, str, int]:
        tok = self._toks[self._i]
        self._i += 1
        return tok

    def _expect(self, value: str) -> None:
        tok = self._take()
        if tok[1] != value:
            raise ExprError("expected %r, found %r" % (value, tok[1] or "end of expression"), tok[2])

    def _or(self) -> Any:
        node = self._and()
        while self._peek()[1] == "or":
            self._take()
            node = ("or", node, self._and())
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
        left = self._value()
        tok = self._peek()
        if tok[1] in _CMP and tok[0] in ("op", "kw"):
            self._take()
            return ("cmp", tok[1], left, self._value())
        return left

    def _value(self) -> Any:
        kind, value, at = self._take()
        if kind == "num":
            return ("lit", float(value) if any(c in value for c in ".eE") else int(value))
        if kind == "str":
            return ("lit", bytes(value[1:-1], "utf-8").decode("unicode_escape"))
        if kind == "kw" and value in ("true", "True"):
            return ("lit", True)
        if kind == "kw" and value in ("false", "False"):
            return ("lit", False)
        if kind == "kw" and value in ("null", "None"):
            return ("lit", None)
        if value == "(":
            node = self._or()
            self._expect(")")
            return node
        if kind == "name":
            name = value.lstrip("$")
            self.keys.add(name)
            path: List[Any] = []
            while self._peek()[1] in (".", "["):
                if self._take()[1] == ".":
                    k, field, fat = self._take()
                    if k not in ("name", "kw"):
                        raise ExprError("expected a field name after '.'", fat)
                    path.append(field)
                else:
                    k, idx, iat = self._take()
                    if k != "num" or not idx.lstrip("-").isdigit():
                        raise ExprError("expected an integer index", iat)
                    path.append(int(idx))
                    self._expect("]")
            return ("ref", name, tuple(path), at)
        raise ExprError("expected a value, found %r" % (value or "end of expression"), at)

    # evaluation
    def evaluate(self, lookup: Callable[[str], Any]) -> bool:
        """Truth of the expression; ``lookup(key)`` raises KeyError for unset keys."""
        return bool(unwrap(self._eval(self.tree, lookup)))

    def _eval(self, node: Any, lookup: Callable[[str], Any]) -> Any:
        op = node[0]
        if op == "lit":
            return node[1]
        if op == "ref":
            value = lookup(node[1])
            for step in node[2]:
                value = field_of(value, step, node[1])
            return value
        if op == "not":
            return not unwrap(self._eval(node[1], lookup))
        if op == "and":
            return unwrap(self._eval(node[1], lookup)) and unwrap(self._eval(node[2], lookup))
        if op == "or":
            return unwrap(self._eval(node[1], lookup)) or unwrap(self._eval(node[2], lookup))
        a, b = unwrap(self._eval(node[2], lookup)), unwrap(self._eval(node[3], lookup))
        try:
            return _compare(node[1], a, b)
        except TypeError:
            raise ExprError("cannot compare %s %s %s" % (type(a).__name__, node[1], type(b).__name__))


def field_of(value: Any, step: Any, root: str) -> Any:
    """``value.step`` or ``value[step]`` for a message, a mapping or a list; ExprError names ``root``."""
    try:
        if isinstance(step, int):
            return unwrap(value)[step]
        if isinstance(value, dict):
            return value[step]
        if isinstance(value, genpy.Message) and step in value.__slots__:
            return getattr(value, step)
    except (IndexError, KeyError, TypeError):
        pass
    raise ExprError("%s has no %s %r" % (root, "index" if isinstance(step, int) else "field", step))


def _compare(op: str, a: Any, b: Any) -> bool:
    if op == "==":
        return a == b
    if op == "!=":
        return a != b
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


def parse(text: str) -> Optional[Expr]:
    return Expr(text)
