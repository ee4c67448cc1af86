"""YAML test scenarios for ``bmtree test``: module scripts, expected calls, expected status.

    tree: ../trees/find_apple.yaml
    scenarios:
      - name: apple in the kitchen
        inputs: {object: apple}
        mocks:
          vision.find_object:
            - succeed: {success: false}
            - succeed: {success: true, position: {x: 8.6, y: 2.3}}
          navigation.go_to:
            - fail: blocked
            - succeed: {room: kitchen}
              delay: 2.0
        events:
          - {at: 1.0, event: vision.lostPerson, params: {person: Ana}}
        expect:
          status: success
          calls:
            - speech.say
            - navigation.go_to: {place: living_room}
          blackboard: {object_room: kitchen}
"""
from __future__ import annotations

import json
import os
import sys
import time
from typing import Any, Dict, List, Optional, TextIO

from comm.errors import did_you_mean
from coordinator.errors import Pos, TreeError, TreeErrors
from coordinator.testing.kit import TreeRun, TreeTest
from coordinator.testing.mocks import MockError, Outcome, outcome_from_dict
from coordinator.yamlsrc import LList, LMap, load_yaml, pos_of
from modules.definition import ModuleDefinition
from modules.search import default_definitions

__all__ = ["run_scenarios", "run_scenario_file", "calls_diff"]

_SCENARIO_KEYS = ("name", "inputs", "mocks", "events", "expect", "max_duration")
_EXPECT_KEYS = ("status", "calls", "blackboard")


def _outcome(raw: Any, at: Pos) -> Outcome:
    try:
        return outcome_from_dict(raw)
    except MockError as exc:
        raise TreeErrors([TreeError(at, str(exc))])


def _check_keys(m: LMap, allowed: Any, what: str) -> None:
    errs = [TreeError(m.key_pos[k], "unknown %s key %r%s" % (what, k, did_you_mean(k, allowed)))
            for k in m if k not in allowed]
    if errs:
        raise TreeErrors(errs)


def _number(m: LMap, key: str, default: float, at: Pos) -> float:
    """``m[key]`` as a non-negative number of seconds, else a positioned error."""
    value = m.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
        raise TreeErrors([TreeError(pos_of(m, key, at), "%s must be a number of seconds >= 0, got %r" % (key, value))])
    return float(value)


def _want(want: Any) -> Any:
    return (want, {}) if isinstance(want, str) else next(iter(want.items()))


def _same(want: Any, got: Any) -> bool:
    target, inputs = _want(want)
    return got.target == target and all(got.inputs.get(k) == v for k, v in (inputs or {}).items())


def _show(target: str, inputs: Any) -> str:
    return "%s %s" % (target, json.dumps(inputs, sort_keys=True, ensure_ascii=False, default=str)) if inputs else target


def calls_diff(expected: List[Any], actual: List[Any]) -> List[str]:
    """Expected vs actual calls as a diff: ``  =`` same, ``  -`` expected only, ``  +`` made only."""
    n, m = len(expected), len(actual)
    lcs = [[0] * (m + 1) for _ in range(n + 1)]
    for i in range(n - 1, -1, -1):
        for j in range(m - 1, -1, -1):
            lcs[i][j] = lcs[i + 1][j + 1] + 1 if _same(expected[i], actual[j]) else max(lcs[i + 1][j], lcs[i][j + 1])
    out, i, j = [], 0, 0
    while i < n or j < m:
        if i < n and j < m and _same(expected[i], actual[j]):
            out.append("  = %s" % _show(*_want(expected[i])))
            i, j = i + 1, j + 1
        elif j < m and (i == n or lcs[i][j + 1] >= lcs[i + 1][j]):
            out.append("  + %s" % _show(actual[j].target, actual[j].inputs))
            j += 1
        else:
            out.append("  - %s" % _show(*_want(expected[i])))
            i += 1
    return out


def _expect_calls(run: TreeRun, expected: List[Any]) -> List[str]:
    problems = []
    actual = run.calls()
    if len(actual) != len(expected):
        problems.append("expected %d calls, got %d: %s" % (len(expected), len(actual), ", ".join(run.targets)))
    for i, (want, got) in enumerate(zip(expected, actual)):
        target, inputs = _want(want)
        if got.target != target:
            problems.append("call %d: expected %s, got %s" % (i + 1, target, got.target))
            continue
        for k, v in (inputs or {}).items():
            if got.inputs.get(k) != v:
                problems.append("call %d (%s): input %s is %r, expected %r" % (i + 1, target, k, got.inputs.get(k), v))
    if problems:
        problems.append("calls changed (- expected only, + made only, = both):")
        problems.extend(calls_diff(expected, actual))
    return problems


