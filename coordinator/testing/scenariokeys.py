"""Checks of a scenario file's keys that rest on the module definitions (docs/scenarios.md).

- the top-level ``modules``: the file's own definition files or folders, relative to its folder,
  used when ``bmtree test`` is given no ``--modules`` (which then wins);
- ``expect: calls``, a list (exactly these calls) or ``{in_order: [...]}`` (these calls in this
  order, others may come between), each call checked against the definitions;
- ``expect: duration``, ``{at_least: S, at_most: S}`` in simulated seconds;
- ``expect: cleanup``, ``success`` or ``failure``: how the tree's ``cleanup:`` ended (its calls are
  among ``calls``);
- ``events``: an event's params, every one the definition lists (they get no defaults).

Each problem goes to ``add(pos, message)``, where it is written; every one is reported.
"""
from __future__ import annotations

import json
import os
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple

import yaml

from comm.errors import ProtocolError, did_you_mean
from comm.typewords import said_of
from coordinator.bounds import finite_number, shown
from coordinator.context import RecordStatus
from coordinator.errors import Pos
from coordinator.testing.expected import ExpectedCall, expected_message, want_form
from coordinator.yamlsrc import LList, LMap, pos_of
from modules.definition import DefinitionError, ModuleDefinition, load_definitions
from modules.search import default_definitions

__all__ = ["CALLS_FORMS", "CLEANUP_ENDINGS", "DURATION_KEYS", "ScenarioDefinitions", "check_calls", "check_cleanup",
           "check_duration", "cleanup_problems", "duration_of", "event_problem", "expected_calls", "function_of",
           "listed_calls", "modules_key"]

Add = Callable[[Pos, str], None]
DURATION_KEYS = ("at_least", "at_most")
CALLS_FORMS = ("in_order",)
_CALL = "module.function or {module.function: {input: value}}"
ENDINGS = tuple(str(s) for s in RecordStatus if s is not RecordStatus.RUNNING)


def function_of(defs: Mapping[str, ModuleDefinition], target: Any) -> Tuple[Any, str]:
    """The definition of ``module.function``, or None and why there is none (with a did-you-mean)."""
    mod, dot, name = str(target).partition(".") if isinstance(target, str) else ("", "", "")
    if not dot or not mod or not name:
        return None, "%r is not a module.function" % (target,)
    definition = defs.get(mod)
    if definition is None:
        return None, "no module %r in the definitions%s" % (mod, did_you_mean(mod, defs) or " (known: %s)" % (
            ", ".join(sorted(defs)) or "none"))
    try:
        return definition.function(name), ""
    except ProtocolError as exc:
        return None, str(exc)


# expect: cleanup ---------------------------------------------------------------------------------------
CLEANUP_ENDINGS = ("success", "failure")


def check_cleanup(expect: Any, at: Pos, tree: Any, add: Add) -> None:
    """``expect: cleanup`` is success or failure, for a tree that has a ``cleanup:``."""
    if "cleanup" not in expect:
        return
    value = str(expect["cleanup"]).lower()
    where = pos_of(expect, "cleanup", at)
    if value not in CLEANUP_ENDINGS:
        add(where, "cleanup is success or failure (how the tree's cleanup: ended), got %r%s" % (
            expect["cleanup"], did_you_mean(value, CLEANUP_ENDINGS)))
    elif tree is not None and getattr(tree, "cleanup", None) is None:
        add(where, "expect: cleanup, but %s has no cleanup: (a top-level node run after root)"
            % os.path.basename(str(getattr(tree, "path", "the tree"))))


def cleanup_problems(expect: Any, result: Any) -> List[str]:
    """How the run's cleanup ended against ``expect: cleanup``."""
    if "cleanup" not in expect:
        return []
    want = str(expect["cleanup"]).upper()
    got = result.cleanup_status.value if result.cleanup_status is not None else "not run"
    if got == want:
        return []
    why = " (%s)" % result.cleanup_reason if result.cleanup_reason else ""
    return ["cleanup %s, expected %s%s" % ("cut short" if got == "INVALID" else got, want, why)]


# expect: calls ----------------------------------------------------------------------------------------
def listed_calls(expect: Any) -> Tuple[Any, Any, Optional[Pos]]:
    """``expect: calls`` as (the list of calls, the container holding it, its key there): the list
    itself, or the ``in_order`` list of ``{in_order: [...]}``; an empty list when there is none, or
    when it is not a list (one error, by :func:`check_calls`, not one for each character of a text)."""
    calls = expect.get("calls")
    if isinstance(calls, dict) and "in_order" in calls:
        listed = calls.get("in_order")
        return listed if isinstance(listed, list) else [], calls, "in_order"
    return (calls if isinstance(calls, list) else []), expect, "calls"


