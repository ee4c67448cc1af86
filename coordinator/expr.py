"""Expressions: a small grammar, parsed and evaluated without eval.

    expr  := or ;  or := and ('or' and)* ;  and := not ('and' not)*
    not   := 'not' not | cmp ;  cmp := sum (('=='|'!='|'<'|'<='|'>'|'>='|'in') sum)?
    sum   := term (('+'|'-') term)* ;  term := unary (('*'|'/') unary)* ;  unary := '-' unary | value
    value := number | string | true | false | null | ref | func '(' [expr (',' expr)*] ')' | '(' expr ')'
    ref   := ['$'] name ('.' field | '[' index ']')*

``check`` holds one; a ``$( … )`` value and a template's ``{ … }`` hold one too. A one-field ROS
message (``std_msgs/String``…) stands for its value, so ``answer == "yes"`` works on the output
of ``speech.listen``. :meth:`Expr.type_errors` finds operands of the wrong type before running,
for the keys whose types the module definitions give.
"""
from __future__ import annotations

import re
from typing import Any, Callable, Dict, List, Optional, Set, Tuple

from comm.errors import did_you_mean
from coordinator.refs import Ref, RefError, kind_of, scan_ref, unwrap

__all__ = ["BRIEF", "Expr", "ExprError", "FUNCTIONS", "brief", "MAX_TEXT", "check_text_size", "kind_of", "text_of"]


class ExprError(RefError):
    """A malformed expression (``offset``: where in its text), or one that cannot be evaluated."""


_TOKEN = re.compile(r"""\s*(?:
    (?P<num>\d+\.\d*(?:[eE][-+]?\d+)?|\d*\.\d+(?:[eE][-+]?\d+)?|\d+)|
    (?P<str>"(?:[^"\\]|\\.)*"|'(?:[^'\\]|\\.)*')|
    (?P<op>==|!=|<=|>=|<|>|\(|\)|\.|\[|\]|\+|-|\*|/|,)|
    (?P<name>\$?[A-Za-z_][A-Za-z0-9_]*)|
    (?P<bad>\S))""", re.X)
_OPEN_PAREN = re.compile(r"\s*\(")

_KEYWORDS = {"and", "or", "not", "in", "true", "false", "null", "True", "False", "None"}
_CMP = {"==", "!=", "<", "<=", ">", ">=", "in"}
_ORDER = {"<", "<=", ">", ">="}

# name -> (arity (min, max), argument kind or "" for any, result kind)
FUNCTIONS: Dict[str, Tuple[Tuple[int, int], str, str]] = {
    "len": ((1, 1), "", "number"),
    "lower": ((1, 1), "string", "string"),
    "upper": ((1, 1), "string", "string"),
    "str": ((1, 1), "", "string"),
    "abs": ((1, 1), "number", "number"),
    "round": ((1, 1), "number", "number"),
    "min": ((1, 8), "number", "number"),
    "max": ((1, 8), "number", "number"),
    "at": ((2, 2), "", ""),
    "join": ((1, 2), "", "string"),
}


def _tokens(text: str) -> List[Tuple[str, Any, int]]:
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
                    "!": " (use 'not', or '!=')"}.get(value, "")
            raise ExprError("unexpected character %r%s" % (value, hint), start)
        if kind == "name" and value in _KEYWORDS:
            kind = "kw"
        elif kind == "name" and not value.startswith("$") and _OPEN_PAREN.match(text, m.end()):
            if value not in FUNCTIONS:
                raise ExprError("unknown function %r%s" % (value, did_you_mean(value, FUNCTIONS)
                                                           or " (functions: %s)" % ", ".join(FUNCTIONS)), start)
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


def _shown(tok: Tuple[str, Any, int]) -> str:
    return tok[1][1] if tok[0] == "ref" else tok[1]


