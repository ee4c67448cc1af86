"""Test a tree without a robot: load it, mock its modules, run it on a simulated clock.

    t = TreeTest("trees/find_apple.yaml")
    t.mocks["vision.find_object"].fail_first(2, success=True, position={"x": 1.0})
    run = t.run()
    assert run.succeeded
    assert run.calls("navigation.go_to")[0].inputs["place"] == "living_room"

A tree error, a missing input or a bad script fails the test at the user's line: the kit's own
frames are hidden from pytest (``__tracebackhide__``).
"""
from __future__ import annotations

import warnings
from collections import defaultdict
from typing import Any, Callable, Dict, FrozenSet, List, Mapping, Optional, Sequence, Set, Tuple

import py_trees
from py_trees.common import Status

from comm.errors import did_you_mean
from comm.rostypes import now_from
from coordinator.builder import build_tree
from coordinator.clock import SimClock
from coordinator.context import CallRecord, RunContext, plain
from coordinator.errors import TreeErrors, UsageError
from coordinator.language import load_tree
from coordinator.nodes.base import NEVER, Flow
from coordinator.runner import RunResult, TreeRunner, shown_status
from coordinator.testing.inprocess import InProcessTransport
from coordinator.testing.limits import (
    DEFAULT_MAX_DURATION,
    DEFAULT_MAX_TICKS,
    DEFAULT_MAX_TICKS_PER_INSTANT,
    KIT_RAISE_WITH,
    TickGuard,
    TickLimitError,
)
from coordinator.testing.mocks import MockError, Mocks
from coordinator.treeast import TreeFile, TreeNode, top_of, walk
from modules.definition import DefinitionError, ModuleDefinition
from modules.search import default_definitions

__all__ = ["TreeTest", "TreeRun", "Coverage", "RunStatus", "UnscriptedWarning"]

HALTED = "halted"   # coverage: a node a parent or a timeout stopped while it ran


class UnscriptedWarning(UserWarning):
    """A run's calls were answered without a script, with empty outputs the tree may have used (pytest
    lists it under "warnings summary"; ``filterwarnings`` can make it an error or hide it)."""


class RunStatus(str):
    """How a kit run ended, as ``bmtree run`` prints it (``"SUCCESS"``, ``"FAILURE"``, ``"INVALID"``), and
    equal to py_trees' :class:`~py_trees.common.Status` member as well: ``run.status == "FAILURE"`` and
    ``run.status == Status.FAILURE`` both hold (the first failed, comparing an enum to its text)."""

    def __eq__(self, other: object) -> bool:
        return str.__eq__(self, other.value if isinstance(other, Status) else other)

    def __ne__(self, other: object) -> bool:
        return not self == other

    __hash__ = str.__hash__

    @property
    def value(self) -> str:
        """Its text, as ``Status.value`` gives it."""
        return str(self)


