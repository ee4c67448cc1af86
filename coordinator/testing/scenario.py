"""YAML test scenarios for ``bmtree test``: module scripts, expected calls, expected status.

    tree: ../trees/find_apple.yaml
    modules: ../defs                                 # the file's own definitions, unless --modules is given
    scenarios:
      - name: apple in the kitchen
        inputs: {object: apple}
        stored: {vision/find_object/room: kitchen}   # what the Blackboard node held before the run
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
          duration: {at_most: 60}                    # simulated seconds; at_least too
      - name: vision is blind
        mocks:
          vision.find_object: {fail: camera covered}
        expect: {status: failure, reason: camera covered, calls: {in_order: [speech.say, vision.find_object]}}

The whole file is checked before any scenario runs. Every run ends: after ``max_duration``
simulated seconds, ``max_ticks`` ticks, or ``max_ticks_per_instant`` ticks without the simulated
clock moving (a livelock); a limit reached is a FAIL naming it. The format: docs/scenarios.md.
"""
from __future__ import annotations

import logging
import os
import sys
import time
from typing import Any, Dict, List, Optional, Set, TextIO, Tuple, Union

from py_trees.common import Status

from comm.errors import did_you_mean
from coordinator.errors import Pos, TreeError, TreeErrors
from coordinator.language import load_tree
from coordinator.testing import scenariomocks as sm
from coordinator.testing.expected import (
    ExpectedCall,
    calls_diff,
    difference,
    expect_calls,
    expect_calls_in_order,
    expect_duration,
)
from coordinator.testing.kit import Coverage, TreeRun, TreeTest
from coordinator.testing.limits import (
    DEFAULT_MAX_DURATION,
    DEFAULT_MAX_TICKS,
    DEFAULT_MAX_TICKS_PER_INSTANT,
    SCENARIO_RAISE_WITH,
    TickGuard,
    TickLimitError,
)
from coordinator.testing.mocks import (
    Mocks,
)
from coordinator.testing.scenariokeys import (
    ScenarioDefinitions,
    check_calls,
    check_cleanup,
    check_duration,
    cleanup_problems,
    duration_of,
    expected_calls,
    listed_calls,
    modules_key,
)
from coordinator.treeast import TreeFile
from coordinator.yamlsrc import LList, LMap, load_file, pos_of
from modules.definition import ModuleDefinition
from modules.search import default_definitions

Definitions = Union[Dict[str, ModuleDefinition], ScenarioDefinitions, None]

__all__ = ["DEFAULT_MAX_DURATION", "DEFAULT_MAX_TICKS", "DEFAULT_MAX_TICKS_PER_INSTANT", "ExpectedCall", "TickGuard",
           "calls_diff", "load_scenario_file", "run_scenario_file", "run_scenarios"]

_LIMITS = ("max_duration", "max_ticks", "max_ticks_per_instant")
_SCENARIO_KEYS = ("name", "inputs", "stored", "mocks", "events", "expect") + _LIMITS + ("killed_at",)
_EXPECT_COMMON = ("status", "calls", "blackboard", "reason", "duration")   # what "expect is a mapping with" names
_EXPECT_KEYS = _EXPECT_COMMON + ("cleanup",)   # cleanup: for a tree with cleanup:
_TOP_KEYS = ("tree", "modules", "scenarios")


class _Scenario:
    """One scenario of a file, checked and ready to run."""

    def __init__(self, name: str, test: TreeTest, expect: Any, limits: Dict[str, Any], given: Set[str],
                 calls: Optional[List[ExpectedCall]] = None):
        self.name, self.test, self.expect, self.limits, self.given = name, test, expect, limits, given
        self.calls = calls if calls is not None else [ExpectedCall(c) for c in listed_calls(expect)[0]]


