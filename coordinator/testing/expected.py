"""A scenario's expected values against what the run made: normalised, and only what is listed.

An expected value is converted to the ROS type of the value it is compared with (a call's input
has the type its definition gives; a message on the tree blackboard its own), the way the tree
converts what it sends, so every form the tree accepts matches:

- ``uint8[]``: a list of numbers, bytes, or base64 text (the form run logs record) are the same bytes;
- ``time``/``duration``: ``{secs: S, nsecs: N}``, seconds, or the nanosecond text (``"100000000000"``)
  that scenarios written from older run logs hold;
- a one-field message: its value (``text: hello`` for a ``std_msgs/String``).

Inside a message only the fields listed are compared, at any depth: ``{pose: {position: {x: 0.5}}}``
checks ``x`` and ignores the rest, as ``expect: calls`` ignores the inputs it does not list. A list
compares whole (its length, then each element, an element's listed fields); a time, a number and
text compare whole. Plain data (a tree key written by ``set``) compares the same way: a mapping
on the keys it lists.
"""
from __future__ import annotations

import json
import re
from typing import Any, Dict, List, NamedTuple, Optional

import genpy

from comm.errors import ProtocolError
from comm.rostypes import resolve_type, single_field, to_message
from coordinator.context import plain

__all__ = ["Difference", "ExpectedCall", "calls_diff", "difference", "expect_calls", "expect_calls_in_order",
           "expect_duration", "expected_message", "legacy_times", "shown", "want_form", "ENDING_KEYS", "ending_of"]

_NANOSECONDS = re.compile(r"^-?[0-9]+$")
_TIMES = ("time", "duration")


class Difference(NamedTuple):
    """Where an actual value differs from the expected one: ``path`` inside it (``''``: the whole
    value, ``position.x``, ``poses[1].position``), the actual and expected values there, and why
    the expected value could not be compared, if so."""

    path: str
    got: Any
    want: Any
    why: str = ""

    def said(self, subject: str) -> str:
        """``input pose.position.x is 0.4, expected 0.5`` (``subject`` names the whole value)."""
        where = subject + ("" if not self.path else self.path if self.path.startswith("[") else "." + self.path)
        if self.why:
            return "%s is %r, expected %r, which %s" % (where, shown(self.got), self.want, self.why)
        if self.got is _MISSING:
            return "%s is not there (expected %r)" % (where, self.want)
        return "%s is %r, expected %r" % (where, shown(self.got), self.want)


_MISSING = object()


def shown(value: Any) -> Any:
    """A value as plain data for a message: messages as mappings, times as ``{secs, nsecs}``,
    bytes as a list of numbers."""
    if isinstance(value, genpy.Message) or isinstance(value, genpy.TVal):
        value = plain(value)
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [shown(v) for v in value]
    if isinstance(value, dict):
        return {k: shown(v) for k, v in value.items()}
    return value


def _time(text: str, kind: str) -> Dict[str, int]:
    t = (genpy.Duration if kind == "duration" else genpy.Time)(0, int(text))
    return {"secs": t.secs, "nsecs": t.nsecs}


def _legacy_field(t: str, value: Any) -> Any:
    base = t.split("[", 1)[0]
    if t.endswith("]"):
        if isinstance(value, (list, tuple)) and (base in _TIMES or "/" in base):
            return [_legacy_field(base, v) for v in value]
        return value
    if base in _TIMES:
        return _time(value, base) if isinstance(value, str) and _NANOSECONDS.match(value) else value
    if "/" in base and isinstance(value, dict):
        return legacy_times(base, value)
    return value


def legacy_times(rostype: str, value: Any) -> Any:
    """``value`` for a ``rostype`` with the nanosecond texts at its times (what run logs recorded
    for a ``std_msgs/Time`` before they wrote ``{secs, nsecs}``) made ``{secs, nsecs}``; the rest
    unchanged."""
    cls = resolve_type(rostype)
    if cls is None:
        return value
    slots, types = getattr(cls, "__slots__", ()), getattr(cls, "_slot_types", ())
    if not isinstance(value, dict) or not set(value) <= set(slots):
        field = single_field(cls)
        return _legacy_field(types[0], value) if field is not None else value
    return {k: _legacy_field(types[slots.index(k)], v) for k, v in value.items()}