class TreeRun:
    """What happened in one run: final status, calls in order, blackboard, node statuses."""

    def __init__(self, result: RunResult, transport: InProcessTransport,
                 unscripted: Optional[Dict[str, int]] = None):
        self.result = result
        self.status = RunStatus(result.status.value)
        #: ``module.function`` -> its calls answered without a script (success, empty text, zero
        #: positions), for functions whose outputs say more than ``success``
        self.unscripted: Dict[str, int] = dict(unscripted or {})
        self.reason = result.reason
        self.duration = result.duration
        self.transport = transport
        defs = transport.mocks.definitions
        self._functions = {"%s.%s" % (m, f) for m, d in defs.items() for f in d.functions}
        self._by_name: Dict[str, List[Tuple[Any, List[str]]]] = {}   # name -> (node, statuses), in the order they ran
        for b, statuses in result.history.items():
            self._by_name.setdefault(b.name, []).append((b, [s.value for s in statuses]))

    def __repr__(self) -> str:
        """What a failed ``assert run.succeeded`` shows: how the run ended and why, where, what steered it."""
        said = "%s in %.2f s" % (self.status.value, self.duration)
        if self.reason and self.status != Status.SUCCESS:
            said += ": %s" % self.reason
        if self.result.failed_at:
            said += " (at %s)" % self.result.failed_at
        if self.result.ended:
            said += "; cleanup (root %s): %s" % (self.result.ended, self.cleanup_status or "did not run")
            if self.result.cleanup_reason:
                said += ": %s" % self.result.cleanup_reason
        if self.unscripted:
            said += "; answered without a script (success, empty outputs): %s" % unscripted_text(self.unscripted)
        return "<TreeRun %s>" % said

    @property
    def succeeded(self) -> bool:
        return self.status == Status.SUCCESS

    @property
    def failed(self) -> bool:
        return self.status == Status.FAILURE

    def calls(self, target: Optional[str] = None) -> List[CallRecord]:
        """Calls in order, all or those of ``module.function``: ``[]`` for a function never called,
        KeyError for one the definitions do not have (a misspelt target must not pass
        ``assert not run.calls(...)``)."""
        __tracebackhide__ = True
        self._known(target, "calls")
        return [c for c in self.result.calls if target is None or c.target == target]

    def _known(self, target: Optional[str], method: str) -> None:
        """KeyError, naming ``run.<method>(...)``, for a ``target`` the definitions do not have."""
        __tracebackhide__ = True
        if target is not None and target not in self._functions and all(c.target != target for c in self.result.calls):
            mod = str(target).partition(".")[0]
            same = sorted(f for f in self._functions if f.partition(".")[0] == mod)
            raise KeyError("run.%s(%r): no function %r in the module definitions%s" % (
                method, target, target, did_you_mean(target, self._functions) or (
                    " (module %s has %s)" % (mod, ", ".join(same)) if same
                    else " (modules: %s)" % ", ".join(sorted({f.partition(".")[0] for f in self._functions})))))

    def label(self, call: CallRecord) -> Tuple[str, str]:
        """(status, error) of ``call`` as the run's summary and ``bmtree replay`` show it: a call halted by
        a stop from outside, or when the cleanup was cut short, says so (``("halted", "did not end within
        10 s (cleanup_timeout)")``, ``("interrupted", "")``) where its record keeps ``halted by the tree``."""
        return shown_status(self.result, call)

    @property
    def targets(self) -> List[str]:
        return [c.target for c in self.result.calls]

    @property
    def blackboard(self) -> Dict[str, Any]:
        """The tree blackboard at the end, one-field messages unwrapped (``answer == "yes"``)."""
        return {k: plain(v) for k, v in self.result.blackboard.items()}

    def statuses(self, name: str, nth: Optional[int] = None) -> List[str]:
        """Statuses the node called ``name`` went through (``["RUNNING", "SUCCESS"]``). Several nodes so
        named (a subtree included twice) that went through different ones: KeyError naming each, unless
        ``nth`` says which (0: the first of them to run)."""
        __tracebackhide__ = True
        if name not in self._by_name:
            raise KeyError("no node named %r ran%s (nodes: %s)" % (
                name, did_you_mean(name, self._by_name), ", ".join(sorted(self._by_name))))
        ran = self._by_name[name]
        if nth is not None:
            if not 0 <= nth < len(ran):
                raise KeyError("run.statuses(%r, %d): %d node%s named %r ran (nth is 0 to %d)" % (
                    name, nth, len(ran), "s" if len(ran) > 1 else "", name, len(ran) - 1))
            return ran[nth][1]
        if any(statuses != ran[0][1] for _b, statuses in ran[1:]):
            said = ["%d: %s %s" % (i, _where(b), statuses) for i, (b, statuses) in enumerate(ran)]
            raise KeyError("%d nodes named %r ran, through different statuses (%s): say which, "
                           "run.statuses(%r, nth) (0: the first to run)" % (len(ran), name, "; ".join(said), name))
        return ran[0][1]

    @property
    def ended(self) -> str:
        """With ``cleanup:``: how root ended, as the cleanup's ``ended`` key says it (succeeded, failed,
        stopped); "" without one."""
        return self.result.ended

    @property
    def cleanup_status(self) -> Optional[str]:
        """With ``cleanup:``: how the cleanup ended (``"SUCCESS"``, ``"FAILURE"``, ``"INVALID"`` when cut
        short by a second stop); None without one (or when it never ran)."""
        status = self.result.cleanup_status
        return status.value if status is not None else None

    @property
    def cleanup_reason(self) -> str:
        """Why the cleanup failed or was cut short ("" when it succeeded)."""
        return self.result.cleanup_reason

    def cleanup_calls(self, target: Optional[str] = None) -> List[CallRecord]:
        """The calls the cleanup made (all, or those of ``module.function``); they are among
        :meth:`calls` too."""
        __tracebackhide__ = True
        self._known(target, "cleanup_calls")
        mine = {id(c) for c in self.result.cleanup_calls}
        return [c for c in self.result.calls if id(c) in mine and (target is None or c.target == target)]

    def said(self) -> List[str]:
        """Convenience for the speech module: every ``text`` passed to ``speech.say``."""
        return [c.inputs.get("text") for c in self.result.calls if c.target == "speech.say"]


