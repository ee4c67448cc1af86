"""Scripted mocks as real ROS module nodes, one process per module, for integration tests.

The script is the YAML form of the in-process kit's scripts::

    module: navigation
    functions:
      go_to:
        - fail: blocked
        - succeed: {room: kitchen}
          delay: 0.5                 # seconds, real time here
    events:
      - {at: 1.0, event: arrived, params: {place: kitchen}}   # seconds after a subscriber (the
                                                              # coordinator) connected to /event/output

Run one with ``python -m coordinator.testing.mocknode SCRIPT [--modules PATH]``, or from a
test with :func:`start_mock_node`, which writes the script of ``mocks`` for you. The node is
the real module runtime (input checks, busy, cancel, discovery) serving the same scripted
module as the in-process transport (:class:`~coordinator.testing.mocks.MockModule`), on worker
threads and wall time instead of the simulated clock.
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import Any, Dict, List, Optional

import yaml

from coordinator.testing.mocks import (
    MockError,
    MockModule,
    Mocks,
    mock_module,
    outcome_from_dict,
    outcome_to_dict,
)
from modules.definition import DefinitionError, ModuleDefinition, default_module_paths, load_definitions

__all__ = ["scripted_module", "script_of", "start_mock_node", "main"]


def scripted_module(definition: ModuleDefinition, script: Dict[str, Any]) -> MockModule:
    """A module object whose functions follow ``script`` (see the module docstring)."""
    mocks = Mocks({definition.name: definition})
    unknown = set(script.get("functions") or {}) - set(definition.functions)
    if unknown:
        raise MockError("module %r has no function %s" % (definition.name, ", ".join(sorted(unknown))))
    for fname, outcomes in (script.get("functions") or {}).items():
        outcomes = outcomes if isinstance(outcomes, list) else [outcomes]
        mocks["%s.%s" % (definition.name, fname)].script(*[outcome_from_dict(o) for o in outcomes])
    for ev in script.get("events") or []:
        if not isinstance(ev, dict):
            raise MockError("an event is a mapping {at, event, params}, got %r" % (ev,))
        mocks.event(float(ev.get("at", 0.0)), "%s.%s" % (definition.name, ev.get("event")), **dict(ev.get("params") or {}))
    return mock_module(mocks, definition.name)


def script_of(mocks: Mocks, module: str, events: Optional[List[Dict[str, Any]]] = None) -> Dict[str, Any]:
    """The YAML-able script of every function of ``module`` scripted in ``mocks``, with its
    events of ``mocks`` and ``events``."""
    functions = {}
    for fname in mocks.definitions[module].functions:
        mock = mocks["%s.%s" % (module, fname)]
        if mock.outcomes:
            functions[fname] = [outcome_to_dict(o) for o in mock.outcomes]
    tied = [name for _, _, _, mod, name, _ in mocks.call_events if mod == module]
    if tied:  # a node's events count from when the coordinator connected; it sees no call of another module
        raise MockError("events tied to a call (event_after: %s.%s) run in process only, not on a mock node"
                        % (module, tied[0]))
    scheduled = [{"at": at, "event": name, "params": params}
                 for at, mod, name, params in mocks.scheduled_events if mod == module]
    return {"module": module, "functions": functions, "events": scheduled + list(events or [])}


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
    except (OSError, KeyError, TypeError, ValueError, AttributeError, DefinitionError, MockError,
            yaml.YAMLError) as exc:
        sys.stderr.write("error: %s: %s\n" % (args.script, exc))
        return 2
    return run_module(definition, impl, "bm_%s" % definition.name)


if __name__ == "__main__":
    sys.exit(main())