def expected_message(rostype: str, value: Any) -> Any:
    """``value`` as a message of ``rostype``, as the tree would send it (ProtocolError if it is none)."""
    return to_message(rostype, legacy_times(rostype, value), allow_scalar=True)


def _same(a: Any, b: Any) -> bool:
    return _norm(a) == _norm(b)


def _norm(v: Any) -> Any:
    if isinstance(v, genpy.Message):
        return {k: _norm(getattr(v, k)) for k in v.__slots__}
    if isinstance(v, genpy.TVal):
        return (v.secs, v.nsecs)
    if isinstance(v, (bytes, bytearray)):
        return list(v)
    if isinstance(v, (list, tuple)):
        return [_norm(x) for x in v]
    if isinstance(v, dict):
        return {k: _norm(x) for k, x in v.items()}
    return v


def _join(path: str, step: Any) -> str:
    if isinstance(step, int):
        return "%s[%d]" % (path, step)
    return "%s.%s" % (path, step) if path else str(step)


def _walk(built: Any, got: Any, want: Any, path: str) -> Optional[Difference]:
    """``got`` against ``built`` (``want`` converted), on the fields ``want`` lists."""
    if isinstance(got, genpy.Message) and isinstance(want, dict) and set(want) <= set(got.__slots__):
        for k in got.__slots__:  # in the message's order: the first difference is the first field
            if k in want:
                d = _walk(getattr(built, k), getattr(got, k), want[k], _join(path, k))
                if d is not None:
                    return d
        return None
    if isinstance(want, (list, tuple)) and isinstance(got, (list, tuple)) and isinstance(built, (list, tuple)):
        if len(want) != len(got) or len(built) != len(got):
            return Difference(path, got, want)
        for i, (b, g, w) in enumerate(zip(built, got, want)):
            d = _walk(b, g, w, _join(path, i))
            if d is not None:
                return d
        return None
    return None if _same(built, got) else Difference(path, got, want)


def difference(want: Any, got: Any, built: Any = None, path: str = "") -> Optional[Difference]:
    """None when ``got`` (a message or plain data) has what ``want`` lists, else the first difference.

    ``built``: ``want`` already converted to ``got``'s type (:func:`expected_message`), or the
    ProtocolError that conversion raised; made here when not given."""
    if isinstance(got, genpy.Message):
        if built is None:
            try:
                built = expected_message(got._type, want)
            except ProtocolError as exc:
                built = exc
        if isinstance(built, ProtocolError):
            return Difference(path, got, want, "is no %s: %s" % (got._type, built))
        return _walk(built, got, want, path)
    if isinstance(got, genpy.TVal):  # a time compares whole
        return None if _as_time(want, got) == (got.secs, got.nsecs) else Difference(path, got, want)
    g = got
    if isinstance(want, dict) and isinstance(g, dict):
        for k, w in want.items():
            if k not in g:
                return Difference(_join(path, k), _MISSING, w)
            d = difference(w, g[k], path=_join(path, k))
            if d is not None:
                return d
        return None
    if isinstance(want, (list, tuple)) and isinstance(g, (list, tuple)):
        if len(want) != len(g):
            return Difference(path, got, want)
        for i, (w, x) in enumerate(zip(want, g)):
            d = difference(w, x, path=_join(path, i))
            if d is not None:
                return d
        return None
    return None if _same(want, g) else Difference(path, got, want)