class Coverage:
    """Which nodes of which trees were ever ticked, and the outcomes each reached; an outcome a node
    cannot have (the data-flow walk says ``NEVER``: a ``force_failure`` never succeeds) is not missing."""

    def __init__(self) -> None:
        self.trees: Dict[str, List[TreeNode]] = {}
        self.reached: Dict[Any, Set[str]] = defaultdict(set)
        self.loaded_by: Dict[str, Set[str]] = {}   # file -> the trees (root files) whose nodes it holds
        self.ran: Set[str] = set()   # the trees (root files) that ran at least once
        self._roots: Dict[str, TreeFile] = {}   # one tree per root file: its nodes' possible outcomes
        self._possible: Dict[Any, Tuple[bool, bool]] = {}   # node position -> (can succeed, can fail)

    def add_tree(self, tree: TreeFile) -> None:
        self._roots.setdefault(tree.root.pos.file, tree)
        seen: Dict[str, List[TreeNode]] = {}
        for node in walk(top_of(tree)):
            if node is tree.top:   # the node above root and cleanup: not written in the file
                continue
            seen.setdefault(node.pos.file, [])
            if node not in seen[node.pos.file]:
                seen[node.pos.file].append(node)
        for f, nodes in seen.items():
            self.loaded_by.setdefault(f, set()).add(tree.root.pos.file)
            known = self.trees.setdefault(f, [])
            for n in nodes:
                if all(n.pos != k.pos for k in known):
                    known.append(n)

    def visitor(self, tree: Optional[TreeFile] = None) -> py_trees.visitors.VisitorBase:
        """A py_trees visitor that records into this coverage on every tick of a run (of ``tree``: then
        that tree is one that ran)."""
        if tree is not None:
            self.ran.add(tree.root.pos.file)
        return _CoverageVisitor(self.reached)

    def did_not_run(self, f: str) -> bool:
        """None of the trees that hold ``f``'s nodes ran: its scenario file was invalid, or its tests
        ended before ``t.run()``. Its nodes say nothing of the tree: the report says so once."""
        return not self.loaded_by.get(f, set()) & self.ran and not any(self.reached.get(n.pos) for n in self.trees[f])

    def possible(self, node: TreeNode) -> Tuple[str, ...]:
        """The outcomes ``node`` can reach, as the data-flow walk sees them: ``("SUCCESS", "FAILURE")``
        but for a node that cannot end one way (a node it never walked: both)."""
        if self._roots:   # walked when first asked: only a report needs it
            for tree in self._roots.values():
                _Endings(tree, self._possible).walk()
            self._roots.clear()
        ok, fails = self._possible.get(node.pos, (True, True))
        return ("SUCCESS",) * ok + ("FAILURE",) * fails

    def report(self) -> str:
        lines = ["bmtree tree coverage"]
        for f in sorted(self.trees):
            nodes = sorted(self.trees[f], key=lambda n: (n.pos.line, n.pos.column))
            if self.did_not_run(f):
                lines.append("%s: did not run: no scenario or test of it ran (an invalid scenario file, or a test "
                             "that ended before t.run()); its %d nodes are not counted" % (f, len(nodes)))
                continue
            ran = [n for n in nodes if self.reached.get(n.pos)]
            lines.append("%s: %d of %d nodes ran" % (f, len(ran), len(nodes)))
            for n in nodes:
                got = self.reached.get(n.pos, set())
                if not got:
                    lines.append("  %s:%d: %s '%s' never ran" % (f, n.pos.line, n.kind, n.name))
                else:
                    outcomes = ", ".join(s for s in ("SUCCESS", "FAILURE") if s in got)
                    if HALTED in got:
                        outcomes = "%s, halted" % outcomes if outcomes else "RUNNING, then halted"
                    missing = [s for s in self.possible(n) if s not in got]
                    lines.append("  %s:%d: %s '%s' reached %s%s" % (
                        f, n.pos.line, n.kind, n.name, outcomes or "RUNNING only",
                        "; never %s" % ", ".join(missing) if missing else ""))
        return "\n".join(lines)