class Expr:
    """A parsed expression: ``keys`` are the tree-blackboard keys it reads, ``refs`` its references.

    Immutable once parsed, so :meth:`parse` shares one object per text (trees repeat their checks).
    """

    _cache: Dict[str, Expr] = {}

    @classmethod
    def parse(cls, text: str) -> Expr:
        """The parsed expression of ``text`` (ExprError if malformed), shared with earlier parses."""
        e = cls._cache.get(text)
        if e is None:
            e = cls(text)
            if len(cls._cache) < 4096:
                cls._cache[text] = e
        return e

    def __init__(self, text: str):
        if len(text) > 2000:
            raise ExprError("expression longer than 2000 characters", 0)
        self.text = text
        self._fixed_errors: Optional[List[Tuple[int, str]]] = None   # type errors when there are no refs
        self.well_typed = False   # known to have no type errors, whatever the tree (no refs, none found)
        self.keys: Set[str] = set()
        self.refs: List[Ref] = []
        self.ref_offsets: List[int] = []   # where each of ``refs`` starts in the text (for error positions)
        self._toks = _tokens(text)
        self._i = 0
        self._depth = 0
        self.tree = self._or()
        if self._peek()[0] != "end":
            raise ExprError("unexpected %r" % _shown(self._peek()), self._peek()[2])
        del self._toks

    # parsing
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
            return ("lit", float(value) if any(c in value for c in ".eE") else int(value))
        if kind == "str":
            return ("lit", bytes(value[1:-1], "utf-8").decode("unicode_escape"))
        if kind == "kw" and value in ("true", "True"):
            return ("lit", True)
        if kind == "kw" and value in ("false", "False"):
            return ("lit", False)
        if kind == "kw" and value in ("null", "None"):
            return ("lit", None)
        if value == "(" and kind == "op":
            node = self._or()
            self._expect(")")
            return node
        if kind == "func":
            return self._call(value, at)
        if kind == "ref":
            self.keys.add(value[0].key)
            self.refs.append(value[0])
            self.ref_offsets.append(at)
            return ("ref", value[0], at)
        raise ExprError("expected a value, found %r" % (value or "end of expression"), at)

    def offset_of(self, key: str) -> Optional[int]:
        """Where the first reference to ``key`` starts in the text, None if it reads no such key."""
        return next((at for r, at in zip(self.refs, self.ref_offsets) if r.key == key), None)

    def _call(self, name: str, at: int) -> Any:
        self._expect("(")
        args = []
        if self._peek()[1] != ")":
            args.append(self._or())
            while self._peek()[1] == ",":
                self._take()
                args.append(self._or())
        self._expect(")")
        (lo, hi), _, _ = FUNCTIONS[name]
        if not lo <= len(args) <= hi:
            raise ExprError("%s() takes %s, got %d" % (name, "1 argument" if hi == 1 else "%d to %d arguments"
                                                       % (lo, hi), len(args)), at)
        return ("call", name, tuple(args), at)

    # evaluation
    def evaluate(self, lookup: Callable[[str], Any]) -> bool:
        """Truth of the expression; ``lookup(key)`` raises KeyError for unset keys."""
        return bool(unwrap(self._eval(self.tree, lookup)))

    def value(self, lookup: Callable[[str], Any]) -> Any:
        """The expression's value (a one-field message stands for its value)."""
        return unwrap(self._eval(self.tree, lookup))

    def values_read(self, lookup: Callable[[str], Any]) -> str:
        """`` (a = 'kitchen', b = 'hall')``: what each reference holds now, for a reason that says why an
        expression was false without the reader having to guess the values ('' without references; a
        reference that cannot be read now is left out)."""
        said: List[str] = []
        for ref in dict.fromkeys(self.refs):   # each once, in the order written
            try:
                said.append("%s = %s" % (str(ref)[1:], brief(ref.resolve(lookup))))
            except (KeyError, RefError):
                continue
        return " (%s)" % ", ".join(said) if said else ""

    def _eval(self, node: Any, lookup: Callable[[str], Any]) -> Any:
        op = node[0]
        if op == "lit":
            return node[1]
        if op == "ref":
            try:
                return node[1].resolve(lookup)
            except ExprError:
                raise
            except RefError as exc:
                raise ExprError(str(exc))
        if op == "not":
            return not unwrap(self._eval(node[1], lookup))
        if op == "and":
            return unwrap(self._eval(node[1], lookup)) and unwrap(self._eval(node[2], lookup))
        if op == "or":
            return unwrap(self._eval(node[1], lookup)) or unwrap(self._eval(node[2], lookup))
        if op == "neg":
            v = unwrap(self._eval(node[1], lookup))
            if kind_of(v) != "number":
                raise ExprError("cannot negate %s" % _described(v))
            return -v
        if op == "arith":
            return _arith(node[1], unwrap(self._eval(node[2], lookup)), unwrap(self._eval(node[3], lookup)))
        if op == "call":
            return _apply(node[1], [unwrap(self._eval(a, lookup)) for a in node[2]])
        a, b = unwrap(self._eval(node[2], lookup)), unwrap(self._eval(node[3], lookup))
        try:
            return _compare(node[1], a, b)
        except TypeError:
            raise ExprError("cannot compare %s %s %s" % (type(a).__name__, node[1], type(b).__name__))

    # static types
    def type_errors(self, key_kind: Callable[[Ref], Optional[str]]) -> List[Tuple[int, str]]:
        """(offset, message) for each operand whose kind, known before running, cannot fit.

        ``key_kind(ref)`` is the kind a reference will hold (see :func:`kind_of`), None if unknown.
        Without references the answer never changes (and trees repeat their checks): kept.
        """
        if not self.refs and self._fixed_errors is not None:
            return list(self._fixed_errors)
        errors: List[Tuple[int, str]] = []
        _static(self.tree, key_kind, errors)
        if not self.refs:
            self._fixed_errors = list(errors)
            self.well_typed = not errors
        return errors

    def kind(self, key_kind: Callable[[Ref], Optional[str]]) -> Optional[str]:
        """The kind of the expression's value (see :func:`kind_of`) when known before running, else None
        (also when an operand is of the wrong kind: :meth:`type_errors` says that)."""
        return _static(self.tree, key_kind, [])


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


