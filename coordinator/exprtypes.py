"""What an expression's values will be, known before running: the kind of each operand, and the
operands that cannot fit (with the fix when it is plain), for the tree's checks.
"""
from __future__ import annotations

import re
from typing import Any, Callable, List, Optional, Tuple

from coordinator.exprfuncs import FUNCTIONS, ORDER, VERB, decimals_problem, list_hint, text_of
from coordinator.keykinds import KIND_WORDS
from coordinator.refs import Ref, kind_of

__all__ = ["never_true", "static_kind"]


def static_kind(node: Any, key_kind: Callable[[Ref], Optional[str]],
                errors: List[Tuple[int, str]]) -> Optional[str]:
    """The kind of ``node``'s value (a node of a :class:`~coordinator.exprparse.Parser` tree) when known,
    after recording misfits below it."""
    op = node[0]
    if op == "lit":
        return kind_of(node[1])
    if op == "list":
        for item in node[1]:
            static_kind(item, key_kind, errors)
        return "list"
    if op == "ref":
        return key_kind(node[1])
    if op in ("and", "or"):
        static_kind(node[1], key_kind, errors)
        static_kind(node[2], key_kind, errors)
        return None
    if op == "not":
        static_kind(node[1], key_kind, errors)
        return "bool"
    if op == "neg":
        k = static_kind(node[1], key_kind, errors)
        if k is not None and k != "number":
            errors.append((node[2], "cannot negate a %s" % k))
        return "number"
    if op == "arith":
        a, b = static_kind(node[2], key_kind, errors), static_kind(node[3], key_kind, errors)
        if node[1] != "+" and (a or b) not in (None, "number") and (a is None or b is None):
            known = a or b   # - * / take numbers only: one side is enough to know it fails
            errors.append((node[4], "cannot %s %s: '%s' takes numbers%s" % (
                VERB[node[1]], "a %s and a value" % known if a else "a value and a %s" % known, node[1],
                " (a list has no '-': build the list you want, e.g. with for_each and set)" if known == "list" else "")))
            return None
        if a is None or b is None:
            return None
        if node[1] == "+" and a == b and a in ("string", "list"):
            return a
        if a != "number" or b != "number":
            errors.append((node[4], "cannot %s a %s and a %s%s" % (VERB[node[1]], a, b, list_hint(node[1], a, b))))
            return None
        return "number"
    if op == "path":
        return _path_kind(node, key_kind, errors)
    if op == "call":
        name, args, at = node[1], node[2], node[3]
        if name == "if":   # either branch may be the value: its kind is known when they agree
            static_kind(args[0], key_kind, errors)
            then, other = static_kind(args[1], key_kind, errors), static_kind(args[2], key_kind, errors)
            return then if then == other else None
        if name == "at":
            kinds = [static_kind(arg, key_kind, errors) for arg in args]
            if kinds[0] not in (None, "list", "string"):
                errors.append((at, "at() takes a list or a string first, not a %s" % kinds[0]))
            if len(kinds) > 1 and kinds[1] not in (None, "number"):
                errors.append((at, "at() takes a number as position, not a %s" % kinds[1]))
            if kinds[0] == "string":
                return "string"   # a character
            element = _typed_as(node)   # at(ps.poses, i) holds what ps.poses[0] does
            return None if element is None else key_kind(element)
        if name == "round" and len(args) > 1 and args[1][0] == "lit" and kind_of(args[1][1]) == "number":
            why = decimals_problem(args[1][1])
            if why:
                errors.append((at, why))
        if name == "join":
            kinds = [static_kind(arg, key_kind, errors) for arg in args]
            if kinds[0] not in (None, "list"):
                errors.append((at, "join() takes a list first, not a %s" % kinds[0]))
            if len(kinds) > 1 and kinds[1] not in (None, "string"):
                errors.append((at, "join() takes text as separator, not a %s" % kinds[1]))
            return "string"
        want = FUNCTIONS[name][1]
        for arg in args:
            k = static_kind(arg, key_kind, errors)
            if k is None:
                continue
            if (want and k != want) or (name == "len" and k not in ("string", "list")):
                errors.append((at, "%s() takes a %s, not a %s" % (name, want or "string or a list", k)))
        return FUNCTIONS[name][2]
    a, b = static_kind(node[2], key_kind, errors), static_kind(node[3], key_kind, errors)
    if node[1] in ORDER and a is not None and b is not None and a != b:
        errors.append((node[4], "cannot compare a %s %s a %s" % (a, node[1], b)))
    elif node[1] in ("==", "!=") and ({a, b} == {"number", "string"} or {a, b} == {"bool", "string"}):
        fix = _as_truth(node) if "bool" in (a, b) else ""
        errors.append((node[4], "a %s %s a %s is always %s%s" % (
            a, node[1], b, "false" if node[1] == "==" else "true",
            fix or _as_other(node[2]) or _as_other(node[3]))))
    return "bool"