def _as_time(want: Any, like: Any) -> Any:
    """``want`` as ``(secs, nsecs)`` of the kind of ``like`` (a time or a duration), None if it is none."""
    kind = type(like)
    try:
        if isinstance(want, dict) and want and set(want) <= {"secs", "nsecs"}:
            t = kind(want.get("secs", 0), want.get("nsecs", 0))
        elif isinstance(want, (int, float)) and not isinstance(want, bool):
            t = kind.from_sec(want)
        elif isinstance(want, str) and _NANOSECONDS.match(want):
            t = kind(0, int(want))
        else:
            return None
    except (TypeError, ValueError, OverflowError):
        return None
    return (t.secs, t.nsecs)


ENDING_KEYS = ("status", "error")
"""What an expected call may say of how it ended, beside its ``module.function`` key."""


def want_form(c: Any) -> bool:
    """An expected call: ``module.function`` or ``{module.function: {input: value}}``, the mapping maybe
    with ``status:`` and ``error:`` beside it (how the call ended)."""
    if isinstance(c, str):
        return True
    if not isinstance(c, dict):
        return False
    targets = [k for k in c if k not in ENDING_KEYS]
    return len(targets) == 1 and isinstance(targets[0], str) and isinstance(c[targets[0]], (dict, type(None)))


def _want(want: Any) -> Any:
    if isinstance(want, str):
        return want, {}
    target = next(k for k in want if k not in ENDING_KEYS)
    return target, want[target]


def ending_of(call: Any) -> str:
    """How a made call ended, as a diff line shows it: ``failed: blocked``."""
    return "%s: %s" % (call.status, call.error) if call.error else str(call.status)


class ExpectedCall:
    """One call of ``expect: calls``: its ``module.function`` and the inputs it lists (as written),
    compared normalised (:mod:`coordinator.testing.expected`): each converted once to the type of
    the input it is compared with, and only the fields it lists."""

    def __init__(self, raw: Any):
        self.target, inputs = _want(raw)
        self.inputs: Dict[str, Any] = dict(inputs or {})
        self.built: Dict[str, Any] = {}  # input -> the value as a message of the input's type, or the ProtocolError
        ending = raw if isinstance(raw, dict) else {}
        self.status: Optional[str] = None if ending.get("status") is None else str(ending["status"])
        self.error: Optional[str] = None if ending.get("error") is None else str(ending["error"])  # text it contains

    @property
    def ending(self) -> str:
        """What it says of how the call ended, as a diff line shows it ('' when nothing)."""
        parts = ([str(self.status)] if self.status is not None else []) + (
            ["error containing %s" % json.dumps(self.error, ensure_ascii=False)] if self.error is not None else [])
        return ", ".join(parts)

    def ending_difference(self, call: Any) -> str:
        """How the made ``call`` ended otherwise than this one says ('' when it did not)."""
        said = []
        if self.status is not None and str(call.status) != self.status:
            said.append("it ended %s, expected %s" % (ending_of(call), self.status))
        if self.error is not None and self.error not in (call.error or ""):
            said.append("its error is %s, expected one containing %s" % (
                json.dumps(call.error or "", ensure_ascii=False), json.dumps(self.error, ensure_ascii=False)))
        return "; ".join(said)

    def difference(self, name: str, got: Any) -> Optional[Difference]:
        """How the made call's input ``name`` (a message) differs from this one's, if it does."""
        if name not in self.built and isinstance(got, genpy.Message):
            try:
                self.built[name] = expected_message(got._type, self.inputs[name])
            except ProtocolError as exc:
                self.built[name] = exc
        return difference(self.inputs[name], got, self.built.get(name))

    def matches(self, call: Any) -> bool:
        """The made ``call`` (a CallRecord) is this one."""
        return call.target == self.target and all(
            k in call.messages and self.difference(k, call.messages[k]) is None for k in self.inputs
        ) and not self.ending_difference(call)

    def show(self) -> str:
        return _show(self.target, self.inputs, self.ending)


def _show(target: str, inputs: Any, ending: str = "") -> str:
    """A call on a diff line: the inputs in name order, each as written or as plain data (times
    ``{"secs": S, "nsecs": N}``), so an expected and a made call read alike; then how it ended, when
    the expected calls say it (``(failed: blocked)``)."""
    shown = target
    if inputs:
        shown += " " + json.dumps({k: inputs[k] for k in sorted(inputs, key=str)}, ensure_ascii=False, default=str)
    return shown + (" (%s)" % ending if ending else "")