def _described(v: Any) -> str:
    return "%s %r" % (kind_of(v), v) if kind_of(v) in ("number", "string", "bool") else kind_of(v)


MAX_TEXT = 1 << 20  # characters a computed text may have (a call's whole payload is 1 MiB)


def check_text_size(text: str) -> str:
    """``text``, unless it is longer than :data:`MAX_TEXT` (a text doubled in a loop would take all memory)."""
    if len(text) > MAX_TEXT:
        raise ExprError("the text would be %d characters long, more than the %d a value may have" % (
            len(text), MAX_TEXT))
    return text


def _arith(op: str, a: Any, b: Any) -> Any:
    ka, kb = kind_of(a), kind_of(b)
    if op == "+" and ka == kb == "string":
        if len(a) + len(b) > MAX_TEXT:
            return check_text_size(a + b[:MAX_TEXT + 1 - len(a)])  # raises without building it whole
        return a + b
    if ka != "number" or kb != "number":
        raise ExprError("cannot %s %s and %s" % (_VERB[op], _described(a), _described(b)))
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    if b == 0:
        raise ExprError("division by zero")
    return a / b


_VERB = {"+": "add", "-": "subtract", "*": "multiply", "/": "divide"}


def _apply(name: str, args: List[Any]) -> Any:
    want = FUNCTIONS[name][1]
    for a in args:
        if want and kind_of(a) != want:
            raise ExprError("%s() takes a %s, got %s" % (name, want, _described(a)))
    a = args[0]
    if name == "at":
        return _at(a, args[1])
    if name == "join":
        return _join(a, args[1] if len(args) > 1 else ", ")
    if name == "len":
        if kind_of(a) not in ("string", "list"):
            raise ExprError("len() takes a string or a list, got %s" % _described(a))
        return len(a)
    if name == "lower":
        return a.lower()
    if name == "upper":
        return a.upper()
    if name == "str":
        return a if isinstance(a, str) else text_of(a)
    if name == "abs":
        return abs(a)
    if name == "round":
        return int(round(a))
    return min(args) if name == "min" else max(args)