def _typed_as(node: Any) -> Optional[Ref]:
    """The reference whose value's type ``node``'s value has, if any: a reference, an element of one
    (``at(ps.poses, i)`` is of the type of ``ps.poses[0]``, whatever ``i``), a field of those."""
    if node[0] == "ref":
        return node[1]
    if node[0] == "call" and node[1] == "at":
        seq = _typed_as(node[2][0])
        return None if seq is None else Ref(seq.key, seq.path + (0,))
    if node[0] == "path":
        base = _typed_as(node[1])
        return None if base is None else Ref(base.key, base.path + node[2])
    return None


def _path_kind(node: Any, key_kind: Callable[[Ref], Optional[str]], errors: List[Tuple[int, str]]) -> Optional[str]:
    """The kind of ``value.field`` / ``value[i]`` after a function's result or a parenthesised expression
    (a ``path`` node), after recording a first step that a value of the kind known cannot have."""
    base, steps, at, written = node[1], node[2], node[3], node[4]
    kind = static_kind(base, key_kind, errors)
    step = steps[0]
    reads = written + ("[%d]" % step if isinstance(step, int) else "." + step)
    if isinstance(step, int) and (kind in ("number", "bool") or kind == "message" and _typed_as(base) is not None):
        errors.append((at, "reads %s, but %s is %s, which is not a list" % (reads, written, KIND_WORDS[kind])))
        return None
    # a key's value, an element of it or if()'s may be a one-field message, whose field may be read (heard.data)
    plain = base[0] not in ("ref", "path") and not (base[0] == "call" and base[1] in ("at", "if"))
    if not isinstance(step, int) and plain and kind in ("number", "bool", "string", "list"):
        errors.append((at, "reads %s, but %s is %s, which has no fields%s" % (
            reads, written, KIND_WORDS[kind], " (an element is %s[0])" % written if kind == "list" else "")))
        return None
    if kind == "string" and all(isinstance(s, int) for s in steps):
        return "string"   # a character
    typed = _typed_as(node)
    return None if typed is None else key_kind(typed)


def never_true(node: Any, why_not: Callable[[str, str, bool], str], errors: List[Tuple[int, str]]) -> None:
    """Each comparison of a key with text that its value can never pass (``st == "timed_out"`` where ``st``
    is a call's status): ``why_not(key, text, contains)`` says why ``$key`` is never ``text`` (``contains``:
    never contains it, for ``"text" in st``), '' when it may be or that is not known."""
    op = node[0]
    if op in ("lit", "ref"):
        return
    if op == "cmp":
        cmp, left, right = node[1], node[2], node[3]
        sides = (left, right) if left[0] == "ref" else (right, left)
        ref, text = sides
        pair = ref[0] == "ref" and not ref[1].path and text[0] == "lit" and isinstance(text[1], str)
        if pair and (cmp in ("==", "!=") or (cmp == "in" and right is ref)):
            why = why_not(ref[1].key, text[1], cmp == "in")
            if why:
                written = "%s %s %s" % (_written(left), cmp, _written(right))
                errors.append((node[4], "%s is always %s: %s" % (written, "true" if cmp == "!=" else "false", why)))
            return
        never_true(left, why_not, errors)
        never_true(right, why_not, errors)
        return
    if op in ("call", "list"):
        for arg in node[2 if op == "call" else 1]:
            never_true(arg, why_not, errors)
        return
    if op == "path":
        never_true(node[1], why_not, errors)
        return
    for child in node[1:]:   # and, or, not, neg, arith: their operands are tuples
        if isinstance(child, tuple):
            never_true(child, why_not, errors)


def _written(node: Any) -> str:
    """A reference or a text literal as an expression writes it."""
    return str(node[1])[1:] if node[0] == "ref" else _quoted(node[1])


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