def run_scenario_file(path: str, definitions: Optional[Dict[str, ModuleDefinition]] = None,
                      out: Optional[TextIO] = None) -> List[bool]:
    """Run every scenario of a file; one PASS/FAIL line each. TreeErrors for a bad file."""
    out = out or sys.stdout
    with open(path, encoding="utf-8") as fh:
        data = load_yaml(fh.read(), path)
    top = Pos(path, 1, 1)
    if not isinstance(data, LMap) or "tree" not in data or not isinstance(data.get("scenarios"), LList):
        raise TreeErrors([TreeError(getattr(data, "pos", top), "a scenario file needs 'tree' and a list 'scenarios'")])
    _check_keys(data, ("tree", "scenarios"), "top-level")
    tree_path = os.path.join(os.path.dirname(os.path.abspath(path)), str(data["tree"]))
    defs = definitions if definitions is not None else default_definitions()
    results = []
    for i, sc in enumerate(data["scenarios"]):
        at = data["scenarios"].item_pos[i]
        if not isinstance(sc, LMap):
            raise TreeErrors([TreeError(at, "a scenario is a mapping")])
        _check_keys(sc, _SCENARIO_KEYS, "scenario")
        name = str(sc.get("name", "scenario %d" % (i + 1)))
        test = TreeTest(tree_path, definitions=defs, inputs=dict(sc.get("inputs") or {}))
        try:
            for target, outcomes in (sc.get("mocks") or {}).items():
                if not isinstance(outcomes, LList):
                    outcomes_list = [outcomes]
                    positions = [pos_of(sc["mocks"], target, at)]
                else:
                    outcomes_list, positions = list(outcomes), outcomes.item_pos
                test.mocks[target].script(*[_outcome(o, p) for o, p in zip(outcomes_list, positions)])
            events = sc.get("events") or []
            for j, ev in enumerate(events):
                ev_at = events.item_pos[j] if isinstance(events, LList) else pos_of(sc, "events", at)
                if not isinstance(ev, LMap) or "event" not in ev:
                    raise TreeErrors([TreeError(ev_at, "an event needs 'event: module.event' (and 'at', 'params')")])
                _check_keys(ev, ("at", "event", "params"), "event")
                params = ev.get("params") or {}
                if not isinstance(params, dict):
                    raise TreeErrors([TreeError(pos_of(ev, "params", ev_at), "params is a mapping of name: value")])
                test.mocks.event(_number(ev, "at", 0.0, ev_at), str(ev["event"]), **dict(params))
        except MockError as exc:
            raise TreeErrors([TreeError(pos_of(sc, "mocks", at), str(exc))])
        expect = sc.get("expect") or {}
        if isinstance(expect, LMap):
            _check_keys(expect, _EXPECT_KEYS, "expect")
        t0 = time.perf_counter()
        run = test.run(max_duration=_number(sc, "max_duration", 3600.0, at))
        ms = (time.perf_counter() - t0) * 1000
        problems = []
        want_status = str(expect.get("status", "success")).upper()
        if run.status.value != want_status:
            problems.append("status %s, expected %s%s" % (run.status.value, want_status,
                                                          " (%s)" % run.reason if run.reason else ""))
        if "calls" in expect:
            problems.extend(_expect_calls(run, list(expect["calls"] or [])))
        bb = run.blackboard
        for k, v in (expect.get("blackboard") or {}).items():
            if bb.get(k) != v:
                problems.append("blackboard %s is %r, expected %r" % (k, bb.get(k), v))
        ok = not problems
        out.write("%s %s: %s (%d calls, %.1f ms)\n" % ("PASS" if ok else "FAIL", path, name, len(run.calls()), ms))
        for p in problems:
            out.write("    %s\n" % p)
        results.append(ok)
    return results


def run_scenarios(paths: List[str], modules: Optional[List[str]] = None, out: Optional[TextIO] = None) -> int:
    """``bmtree test``: exit 0 if every scenario passed, 1 if one failed, 2 for an invalid file."""
    out = out or sys.stdout
    defs = default_definitions(modules or ())
    results: List[bool] = []
    invalid = False
    for path in paths:
        try:
            results.extend(run_scenario_file(path, defs, out))
        except TreeErrors as exc:
            sys.stderr.write(str(exc) + "\n")
            invalid = True
        except OSError as exc:
            sys.stderr.write("%s: cannot read: %s\n" % (path, exc.strerror or exc))
            invalid = True
    passed = sum(results)
    out.write("%d passed, %d failed\n" % (passed, len(results) - passed))
    if invalid:
        return 2
    return 0 if passed == len(results) else 1