def _made(call: Any, want: List[ExpectedCall]) -> str:
    """A made call on a diff line: with how it ended when an expected call says how one must."""
    return _show(call.target, call.inputs, ending_of(call) if any(w.ending for w in want) else "")


def calls_diff(expected: List[Any], actual: List[Any]) -> List[str]:
    """Expected vs actual calls as a diff: ``  =`` same, ``  -`` expected only, ``  +`` made only.
    ``expected``: ExpectedCall objects or the written forms."""
    want = [e if isinstance(e, ExpectedCall) else ExpectedCall(e) for e in expected]
    n, m = len(want), len(actual)
    head = 0  # the common start and end are matched in a line; the longest common subsequence in between
    while head < min(n, m) and want[head].matches(actual[head]):
        head += 1
    tail = 0
    while tail < min(n, m) - head and want[n - 1 - tail].matches(actual[m - 1 - tail]):
        tail += 1
    mid_w, mid_a = want[head:n - tail], actual[head:m - tail]
    n2, m2 = len(mid_w), len(mid_a)
    lcs = [[0] * (m2 + 1) for _ in range(n2 + 1)]
    same = [[False] * m2 for _ in range(n2)]
    for i in range(n2 - 1, -1, -1):
        for j in range(m2 - 1, -1, -1):
            if mid_w[i].matches(mid_a[j]):
                same[i][j] = True
                lcs[i][j] = lcs[i + 1][j + 1] + 1
            else:
                lcs[i][j] = max(lcs[i + 1][j], lcs[i][j + 1])
    out = ["  = %s" % w.show() for w in want[:head]]
    i, j = 0, 0
    while i < n2 or j < m2:
        if i < n2 and j < m2 and same[i][j]:
            out.append("  = %s" % mid_w[i].show())
            i, j = i + 1, j + 1
        elif j < m2 and (i == n2 or lcs[i][j + 1] >= lcs[i + 1][j]):
            out.append("  + %s" % _made(mid_a[j], want))
            j += 1
        else:
            out.append("  - %s" % mid_w[i].show())
            i += 1
    out.extend("  = %s" % w.show() for w in want[n - tail:])
    return out


def expect_calls(run: Any, expected: List[ExpectedCall]) -> List[str]:
    """What differs between the calls a run made (a TreeRun) and ``expect: calls``."""
    problems = []
    actual = run.calls()
    if len(actual) != len(expected):
        problems.append("expected %d calls, got %d: %s" % (len(expected), len(actual), ", ".join(run.targets)))
    for i, (want, got) in enumerate(zip(expected, actual)):
        if got.target != want.target:
            problems.append("call %d: expected %s, got %s" % (i + 1, want.target, got.target))
            continue
        for k in want.inputs:
            if k not in got.messages:
                problems.append("call %d (%s): it has no input %r" % (i + 1, want.target, k))
                continue
            d = want.difference(k, got.messages[k])
            if d is not None:
                problems.append("call %d (%s): %s" % (i + 1, want.target, d.said("input %s" % k)))
        ended = want.ending_difference(got)
        if ended:
            problems.append("call %d (%s): %s" % (i + 1, want.target, ended))
    if problems:
        problems.append("calls changed (- expected only, + made only, = both):")
        problems.extend(calls_diff(expected, actual))
    return problems


def _first_difference(want: ExpectedCall, call: Any) -> str:
    """How a made call of ``want``'s function differs from it: its first input that does not match."""
    for k in want.inputs:
        if k not in call.messages:
            return "it has no input %r" % k
        d = want.difference(k, call.messages[k])
        if d is not None:
            return d.said("input %s" % k)
    return want.ending_difference(call)