def _scenario(sc: Any, i: int, at: Pos, tree_path: str, defs: Dict[str, ModuleDefinition],
              tree: Optional[TreeFile] = None, coverage: Optional[Coverage] = None) -> _Scenario:
    """Check one scenario (TreeErrors listing every problem, with positions) and script its mocks and events;
    ``tree`` (loaded from ``tree_path``) None: the tree is missing or invalid (already reported), the rest is
    checked all the same."""
    if not isinstance(sc, LMap):
        raise TreeErrors([TreeError(at, "a scenario is a mapping")])
    out = sm.Problems()
    sm.check_keys(sc, _SCENARIO_KEYS, "scenario", out)
    inputs = sm.mapping(sc, "inputs", at, "inputs is a mapping of tree input: value", out)
    mocks = sm.mapping(sc, "mocks", at, "mocks is a mapping of module.function: outcome (or a list of outcomes)", out)
    expect = _expectations(sc, at, out)
    calls = expected_calls(expect, at, defs, out.add)
    if expect:
        check_cleanup(expect, at, tree, out.add)
    limits = {"max_duration": sm.number(sc, "max_duration", DEFAULT_MAX_DURATION, at, out),
              "max_ticks": sm.count(sc, "max_ticks", DEFAULT_MAX_TICKS, at, out),
              "max_ticks_per_instant": sm.count(sc, "max_ticks_per_instant", DEFAULT_MAX_TICKS_PER_INSTANT, at, out),
              "killed_at": sm.number(sc, "killed_at", 0.0, at, out) if "killed_at" in sc else None}
    if not isinstance(sc.get("name", ""), str):
        out.add(pos_of(sc, "name", at), "name must be text, got %r" % (sc.get("name"),))
    test = None
    if tree is not None:
        before = len(out.errors)
        _check_inputs(tree, inputs, sc, at, out)
        if len(out.errors) == before:   # the tree is valid (checked before), its inputs given
            test = TreeTest(tree_path, definitions=defs, inputs=dict(inputs), coverage=coverage)
            test.raise_limits_with = SCENARIO_RAISE_WITH
            test.warn_unscripted = False   # a scenario written from a run scripts what the run answered
    mocked = test.mocks if test is not None else Mocks(defs)
    stored = sm.stored(sc, at, defs, out)
    if stored:
        mocked.stored_values.extend(stored)
    for target, outcomes in mocks.items():
        sm.script(mocked, mocks, target, outcomes, at, out)
    events = sc.get("events") or []
    if not isinstance(events, list):
        out.add(pos_of(sc, "events", at), "events is a list of {at, event, params}")
        events = []
    for j, ev in enumerate(events):
        ev_at = events.item_pos[j] if isinstance(events, LList) else pos_of(sc, "events", at)
        sm.event(mocked, ev, ev_at, defs, out)
    if out.errors or test is None:
        raise TreeErrors(out.errors)
    return _Scenario(str(sc.get("name", "scenario %d" % (i + 1))), test, expect, limits,
                     {k for k in _LIMITS if k in sc}, calls)


def _check_inputs(tree: Any, inputs: Any, sc: LMap, at: Pos, out: sm.Problems) -> None:
    """A scenario's ``inputs`` against the tree's: each declared, every required one given."""
    declared = tree.inputs
    for k in inputs:
        if k not in declared:
            out.add(inputs.key_pos[k], "the tree declares no input %r%s (its inputs: %s)" % (
                k, did_you_mean(k, declared), ", ".join(sorted(declared)) or "none"))
    missing = sorted(tree.required_inputs - set(inputs))
    if missing:
        out.add(pos_of(sc, "inputs", at), "the tree needs the input%s %s: give %s in 'inputs'" % (
            "s" if len(missing) > 1 else "", ", ".join(missing), "them" if len(missing) > 1 else "it"))


def _expectations(sc: LMap, at: Pos, out: sm.Problems) -> Any:
    """A scenario's ``expect``, checked (its problems to ``out``)."""
    expect = sm.mapping(sc, "expect", at, "expect is a mapping with " + ", ".join(_EXPECT_COMMON), out)
    if not expect:
        return expect
    sm.check_keys(expect, _EXPECT_KEYS, "expect", out)
    status = str(expect.get("status", "success"))
    if status.lower() not in ("success", "failure"):
        out.add(pos_of(expect, "status", at), "status is success or failure, got %r%s" % (
            status, did_you_mean(status.lower(), ("success", "failure"))))
    check_calls(expect, at, out.add)
    check_duration(expect, at, out.add)
    sm.mapping(expect, "blackboard", at, "blackboard is a mapping of tree key: value", out)
    want = expect.get("reason")
    if isinstance(want, list):   # the pieces around what differs from run to run (replay --scenario writes them)
        if not want or not all(isinstance(p, str) and p for p in want):
            out.add(pos_of(expect, "reason", at), "reason as a list holds the texts the run's reason must contain, "
                                                   "in this order (at least one, none empty), got %r" % (want,))
    elif "reason" in expect and not isinstance(want, str):
        out.add(pos_of(expect, "reason", at), "reason is text that the run's reason must contain, got %r" % (want,))
    return expect


