"""Scripted mocks as real ROS module nodes, one process per module, for integration tests.

The script is the YAML form of the in-process kit's scripts::

    module: navigation
    functions:
      go_to:
        - fail: blocked
        - succeed: {room: kitchen}
          delay: 0.5                 # seconds, real time here
    events:
      - {at: 1.0, event: arrived, params: {place: kitchen}}   # seconds after the node started

Run one with ``python -m coordinator.testing.mocknode SCRIPT [--modules PATH]``, or from a
test with :func:`start_mock_node`, which writes the script of ``mocks`` for you. The node is
the real module runtime (input checks, busy, cancel, discovery); only the behaviour is scripted.
"""
from __future__ import annotations

import argparse
import os
import sys
import threading
from typing import Any, Callable, Dict, List, Optional

import yaml

from coordinator.testing.mocks import FunctionMock, MockError, Mocks, outcome_from_dict, outcome_to_dict
from modules.definition import DefinitionError, ModuleDefinition, default_module_paths, load_definitions
from modules.runtime import BasicModule, Failure, Rejected

__all__ = ["scripted_module", "script_of", "start_mock_node", "main"]


def _method(mock: FunctionMock) -> Callable[..., Dict[str, Any]]:
    def method(self: BasicModule, **inputs: Any) -> Dict[str, Any]:
        mock.calls.append(inputs)
        outcome = mock.next_outcome()
        ctx = self.context
        if outcome.kind == "hang":
            ctx.cancelled.wait()
            return {}
        if outcome.delay and not ctx.sleep(outcome.delay):
            return {}
        if outcome.kind == "fail":
            raise Failure(outcome.reason)
        if outcome.kind == "reject":
            raise Rejected(outcome.reason)
        return dict(outcome.outputs)
    method.__name__ = mock.fn.name
    return method


def scripted_module(definition: ModuleDefinition, script: Dict[str, Any]) -> BasicModule:
    """A module object whose functions follow ``script`` (see the module docstring)."""
    mocks = Mocks({definition.name: definition})
    unknown = set(script.get("functions") or {}) - set(definition.functions)
    if unknown:
        raise MockError("module %r has no function %s" % (definition.name, ", ".join(sorted(unknown))))
    for fname, outcomes in (script.get("functions") or {}).items():
        outcomes = outcomes if isinstance(outcomes, list) else [outcomes]
        mocks["%s.%s" % (definition.name, fname)].script(*[outcome_from_dict(o) for o in outcomes])
    methods = {name: _method(mocks["%s.%s" % (definition.name, name)]) for name in definition.functions}
    events = list(script.get("events") or [])
    for ev in events:
        if ev.get("event") not in definition.events:
            raise MockError("module %r has no event %r" % (definition.name, ev.get("event")))
        definition.events[ev["event"]].build_values(ev.get("params") or {})

    def setup(self: BasicModule, node: Any) -> None:
        for ev in events:
            t = threading.Timer(float(ev.get("at", 0.0)), self.emit, args=(ev["event"],),
                                kwargs=dict(ev.get("params") or {}))
            t.daemon = True
            t.start()

    cls = type("Mock_%s" % definition.name, (BasicModule,), dict(methods, setup=setup, concurrent=True))
    return cls()


def script_of(mocks: Mocks, module: str, events: Optional[List[Dict[str, Any]]] = None) -> Dict[str, Any]:
    """The YAML-able script of every function of ``module`` scripted in ``mocks``."""
    functions = {}
    for fname in mocks.definitions[module].functions:
        mock = mocks["%s.%s" % (module, fname)]
        if mock.outcomes:
            functions[fname] = [outcome_to_dict(o) for o in mock.outcomes]
    return {"module": module, "functions": functions, "events": list(events or [])}


def start_mock_node(ros_graph: Any, mocks: Mocks, module: str, events: Optional[List[Dict[str, Any]]] = None,
                    modules: Optional[List[str]] = None, timeout: float = 20.0) -> Any:
    """Start ``module`` of ``mocks`` as a real node on ``ros_graph``'s master; waits until it is announced."""
    import time

    from modules.discovery import live_modules

    path = os.path.join(ros_graph.ros_home, "mock_%s.yaml" % module)
    with open(path, "w") as fh:
        yaml.safe_dump(script_of(mocks, module, events), fh)
    args = ["-m", "coordinator.testing.mocknode", path]
    for m in modules or []:
        args += ["--modules", m]
    proc = ros_graph.start_node(args, "/bm_%s" % module, timeout=timeout)
    end = time.monotonic() + timeout
    while module not in live_modules(ros_graph.uri):
        if time.monotonic() > end:
            raise MockError("mock node of %r did not announce itself" % module)
        time.sleep(0.05)
    return proc


def main(argv: Optional[List[str]] = None) -> int:
    import rospy

    from modules.node import run_module

    p = argparse.ArgumentParser(prog="python -m coordinator.testing.mocknode", description=__doc__.split("\n")[0])
    p.add_argument("script")
    p.add_argument("--modules", action="append", metavar="PATH", help="definition file or directory")
    args = p.parse_args(rospy.myargv(argv if argv is not None else sys.argv)[1:])
    try:
        with open(args.script, encoding="utf-8") as fh:
            script = yaml.safe_load(fh) or {}
        defs = load_definitions(args.modules or default_module_paths())
        definition = defs[script["module"]]
        impl = scripted_module(definition, script)
    except (OSError, KeyError, DefinitionError, MockError, yaml.YAMLError) as exc:
        sys.stderr.write("error: %s: %s\n" % (args.script, exc))
        return 2
    return run_module(definition, impl, "bm_%s" % definition.name)


if __name__ == "__main__":
    sys.exit(main())