def check_calls(expect: Any, at: Pos, add: Add) -> None:
    """The form of ``expect: calls``: a list of calls, or a mapping ``{in_order: [calls]}``."""
    calls = expect.get("calls")
    if calls is None or isinstance(calls, list):
        if not all(want_form(c) for c in calls or []):
            add(pos_of(expect, "calls", at), "calls is a list of %s" % _CALL)
        return
    c_at = pos_of(expect, "calls", at)
    if not isinstance(calls, dict):
        add(c_at, "calls is a list of %s (exactly the calls made), or {in_order: [such calls]} (these calls in this "
                  "order, others may come between), got %r" % (_CALL, calls))
        return
    if not calls:
        add(c_at, "calls {} lists no call: write calls: {in_order: [calls]}, or calls: [] for a run that makes none")
    for k in calls:
        if k not in CALLS_FORMS:
            add(calls.key_pos[k] if isinstance(calls, LMap) else c_at, "unknown calls key %r%s: calls is a list of "
                "calls, or {in_order: [calls]}" % (k, did_you_mean(k, CALLS_FORMS)))
    if "in_order" not in calls:
        return
    listed = calls["in_order"]
    o_at = pos_of(calls, "in_order", c_at)
    if not isinstance(listed, list) or not listed:
        one = ": write one call as a list of one, in_order: %s" % _flow([listed]) if want_form(listed) else ""
        add(o_at, "calls in_order is a list of the calls made in this order (%s), at least one; got %r%s" % (
            _CALL, listed, one))
        return
    for j, c in enumerate(listed):
        if not want_form(c):
            add(pos_of(listed, j, o_at), "calls in_order: call %d is not %s, got %r" % (j + 1, _CALL, c))


def _flow(value: Any) -> str:
    """``value`` as YAML in flow style, on one line (``[{speech.say: {text: hi}}]``)."""
    plain = json.loads(json.dumps(value, default=str))   # (the loader's mappings are not plain dicts)
    return yaml.safe_dump(plain, default_flow_style=True, width=float("inf")).strip()


def expected_calls(expect: Any, at: Pos, defs: Mapping[str, ModuleDefinition], add: Add) -> List[ExpectedCall]:
    """``expect: calls`` (either form) checked against the definitions: each a function of a
    module, each input one it has, of a value that fits its type."""
    calls, holder, key = listed_calls(expect)
    found = []
    for j, c in enumerate(calls):
        if not want_form(c):
            continue  # said by check_calls
        c_at = calls.item_pos[j] if isinstance(calls, LList) else pos_of(holder, key, at)
        want = ExpectedCall(c)
        found.append(want)
        _check_ending(c, c_at, add)
        fn, why = function_of(defs, want.target)
        if fn is None:
            add(c.key_pos.get(want.target, c_at) if isinstance(c, LMap) else c_at, "expected call: %s" % why)
            continue
        inputs = c[want.target] if isinstance(c, dict) else None
        params = {q.name: q for q in fn.inputs}
        for name, value in want.inputs.items():
            q = params.get(name)
            if q is None:
                add(inputs.key_pos[name] if isinstance(inputs, LMap) else c_at, "%s has no input %r%s" % (
                    fn.qualified, name, did_you_mean(name, params) or " (its inputs: %s)" % (", ".join(params) or "none")))
                continue
            try:
                want.built[name] = expected_message(q.rostype, value)
            except ProtocolError as exc:
                add(inputs.val_pos[name] if isinstance(inputs, LMap) else c_at,
                    said_of("%s input %r" % (fn.qualified, name), exc))
    return found


def _check_ending(c: Any, at: Pos, add: Add) -> None:
    """An expected call's ``status:`` (one a call ends with) and ``error:`` (text)."""
    if not isinstance(c, dict):
        return
    if "status" in c and str(c["status"]) not in ENDINGS:
        add(c.val_pos["status"] if isinstance(c, LMap) else at, "status of an expected call is how it ended: one of "
            "%s, got %r%s" % (", ".join(ENDINGS), c["status"], did_you_mean(str(c["status"]), ENDINGS)))
    if "error" in c and not isinstance(c["error"], str):
        add(c.val_pos["error"] if isinstance(c, LMap) else at, "error of an expected call is a text its error must "
            "contain (\"blocked\"), got %r" % (c["error"],))


# events -----------------------------------------------------------------------------------------------
def event_problem(said: str, event: Any, params: Mapping[str, Any]) -> str:
    """What is wrong with an event of ``events`` (``said``: the kit's words), with the rule when a param
    is missing: an event gives every param of ``event`` (its definition), as a module's ``emit`` and
    ``t.mocks.event`` must; a mock's outputs get defaults, an event's params do not."""
    if event is None or all(q.name in params for q in event.params):
        return said
    return ("%s: an event gives every param its definition lists (%s), as a module's emit and t.mocks.event must; "
            "unlike a mock's outputs, params get no defaults" % (said, ", ".join(q.name for q in event.params)))


# expect: duration -----------------------------------------------------------------------------------
def _seconds(value: Any) -> bool:
    return finite_number(value) and value >= 0