def load_scenario_file(path: str, definitions: Definitions = None,
                       coverage: Optional[Coverage] = None) -> List[_Scenario]:
    """Every scenario of a file, checked before any runs; TreeErrors lists every problem of the file.
    ``definitions``: given ones (the file's ``modules`` is then only checked), or None for the
    defaults with the file's ``modules`` (a ScenarioDefinitions: the same, loaded once for many files).
    ``coverage``: record which nodes of the trees ran (``bmtree test --coverage``)."""
    top = Pos(path, 1, 1)
    data = load_file(path)  # at most MAX_BYTES, and never a device (bmtree test /dev/zero)
    if not isinstance(data, LMap) or "tree" not in data or not isinstance(data.get("scenarios"), LList):
        raise TreeErrors([TreeError(getattr(data, "pos", top), "a scenario file needs 'tree' and a list 'scenarios'")])
    found = sm.Problems()
    sm.check_keys(data, _TOP_KEYS, "top-level", found)
    errors = found.errors   # the scenario file's own
    tree_errors: List[TreeError] = []   # its tree's (and its warnings): said first
    before = len(errors)
    named = modules_key(data, path, top, found.add)
    source = definitions if isinstance(definitions, ScenarioDefinitions) else ScenarioDefinitions(definitions)
    defs = source.of(named, found.add)
    if defs is None or len(errors) > before:   # without its definitions the rest cannot be checked
        raise _FileErrors([], errors)
    loaded: Optional[TreeFile] = None
    tree = data["tree"]
    tree_path = os.path.join(os.path.dirname(os.path.abspath(path)), str(tree))
    if not isinstance(tree, str) or not tree.strip():
        errors.append(TreeError(pos_of(data, "tree", top), "tree is the path of a tree file, got %r" % (tree,)))
    elif not os.path.isfile(tree_path):
        errors.append(TreeError(pos_of(data, "tree", top), "tree %s: no such file (relative paths are from the "
                                                           "scenario file's folder)" % tree_path))
    else:
        try:
            loaded = load_tree(tree_path, defs)   # the tree itself, before the scenarios give it inputs
        except TreeErrors as exc:
            tree_errors = list(exc.errors) + list(getattr(exc, "warnings", ()))
    if not data["scenarios"]:
        errors.append(TreeError(pos_of(data, "scenarios", top), "scenarios is empty: write at least one scenario"))
    usable = loaded if not errors and not tree_errors else None   # else the scenarios are checked without it
    scenarios = []
    for i, sc in enumerate(data["scenarios"]):
        try:
            scenarios.append(_scenario(sc, i, data["scenarios"].item_pos[i], tree_path, defs, usable, coverage))
        except TreeErrors as exc:
            errors.extend(exc.errors)
    if errors or tree_errors:
        raise _FileErrors(tree_errors, errors)
    return scenarios


class _FileErrors(TreeErrors):
    """A scenario file's problems as docs/scenarios.md says: its tree's errors and warnings (in the
    tree's file order), then the scenario file's own (in its order), whatever the files' names."""

    def __init__(self, tree_errors: List[TreeError], own: List[TreeError]):
        super().__init__(own)
        in_order = sorted(set(tree_errors), key=lambda e: (e.pos.file, e.pos.line, e.pos.column, e.message))
        self.errors = in_order + self.errors
        self.args = ("\n".join(str(e) for e in self.errors),)


def _run(s: _Scenario) -> Tuple[TreeRun, List[str]]:
    """Run one scenario; its problems (none: PASS)."""
    limits = s.limits
    try:   # the kit's tick limits, worded for a scenario (set where its TreeTest is made)
        run = s.test.run(max_duration=limits["max_duration"], max_ticks=limits["max_ticks"],
                         max_ticks_per_instant=limits["max_ticks_per_instant"], kill_at=limits["killed_at"])
    except TickLimitError as exc:   # a FAIL whatever expect says
        return exc.run, [exc.hit]
    stopped = run.reason.startswith("stopped after %g s" % limits["max_duration"])
    if stopped and "max_duration" not in s.given:
        return run, ["stopped after %g simulated seconds, the default max_duration: the tree did not end; set the "
                     "scenario key 'max_duration' to raise the limit (or to expect the stop)" % limits["max_duration"]]
    problems = []
    expect = s.expect
    want_status = str(expect.get("status", "success")).upper()
    if run.status.value != want_status:
        at = " at %s" % run.result.failed_at if run.result.failed_at else ""
        problems.append("status %s, expected %s%s" % (run.status.value, want_status,
                                                      " (%s)%s" % (run.reason, at) if run.reason else ""))
        if stopped:
            problems.append("the run reached the scenario's max_duration (%g s of simulated time); raise it if "
                            "the tree needs longer" % limits["max_duration"])
    if "calls" in expect:
        in_order = isinstance(expect["calls"], dict)
        problems.extend(expect_calls_in_order(run, s.calls) if in_order else expect_calls(run, s.calls))
    problems.extend(expect_duration(run.duration, duration_of(expect)))
    problems.extend(cleanup_problems(expect, run.result))
    if "reason" in expect:
        problems.extend(_reason_problems(run, expect["reason"]))
    bb = run.result.blackboard  # the values as the tree holds them: messages keep their types
    for k, v in (expect.get("blackboard") or {}).items():
        if k not in bb:
            if v is not None:
                problems.append("blackboard %s was never written in this run (expected %r)%s" % (
                    k, v, did_you_mean(k, bb) or "; written: %s" % (", ".join(sorted(map(str, bb))) or "none")))
            continue
        d = difference(v, bb[k])
        if d is not None:
            problems.append(d.said("blackboard %s" % k))
    return run, problems


