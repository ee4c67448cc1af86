"""Test a tree without a robot: load it, mock its modules, run it on a simulated clock.

    t = TreeTest("trees/find_apple.yaml")
    t.mocks["vision.find_object"].fail_first(2, success=True, position={"x": 1.0})
    run = t.run()
    assert run.succeeded
    assert run.calls("navigation.go_to")[0].inputs["place"] == "living_room"
"""
from __future__ import annotations

from collections import defaultdict
from typing import Any, Dict, Iterable, List, Mapping, Optional, Set

from py_trees.common import Status

from coordinator.builder import build_tree
from coordinator.clock import SimClock
from coordinator.context import CallRecord, RunContext, plain
from coordinator.language import Node, TreeFile, load_tree, walk
from coordinator.runner import RunResult, TreeRunner
from coordinator.testing.mocks import InProcessTransport, Mocks
from modules.definition import ModuleDefinition, default_module_paths, load_definitions

__all__ = ["TreeTest", "TreeRun", "Coverage"]


class TreeRun:
    """What happened in one run: final status, calls in order, blackboard, node statuses."""

    def __init__(self, result: RunResult, transport: InProcessTransport):
        self.result = result
        self.status: Status = result.status
        self.reason = result.reason
        self.duration = result.duration
        self.transport = transport
        self._by_name: Dict[str, List[str]] = {}
        for b, statuses in result.history.items():
            self._by_name.setdefault(b.name, [s.value for s in statuses])

    @property
    def succeeded(self) -> bool:
        return self.status == Status.SUCCESS

    @property
    def failed(self) -> bool:
        return self.status == Status.FAILURE

    def calls(self, target: Optional[str] = None) -> List[CallRecord]:
        """Calls in order, all or those of ``module.function``."""
        return [c for c in self.result.calls if target is None or c.target == target]

    @property
    def targets(self) -> List[str]:
        return [c.target for c in self.result.calls]

    @property
    def blackboard(self) -> Dict[str, Any]:
        """The tree blackboard at the end, one-field messages unwrapped (``answer == "yes"``)."""
        return {k: plain(v) for k, v in self.result.blackboard.items()}

    def statuses(self, name: str) -> List[str]:
        """Statuses the first node called ``name`` went through (``["RUNNING", "SUCCESS"]``)."""
        if name not in self._by_name:
            raise KeyError("no node named %r ran (nodes: %s)" % (name, ", ".join(sorted(self._by_name))))
        return self._by_name[name]

    def said(self) -> List[str]:
        """Convenience for the speech module: every ``text`` passed to ``speech.say``."""
        return [c.inputs.get("text") for c in self.calls("speech.say")]


class Coverage:
    """Which nodes of which trees were ever ticked, and the outcomes each reached."""

    def __init__(self) -> None:
        self.trees: Dict[str, List[Node]] = {}
        self.reached: Dict[Any, Set[str]] = defaultdict(set)

    def add_tree(self, tree: TreeFile) -> None:
        seen: Dict[str, List[Node]] = {}
        for node in walk(tree.root):
            seen.setdefault(node.pos.file, [])
            if node not in seen[node.pos.file]:
                seen[node.pos.file].append(node)
        for f, nodes in seen.items():
            known = self.trees.setdefault(f, [])
            for n in nodes:
                if all(n.pos != k.pos for k in known):
                    known.append(n)

    def record(self, history: Mapping[Any, Iterable[Status]]) -> None:
        for b, statuses in history.items():
            node = getattr(b, "bmtree_node", None)
            if node is not None:
                self.reached[node.pos].update(s.value for s in statuses if s != Status.INVALID)

    def report(self) -> str:
        lines = ["bmtree tree coverage"]
        for f in sorted(self.trees):
            nodes = sorted(self.trees[f], key=lambda n: (n.pos.line, n.pos.column))
            ran = [n for n in nodes if self.reached.get(n.pos)]
            lines.append("%s: %d of %d nodes ran" % (f, len(ran), len(nodes)))
            for n in nodes:
                got = self.reached.get(n.pos, set())
                if not got:
                    lines.append("  %s:%d: %s '%s' never ran" % (f, n.pos.line, n.kind, n.name))
                else:
                    outcomes = [s for s in ("SUCCESS", "FAILURE") if s in got]
                    missing = [s for s in ("SUCCESS", "FAILURE") if s not in got]
                    lines.append("  %s:%d: %s '%s' reached %s%s" % (
                        f, n.pos.line, n.kind, n.name, ", ".join(outcomes) or "RUNNING only",
                        "; never %s" % ", ".join(missing) if missing else ""))
        return "\n".join(lines)


class TreeTest:
    """One tree, its mocked modules (``mocks``), a simulated clock; ``run()`` to completion.

    Args:
        path: the tree file.
        definitions: module definitions (default: the project's and ``$BMTREE_MODULE_PATH``).
        inputs: values for the tree's declared inputs.
        coverage: a :class:`Coverage` to record into (the pytest plugin passes one).
    """

    def __init__(self, path: str, definitions: Optional[Mapping[str, ModuleDefinition]] = None,
                 inputs: Optional[Dict[str, Any]] = None, coverage: Optional[Coverage] = None):
        self.definitions = dict(definitions) if definitions is not None else load_definitions(default_module_paths())
        self.inputs = dict(inputs or {})
        self.tree = load_tree(path, self.definitions, given=set(self.inputs))
        self.mocks = Mocks(self.definitions)
        self.coverage = coverage
        if coverage is not None:
            coverage.add_tree(self.tree)

    def run(self, max_duration: float = 3600.0, default_timeout: float = 30.0) -> TreeRun:
        """Run to SUCCESS/FAILURE (or ``max_duration`` simulated seconds)."""
        clock = SimClock()
        transport = InProcessTransport(self.mocks, clock)
        ctx = RunContext(transport, clock, self.definitions, default_timeout=default_timeout)
        root = build_tree(self.tree, ctx, self.inputs)
        result = TreeRunner(root, ctx, record_history=True).run(max_duration)
        if self.coverage is not None:
            self.coverage.record(result.history)
        return TreeRun(result, transport)