def check_duration(expect: Any, at: Pos, add: Add) -> None:
    """``expect: duration``: ``{at_least: S, at_most: S}`` (either or both), simulated seconds."""
    if "duration" not in expect:
        return
    raw, d_at = expect["duration"], pos_of(expect, "duration", at)
    if not isinstance(raw, dict) or not raw:
        add(d_at, "duration is a mapping of at_least and/or at_most, in simulated seconds ({at_most: 30}), got %r" % (
            raw,))
        return
    for k, v in raw.items():
        if k not in DURATION_KEYS:
            add(raw.key_pos[k] if isinstance(raw, LMap) else d_at, "unknown duration key %r%s: duration takes "
                "at_least and/or at_most (simulated seconds)" % (k, did_you_mean(k, DURATION_KEYS)))
        elif not _seconds(v):
            add(pos_of(raw, k, d_at), "duration %s must be a number of seconds >= 0, got %s" % (k, shown(v)))
    low, high = raw.get("at_least"), raw.get("at_most")
    if _seconds(low) and _seconds(high) and low > high:
        add(d_at, "duration at_least %g is above at_most %g: no run can pass" % (low, high))


def duration_of(expect: Any) -> Dict[str, float]:
    """The bounds of a checked ``expect: duration`` (empty: not checked)."""
    raw = expect.get("duration") or {}
    return {k: float(raw[k]) for k in DURATION_KEYS if k in raw}


# modules: the file's own definitions ------------------------------------------------------------------
def modules_key(data: LMap, path: str, top: Pos, add: Add) -> List[Tuple[str, Pos]]:
    """The definition files and folders the top-level ``modules`` names (one path or a list of
    them, each relative to the scenario file's folder), with where each is written; each must be
    a file or a folder."""
    if "modules" not in data:
        return []
    raw, m_at = data["modules"], pos_of(data, "modules", top)
    what = ("modules is the path of a module definition file or folder, or a list of them (relative to the "
            "scenario file's folder)")
    if raw is None or raw == []:
        add(m_at, "%s; it is empty: leave the key out for the default definitions" % what)
        return []
    if isinstance(raw, str):
        items, positions = [raw], [m_at]
    elif isinstance(raw, list):
        items, positions = list(raw), [pos_of(raw, j, m_at) for j in range(len(raw))]
    else:
        add(m_at, "%s, got %r" % (what, raw))
        return []
    base = os.path.dirname(os.path.abspath(path))
    found = []
    for item, where in zip(items, positions):
        if not isinstance(item, str) or not item.strip():
            add(where, "%s: got %r" % (what, item))
            continue
        full = os.path.normpath(os.path.join(base, item))
        if not os.path.exists(full):
            add(where, "modules %s: no such file or folder (relative paths are from the scenario file's folder)" % full)
        elif not os.path.isfile(full) and not os.path.isdir(full):
            add(where, "modules %s: not a definition file or folder" % full)
        else:
            found.append((full, where))
    return found


class ScenarioDefinitions:
    """The module definitions the scenario files of one ``bmtree test`` run with: ``given`` ones
    (``--modules``: every file gets them, its own ``modules`` key is only checked), else the default
    ones (the simulated robot's, the ROS packages', ``$BMTREE_MODULE_PATH``'s) with each file's
    own ``modules`` over them, as ``--modules`` would add them. Each list of paths is loaded once."""

    def __init__(self, given: Optional[Mapping[str, ModuleDefinition]] = None):
        self.given = dict(given) if given is not None else None
        self._defaults: Optional[Dict[str, ModuleDefinition]] = None
        self._loaded: Dict[Tuple[str, ...], Dict[str, ModuleDefinition]] = {}

    def of(self, named: List[Tuple[str, Pos]], add: Add) -> Optional[Dict[str, ModuleDefinition]]:
        """The definitions for a file whose ``modules`` key names ``named`` (checked by
        :func:`modules_key`); None after a problem of those definitions (each at its path)."""
        if self.given is not None:
            return self.given
        key = tuple(p for p, _ in named)
        if key in self._loaded:
            return self._loaded[key]
        if self._defaults is None:
            self._defaults = default_definitions()  # its own problems are a DefinitionError, as with no key
        own: Dict[str, ModuleDefinition] = {}
        bad = False
        for p, where in named:
            try:
                found = load_definitions([p])
            except DefinitionError as exc:
                bad = True
                for problem in exc.problems:
                    add(where, "modules: %s" % problem)
                continue
            if not found:
                bad = True
                add(where, "modules %s: no module definition (.json file) in this folder" % p)
            for name, d in found.items():
                if name in own and os.path.realpath(own[name].source) != os.path.realpath(d.source):
                    bad = True
                    add(where, "modules: module %r is defined twice: in %s and %s" % (name, own[name].source, d.source))
                own[name] = d
        if bad:
            return None
        defs = dict(self._defaults)
        defs.update(own)
        self._loaded[key] = defs
        return defs