class _Endings(Flow):
    """The data-flow walk of one tree, noting for each node whether it can succeed and fail (an ending
    its kind says ``NEVER`` of it cannot have); its errors are the check's, already reported."""

    def __init__(self, tree: TreeFile, possible: Dict[Any, Tuple[bool, bool]]):
        super().__init__([], tree)
        self.root = tree
        self.possible = possible

    def walk(self) -> None:
        self.outcome(top_of(self.root), frozenset(self.root.inputs))

    def outcome(self, node: TreeNode, avail: FrozenSet[str]) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        ok, failed = super().outcome(node, avail)
        was = self.possible.get(node.pos, (False, False))   # a node walked again (an included file): either
        self.possible[node.pos] = (was[0] or ok is not NEVER, was[1] or failed is not NEVER)
        return ok, failed


class _CoverageVisitor(py_trees.visitors.VisitorBase):
    def __init__(self, reached: Dict[Any, Set[str]]):
        super().__init__(full=False)
        self.reached = reached

    def halted(self, changes: List[Any]) -> None:
        """The nodes a tick halted (RUNNING, then INVALID: a parallel or a timeout stopped them)."""
        for b, before, status in changes:
            node = getattr(b, "bmtree_node", None)
            if node is not None and status == Status.INVALID and before == Status.RUNNING:
                self.reached[node.pos].add(HALTED)

    def run(self, behaviour: py_trees.behaviour.Behaviour) -> None:
        node = getattr(behaviour, "bmtree_node", None)
        if node is not None and behaviour.status != Status.INVALID and node.kind != "with_cleanup":
            self.reached[node.pos].add(behaviour.status.value)