def _join(seq: Any, sep: Any) -> str:
    """``join(names)``, ``join(names, " and ")``: a list's elements as text, for a robot to say."""
    seq, sep = unwrap(seq), unwrap(sep)
    if kind_of(seq) != "list":
        raise ExprError("join() takes a list first, got %s" % _described(seq))
    if not isinstance(sep, str):
        raise ExprError("join() takes text as separator, got %s" % _described(sep))
    return check_text_size(sep.join(text_of(x) for x in seq))


def _at(seq: Any, i: Any) -> Any:
    """``at(xs, i)``: the element of ``xs`` at position ``i`` (0 the first, -1 the last), where ``i`` is
    worked out when the node runs (``xs[0]`` takes a fixed position only)."""
    seq = unwrap(seq)
    if kind_of(seq) not in ("list", "string"):
        raise ExprError("at() takes a list or a string first, got %s" % _described(seq))
    n = unwrap(i)
    if kind_of(n) != "number" or isinstance(n, float) and not n.is_integer():
        raise ExprError("at() takes a whole number as position, got %s" % _described(i))
    if not -len(seq) <= int(n) < len(seq):
        raise ExprError("at(): no position %d in a %s of %d" % (n, kind_of(seq), len(seq)))
    return seq[int(n)]


def text_of(v: Any) -> str:
    """A value as a template or ``str()`` writes it (``3`` for 3.0, ``true``, ``null``; a list, a mapping
    or a message in YAML's flow style: ``[kitchen, hall]``, ``{x: 1, y: 2.5, z: 0}``)."""
    v = unwrap(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if v is None:
        return "null"
    if isinstance(v, float) and v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    if isinstance(v, (list, tuple)):   # YAML's flow style, as a tree writes one: [kitchen, hall]
        return "[%s]" % ", ".join(text_of(x) for x in v)
    if isinstance(v, dict):
        return "{%s}" % ", ".join("%s: %s" % (k, text_of(x)) for k, x in v.items())
    if hasattr(v, "__slots__") and hasattr(v, "_type"):   # a message of several fields
        return text_of({k: getattr(v, k) for k in v.__slots__})
    return str(v)


def _compare(op: str, a: Any, b: Any) -> bool:
    if op == "==":
        return a == b
    if op == "!=":
        return a != b
    if op in _ORDER and (kind_of(a) == "bool") != (kind_of(b) == "bool"):
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


def _static(node: Any, key_kind: Callable[[Ref], Optional[str]], errors: List[Tuple[int, str]]) -> Optional[str]:
    """The kind of ``node``'s value when known, after recording misfits below it."""
    op = node[0]
    if op == "lit":
        return kind_of(node[1])
    if op == "ref":
        return key_kind(node[1])
    if op in ("and", "or"):
        _static(node[1], key_kind, errors)
        _static(node[2], key_kind, errors)
        return None
    if op == "not":
        _static(node[1], key_kind, errors)
        return "bool"
    if op == "neg":
        k = _static(node[1], key_kind, errors)
        if k is not None and k != "number":
            errors.append((node[2], "cannot negate a %s" % k))
        return "number"
    if op == "arith":
        a, b = _static(node[2], key_kind, errors), _static(node[3], key_kind, errors)
        if a is None or b is None:
            return None
        if node[1] == "+" and a == b == "string":
            return "string"
        if a != "number" or b != "number":
            errors.append((node[4], "cannot %s a %s and a %s" % (_VERB[node[1]], a, b)))
            return None
        return "number"
    if op == "call":
        name, args, at = node[1], node[2], node[3]
        if name == "at":
            kinds = [_static(arg, key_kind, errors) for arg in args]
            if kinds[0] not in (None, "list", "string"):
                errors.append((at, "at() takes a list or a string first, not a %s" % kinds[0]))
            if len(kinds) > 1 and kinds[1] not in (None, "number"):
                errors.append((at, "at() takes a number as position, not a %s" % kinds[1]))
            return None   # an element: its kind is not known here
        if name == "join":
            kinds = [_static(arg, key_kind, errors) for arg in args]
            if kinds[0] not in (None, "list"):
                errors.append((at, "join() takes a list first, not a %s" % kinds[0]))
            if len(kinds) > 1 and kinds[1] not in (None, "string"):
                errors.append((at, "join() takes text as separator, not a %s" % kinds[1]))
            return "string"
        want = FUNCTIONS[name][1]
        for arg in args:
            k = _static(arg, key_kind, errors)
            if k is None:
                continue
            if (want and k != want) or (name == "len" and k not in ("string", "list")):
                errors.append((at, "%s() takes a %s, not a %s" % (name, want or "string or a list", k)))
        return FUNCTIONS[name][2]
    a, b = _static(node[2], key_kind, errors), _static(node[3], key_kind, errors)
    if node[1] in _ORDER and a is not None and b is not None and a != b:
        errors.append((node[4], "cannot compare a %s %s a %s" % (a, node[1], b)))
    elif node[1] in ("==", "!=") and ({a, b} == {"number", "string"} or {a, b} == {"bool", "string"}):
        fix = _as_truth(node) if "bool" in (a, b) else ""
        errors.append((node[4], "a %s %s a %s is always %s%s" % (
            a, node[1], b, "false" if node[1] == "==" else "true",
            fix or _as_other(node[2]) or _as_other(node[3]))))
    return "bool"


def _as_truth(node: Any) -> str:
    """`` (write door_open, or door_open == true)``: the fix for a true/false value compared with text that
    is not a literal ``true``/``false`` of its own ('' when the text side is not written in the expression)."""
    op, left, right = node[1], node[2], node[3]
    text, other = (left, right) if left[0] == "lit" and isinstance(left[1], str) else (right, left)
    if text[0] != "lit" or not isinstance(text[1], str):
        return ""
    name = str(other[1])[1:] if other[0] == "ref" else ""
    word = text[1].strip().lower()
    if word not in ("true", "false"):
        return " (a true/false value is not text: %scompare it with true or false, unquoted)" % (
            "write %s or not %s, or " % (name, name) if name else "")
    if not name:
        return " (compare with %s, unquoted)" % word
    holds = (word == "true") == (op == "==")
    return " (write %s%s, or %s %s %s, unquoted)" % ("" if holds else "not ", name, name, op, word)


_NUMBER_TEXT = re.compile(r"-?(?:\d+\.\d*|\d*\.\d+|\d+)(?:[eE][-+]?\d+)?$")


def _as_other(node: Any) -> str:
    """`` (write 0, not "0")``: the fix when one side of a number-text comparison is a literal that
    the other kind can write; '' otherwise."""
    if node[0] != "lit":
        return ""
    v = node[1]
    if isinstance(v, str):
        if not _NUMBER_TEXT.match(v):
            return ""
        num = float(v)
        if num in (float("inf"), float("-inf")):
            return ""
        return " (write %s, not %s)" % (text_of(num), _quoted(v))
    return " (write %s, not %s)" % (_quoted(text_of(v)), text_of(v))


def _quoted(text: str) -> str:
    """Text as an expression writes it, in double quotes."""
    return '"%s"' % text.replace("\\", "\\\\").replace('"', '\\"')