def _reason_problems(run: TreeRun, want: Any) -> List[str]:
    """``expect: reason`` against the run's: a text it must contain, or texts it must contain in this order
    (what ``bmtree replay --scenario`` writes around a call id or a measured time)."""
    pieces = [want] if isinstance(want, str) else [str(p) for p in want]
    reason, at, missing = run.reason, 0, None
    for i, piece in enumerate(pieces):
        found = reason.find(piece, at)
        if found < 0:
            missing = i
            break
        at = found + len(piece)
    if missing is None:
        return []
    said = repr(pieces[0]) if len(pieces) == 1 else "%s in this order" % ", ".join(map(repr, pieces))
    if not reason:
        return ["no reason (the run %s), expected one containing %s" % (
            "succeeded" if run.status == Status.SUCCESS else "gave none", said)]
    if len(pieces) == 1:
        return ["reason %r does not contain %r" % (reason, pieces[0])]
    return ["reason %r does not contain %s: %r not found%s" % (
        reason, said, pieces[missing], " after %r" % pieces[missing - 1] if missing else "")]


def run_scenario_file(path: str, definitions: Definitions = None,
                      out: Optional[TextIO] = None, coverage: Optional[Coverage] = None) -> List[bool]:
    """Run every scenario of a file (all checked first); one PASS/FAIL line each. TreeErrors for a bad file."""
    out = out or sys.stdout
    results = []
    for s in load_scenario_file(path, definitions, coverage):
        t0 = time.perf_counter()
        with _ModuleLog() as logged:
            run, problems = _run(s)
        ms = (time.perf_counter() - t0) * 1000
        ok = not problems
        out.write("%s %s: %s (%d calls, %.1f ms)\n" % ("PASS" if ok else "FAIL", path, s.name, len(run.calls()), ms))
        for p in problems:
            out.write("    %s\n" % p)
        if not ok:
            out.writelines("    module log: %s\n" % line for line in logged.lines)
        results.append(ok)
    return results


class _ModuleLog(logging.Handler):
    """The warnings the mocked modules' runtime logs during a scenario (``busy with call …``, a cancelled
    call whose code has not returned), kept, not printed between the PASS/FAIL lines: a FAIL shows them
    under its problems (at most ``MAX``), a PASS drops them."""

    MAX = 20

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.lines: List[str] = []
        self._logger = logging.getLogger("bmtree.module")

    def emit(self, record: logging.LogRecord) -> None:
        if len(self.lines) < self.MAX:
            self.lines.append(record.getMessage())

    def __enter__(self) -> _ModuleLog:
        self._propagate = self._logger.propagate
        self._logger.addHandler(self)
        self._logger.propagate = False   # else Python's last-resort handler prints it on stderr
        return self

    def __exit__(self, *exc: Any) -> None:
        self._logger.removeHandler(self)
        self._logger.propagate = self._propagate


def run_scenarios(paths: List[str], modules: Optional[List[str]] = None, out: Optional[TextIO] = None,
                  coverage: bool = False) -> int:
    """``bmtree test``: exit 0 if every scenario passed, 1 if one failed, 2 for an invalid file;
    ``modules`` (``--modules``) given, every file runs with them and its own ``modules`` is not loaded;
    ``coverage``: then which nodes of the trees ran and which outcomes they reached."""
    out = out or sys.stdout
    defs = ScenarioDefinitions(default_definitions(modules) if modules else None)
    cov = Coverage() if coverage else None
    results: List[bool] = []
    invalid = 0  # files
    for path in paths:
        try:
            results.extend(run_scenario_file(path, defs, out, cov))
        except TreeErrors as exc:
            sys.stderr.write(str(exc) + "\n")
            invalid += 1
        except OSError as exc:
            sys.stderr.write("%s: cannot read: %s\n" % (path, exc.strerror or exc))
            invalid += 1
    passed = sum(results)
    out.write("%d passed, %d failed%s\n" % (passed, len(results) - passed, ", %d scenario file%s not valid (above)" % (
        invalid, " is" if invalid == 1 else "s are") if invalid else ""))
    if cov is not None and cov.trees:
        out.write(cov.report() + "\n")
    if invalid:
        return 2
    return 0 if passed == len(results) else 1