def _not_found(k: int, expected: List[ExpectedCall], actual: List[Any], after: Optional[int],
               matched: Dict[int, int]) -> List[str]:
    """Why ``expected[k]`` was not found after the made call ``after`` (None: from the start), with
    what the run did instead: its calls of that function after, or only before, that call."""
    want = expected[k]
    head = "calls in order: expected call %d of %d, %s, not found " % (k + 1, len(expected), want.show())
    if after is None:
        return [head + "from the start of the run"] + _instead(want, actual, 0, matched)
    got = actual[after]
    head += "after call %d, %s (which matched expected call %d)" % (after + 1, _made(got, expected), matched[after] + 1)
    return [head] + _instead(want, actual, after + 1, matched)


def _instead(want: ExpectedCall, actual: List[Any], start: int, matched: Dict[int, int]) -> List[str]:
    """What the run did instead of ``want`` after call ``start`` (1-based; 0: from the start): its
    calls of that function and how each differs (the first three); a matching call up to call
    ``start`` (the order differs), or that the function was called only before, or never."""
    later = [i for i in range(start, len(actual)) if actual[i].target == want.target]
    said = ["  call %d (%s): %s" % (i + 1, want.target, _first_difference(want, actual[i])) for i in later[:3]]
    if len(later) > 3:
        said.append("  and %d more %s call%s" % (len(later) - 3, want.target, "s" if len(later) > 4 else ""))
    earlier = [i for i in range(start) if actual[i].target == want.target]
    same = [i for i in earlier if want.matches(actual[i])]
    if same:
        i = same[-1]
        said.append("  call %d matches it, but %s" % (i + 1, "it is not after call %d: the order differs" % start
                    if i + 1 < start else "it is expected call %d already: each made call matches one expected call"
                    % (matched[i] + 1)))
    elif earlier and not later:
        said.append("  %s was called only up to call %d: call%s %s" % (
            want.target, start, "s" if len(earlier) > 1 else "", ", ".join(str(i + 1) for i in earlier)))
    if not earlier and not later:
        said.append("  the run made no %s call" % want.target)
    return said


def expect_calls_in_order(run: Any, expected: List[ExpectedCall]) -> List[str]:
    """What is missing of ``expect: calls: {in_order: [...]}``: each expected call must be made after
    the made call that matched the one before it (the first: from the start of the run); other
    calls may come between. Each expected call is matched with the earliest made call that fits,
    and one not found is said with the made call it was looked for after; the next expected call
    is then looked for after that same call."""
    actual = run.calls()
    matched: Dict[int, int] = {}    # made call -> the expected call it matched
    missing: Dict[Optional[int], List[int]] = {}   # made call (None: the start) -> expected calls not found after it
    problems: List[str] = []
    after: Optional[int] = None
    for k, want in enumerate(expected):
        start = 0 if after is None else after + 1
        found = next((i for i in range(start, len(actual)) if want.matches(actual[i])), None)
        if found is None:
            problems.extend(_not_found(k, expected, actual, after, matched))
            missing.setdefault(after, []).append(k)
            continue
        matched[found] = k
        after = found
    if not problems:
        return []
    problems.append("calls made (= matched an expected call; - an expected call not found after the call above; "
                    "the others may come between):")
    lines = ["  - %s" % expected[k].show() for k in missing.get(None, [])]
    for i, c in enumerate(actual):
        lines.append("  %s %d %s" % ("=" if i in matched else " ", i + 1, _made(c, expected)))
        lines.extend("  - %s" % expected[k].show() for k in missing.get(i, []))
    return problems + lines


def expect_duration(duration: float, bounds: Dict[str, float]) -> List[str]:
    """``expect: duration``: the run's simulated seconds against ``at_least`` and ``at_most``."""
    problems = []
    if "at_least" in bounds and duration < bounds["at_least"] - 1e-9:
        problems.append("duration %g s (simulated), expected at least %g s" % (duration, bounds["at_least"]))
    if "at_most" in bounds and duration > bounds["at_most"] + 1e-9:
        problems.append("duration %g s (simulated), expected at most %g s" % (duration, bounds["at_most"]))
    return problems
