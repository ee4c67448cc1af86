"""Expressions: a small grammar, parsed and evaluated without eval.

    expr  := or ;  or := and ('or' and)* ;  and := not ('and' not)*
    not   := 'not' not | cmp ;  cmp := sum (('=='|'!='|'<'|'<='|'>'|'>='|'in') sum)?
    sum   := term (('+'|'-') term)* ;  term := unary (('*'|'/') unary)* ;  unary := '-' unary | value
    value := number | string | true | false | null | ref | func '(' [expr (',' expr)*] ')' path
           | '(' expr ')' path | '[' [expr (',' expr)*] ']'
    ref   := ['$'] name path ;  path := ('.' field | '[' index ']')*

``check`` holds one; a ``$( … )`` value and a template's ``{ … }`` hold one too. A one-field ROS
message (``std_msgs/String``…) stands for its value, so ``answer == "yes"`` works on the output
of ``speech.listen``. :meth:`Expr.type_errors` finds operands of the wrong type before running,
for the keys whose types the module definitions give.

The grammar is :mod:`coordinator.exprparse`, what operators and functions do and how a value is
written :mod:`coordinator.exprfuncs`, the kinds known before running :mod:`coordinator.exprtypes`.
"""
from __future__ import annotations

from typing import Any, Callable, Dict, List, Optional, Set, Tuple

from coordinator.exprfuncs import (
    BRIEF,
    FUNCTIONS,
    MAX_TEXT,
    ExprError,
    apply_function,
    arithmetic,
    brief,
    check_text_size,
    compare,
    described,
    text_of,
)
from coordinator.exprparse import Parser
from coordinator.exprtypes import static_kind
from coordinator.refs import Ref, RefError, check_size, field_of, kind_of, unwrap

__all__ = ["BRIEF", "Expr", "ExprError", "FUNCTIONS", "brief", "MAX_TEXT", "check_text_size", "kind_of", "text_of"]


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
        parsed = Parser(text)
        self.tree: Any = parsed.tree
        self.keys: Set[str] = parsed.keys
        self.refs: List[Ref] = parsed.refs
        self.ref_offsets: List[int] = parsed.ref_offsets   # where each of ``refs`` starts (for error positions)

    def offset_of(self, key: str) -> Optional[int]:
        """Where the first reference to ``key`` starts in the text, None if it reads no such key."""
        return next((at for r, at in zip(self.refs, self.ref_offsets) if r.key == key), None)

    # evaluation
    def evaluate(self, lookup: Callable[[str], Any]) -> bool:
        """Truth of the expression; ``lookup(key)`` raises KeyError for unset keys."""
        return bool(self.value(lookup))

    def value(self, lookup: Callable[[str], Any]) -> Any:
        """The expression's value (a one-field message stands for its value). What Python refuses on the
        values the run holds (``round(nan)``, a number too large for a float) is an ExprError, which fails
        the node that worked it out, never the run."""
        try:
            return unwrap(self._eval(self.tree, lookup))
        except (ValueError, OverflowError, ArithmeticError) as exc:
            raise ExprError(str(exc))

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
                raise ExprError("cannot negate %s" % described(v))
            return -v
        if op == "arith":
            return arithmetic(node[1], unwrap(self._eval(node[2], lookup)), unwrap(self._eval(node[3], lookup)))
        if op == "call":
            if node[1] == "if":   # only the branch chosen: if(len(xs) > 0, at(xs, 0), "nobody") on []
                cond, then, other = node[2]
                return self._eval(then if unwrap(self._eval(cond, lookup)) else other, lookup)
            return apply_function(node[1], [unwrap(self._eval(a, lookup)) for a in node[2]])
        if op == "path":
            return _follow(self._eval(node[1], lookup), node[2], node[4])
        if op == "list":
            items = [unwrap(self._eval(a, lookup)) for a in node[1]]
            try:
                check_size(items)   # [xs, xs] in a loop doubles xs at each run
            except RefError as exc:
                raise ExprError(str(exc))
            return items
        a, b = unwrap(self._eval(node[2], lookup)), unwrap(self._eval(node[3], lookup))
        try:
            return compare(node[1], a, b)
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
        static_kind(self.tree, key_kind, errors)
        if not self.refs:
            self._fixed_errors = list(errors)
            self.well_typed = not errors
        return errors

    def kind(self, key_kind: Callable[[Ref], Optional[str]]) -> Optional[str]:
        """The kind of the expression's value (see :func:`kind_of`) when known before running, else None
        (also when an operand is of the wrong kind: :meth:`type_errors` says that)."""
        return static_kind(self.tree, key_kind, [])


def _follow(value: Any, steps: Tuple[Any, ...], written: str) -> Any:
    """The fields and indexes ``steps`` of ``value``, the result of ``written`` (``at(ps.poses, i)``), read
    as a reference's are, its errors naming the path so far (``at(ps.poses, i).position has no field 'w'``)."""
    for i, step in enumerate(steps):
        try:
            value = field_of(value, step, written + "".join("[%d]" % s if isinstance(s, int) else "." + s
                                                            for s in steps[:i]))
        except RefError as exc:
            raise ExprError(str(exc))
    return value