class TreeTest:
    """One tree, its mocked modules (``mocks``), a simulated clock; ``run()`` to completion.

    Args:
        path: the tree file.
        definitions: module definitions (default: :func:`modules.search.default_definitions`).
        inputs: values for the tree's declared inputs; every input without a default must be
            given (else UsageError here, saying how).
        coverage: a :class:`Coverage` to record into (the pytest plugin passes one).
        modules: more definition files or folders (your own modules), as ``--modules`` of the CLI;
            added to ``definitions`` (or to the default ones).
        strict: a call to a function the test did not script fails the test (``mocks.strict``); by
            default it succeeds with empty outputs, and ``TreeRun.unscripted`` lists those that say more
            than ``success``.
    """

    def __init__(self, path: str, definitions: Optional[Mapping[str, ModuleDefinition]] = None,
                 inputs: Optional[Dict[str, Any]] = None, coverage: Optional[Coverage] = None,
                 modules: Sequence[str] = (), strict: bool = False):
        __tracebackhide__ = True
        self.path = path
        self.inputs = dict(inputs or {})
        try:
            if definitions is None:
                self.definitions = default_definitions(modules)
            else:
                self.definitions = dict(definitions)
                if modules:
                    from modules.definition import load_definitions

                    self.definitions.update(load_definitions(list(modules)))
            self.tree = load_tree(path, self.definitions, given=set(self.inputs))
            self._check_inputs()
        except (TreeErrors, DefinitionError, UsageError) as exc:
            # the message says where (file:line:column); the loader's frames would only bury it
            raise exc.with_traceback(None)
        self.mocks = Mocks(self.definitions)
        self.mocks.strict = strict
        self.coverage = coverage
        if coverage is not None:
            coverage.add_tree(self.tree)

    warn_unscripted = True
    """Warn (:class:`UnscriptedWarning`) of a run's calls answered without a script (``bmtree test``'s
    scenario files, written from runs, do not)."""

    raise_limits_with = KIT_RAISE_WITH
    """How a tick limit's error says to raise it (``bmtree test`` names its scenario keys instead)."""

    def run(self, max_duration: float = DEFAULT_MAX_DURATION, default_timeout: float = 30.0,
            observers: Sequence[Any] = (), stop_when: Optional[Callable[[], str]] = None,
            max_ticks: int = DEFAULT_MAX_TICKS, max_ticks_per_instant: int = DEFAULT_MAX_TICKS_PER_INSTANT,
            kill_at: Optional[float] = None) -> TreeRun:
        """Run to SUCCESS/FAILURE (or ``max_duration`` simulated seconds, or until ``stop_when()``
        gives a reason); ``observers`` are :class:`~coordinator.runevents.RunObserver` (e.g. a
        RunStream writing a run log). A run that ticks ``max_ticks`` times, or ``max_ticks_per_instant``
        times without the simulated clock moving (a livelock), is stopped and raises
        :class:`~coordinator.testing.limits.TickLimitError`, whatever the test expects. ``kill_at``: the
        run ends then as a killed process's does (nothing more ticked, no cleanup begun after it)."""
        __tracebackhide__ = True
        self._check_inputs()
        clock = SimClock()
        transport = InProcessTransport(self.mocks, clock)
        ctx = RunContext(transport, clock, self.definitions, default_timeout=default_timeout)
        root = build_tree(self.tree, ctx, self.inputs)
        visitors = [self.coverage.visitor(self.tree)] if self.coverage is not None else []
        guard = TickGuard(max_ticks, max_ticks_per_instant, self.raise_limits_with)
        del self.mocks.errors[:]
        before = self.mocks.unscripted(every=True)
        with now_from(clock.now):  # a time given as `now` is the simulated time: the same on every run
            runner = TreeRunner(root, ctx, record_history=True, visitors=visitors, observers=[guard, *observers],
                                tree=self.tree)
            result = runner.run(max_duration, stop_when, guard, kill_at)
            if kill_at is None or not result.reason.startswith("killed after"):
                runner.confirm_cancels()  # the answers to the cancels of its last tick, as `bmtree run` waits
        if self.mocks.errors:  # a respond() gave outputs that break the definition: the test's bug
            raise self.mocks.errors[0]
        unscripted = {t: n - before.get(t, 0) for t, n in self.mocks.unscripted(every=True).items()
                      if n > before.get(t, 0)}
        if unscripted and self.mocks.strict:
            first = sorted(unscripted)[0]
            raise MockError("calls to functions without a script (strict mocks; answered failed): %s; script them, "
                            "e.g. mocks[%r].succeed(...) or .fail(...)" % (unscripted_text(unscripted), first))
        says_more = self.mocks.unscripted()
        unscripted = {t: n for t, n in unscripted.items() if t in says_more}
        run = TreeRun(result, transport, unscripted)
        if unscripted and self.warn_unscripted:
            first = sorted(unscripted)[0]
            warnings.warn(UnscriptedWarning(
                "%s: calls answered without a script (success, empty text, zero numbers): %s; script them "
                "(mocks[%r].succeed(...)), or make such calls fail the test: TreeTest(..., strict=True), or the "
                "pytest ini key bmtree_strict_mocks = true" % (self.path, unscripted_text(unscripted), first)),
                stacklevel=2)
        stopped = [r for r in (result.reason, result.cleanup_reason) if guard.hit and r.startswith(guard.hit)]
        if stopped:   # stopped by it (root, or a cleanup that livelocked); the reason adds the running node
            where = stopped[0][len(guard.hit):]
            raise TickLimitError("%s: %s%s" % (self.path, guard.hit, " (it was stopped%s)" % where if where else ""),
                                 guard.hit, run)
        return run

    def _check_inputs(self) -> None:
        """UsageError naming an input ``inputs`` gives that the tree does not declare, or the tree's inputs
        without a default that ``inputs`` lacks, and how to give them."""
        __tracebackhide__ = True
        unknown = sorted(str(k) for k in self.inputs if k not in self.tree.inputs)
        if unknown:   # a typo would silently run the default: a green test that tests nothing
            k = unknown[0]
            raise UsageError("%s declares no input %r%s (its inputs: %s)" % (
                self.path, k, did_you_mean(k, self.tree.inputs), ", ".join(sorted(self.tree.inputs)) or "none"))
        missing = sorted(self.tree.required_inputs - set(self.inputs))
        if missing:
            example = ", ".join("%r: ..." % m for m in missing)
            raise UsageError("%s: tree input%s %s must be given: bmtree_tree(path, inputs={%s}) or TreeTest(path, "
                             "inputs={%s}); in a scenario file, the scenario's inputs: {%s}" % (
                                 self.path, "s" if len(missing) > 1 else "", ", ".join(repr(m) for m in missing),
                                 example, example, ", ".join("%s: ..." % m for m in missing)))


def unscripted_text(unscripted: Mapping[str, int]) -> str:
    """``speech.listen ×2, vision.find_object``: calls answered without a script, by function."""
    return ", ".join("%s ×%d" % (t, n) if n > 1 else t for t, n in sorted(unscripted.items()))


def _where(b: Any) -> str:
    """Where a behaviour is written: ``go_safely.yaml:12:9`` (and the include it is in), or its name."""
    import os

    def at(x: Any) -> str:
        pos = getattr(getattr(x, "bmtree_node", None), "pos", None)
        return "%s:%s:%s" % (os.path.basename(str(pos.file)), pos.line, pos.column) if pos is not None else ""

    said, up = at(b) or repr(b.name), b.parent
    while up is not None:   # the include it came through: a subtree included twice is written once
        if getattr(getattr(up, "bmtree_node", None), "kind", "") == "include" and at(up):
            return "%s (in %s at %s)" % (said, up.name, at(up))
        up = up.parent
    return said
