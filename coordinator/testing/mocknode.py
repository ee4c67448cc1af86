"""Scripted mocks as real ROS module nodes, one process per module, for integration tests.

The script is the YAML form of the in-process kit's scripts (``--help`` shows it too)::

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
from typing import Any, Dict, List, Optional, Tuple

import yaml

from comm.errors import ProtocolError, did_you_mean
from coordinator.bounds import finite_number, shown
from coordinator.errors import Pos, TreeError, TreeErrors
from coordinator.testing.mocks import (
    MockError,
    MockModule,
    Mocks,
    mock_module,
    outcome_from_dict,
    outcome_to_dict,
)
from coordinator.yamlsrc import LList, LMap, load_file, pos_of
from modules.definition import DefinitionError, ModuleDefinition, default_module_paths, load_definitions

__all__ = ["load_script", "scripted_module", "script_of", "start_mock_node", "main"]

FORMAT = """script (YAML):
  module: navigation                 # the module the node plays (a name of the definitions)
  functions:                         # per function, its outcomes in turn; the last one repeats
    go_to:
      - fail: blocked                # also: reject: REASON, hang: true
      - succeed: {room: kitchen}     # the outputs, checked against the definition
        delay: 0.5                   # seconds (wall time) before the answer
  events:                            # emitted once, AT seconds after the coordinator connected
    - {at: 1.0, event: arrived, params: {place: kitchen}}
A function left out succeeds at once with zero/empty outputs. A mistake is reported as
SCRIPT:LINE:COLUMN: message, exit 2."""
_SCRIPT_KEYS = ("module", "functions", "events")
_EVENT_KEYS = ("at", "event", "params")
_OUTCOME_KEYS = ("succeed", "fail", "reject", "hang", "die", "delay")


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


def load_script(path: str, definitions: Dict[str, ModuleDefinition]) -> Tuple[ModuleDefinition, MockModule]:
    """The module a script file plays and its scripted module; TreeErrors lists every problem of the
    file, each as ``path:line:column: message`` (the format: :data:`FORMAT`)."""
    from coordinator.testing.scenariomocks import check_outputs, check_reason

    top = Pos(path, 1, 1)
    data = load_file(path)  # at most MAX_BYTES, and never a device (bmtree test /dev/zero)
    known = " (known: %s)" % (", ".join(sorted(definitions)) or "none")
    if not isinstance(data, LMap) or "module" not in data:
        raise TreeErrors([TreeError(getattr(data, "pos", None) or top, "a mock node's script needs 'module: NAME', "
                                    "the module it plays%s; then 'functions' and 'events' (--help)" % known)])
    errors: List[TreeError] = []
    for k in data:
        if k not in _SCRIPT_KEYS:
            errors.append(TreeError(data.key_pos[k], "unknown key %r%s" % (
                k, did_you_mean(k, _SCRIPT_KEYS) or " (a script has %s)" % ", ".join(_SCRIPT_KEYS))))
    name = data["module"]
    definition = definitions.get(name) if isinstance(name, str) else None
    if definition is None:
        errors.append(TreeError(pos_of(data, "module", top), "no module %r in the definitions%s" % (
            name, did_you_mean(name, definitions) or known)))
        raise TreeErrors(errors)
    functions = data.get("functions")
    if functions is not None and not isinstance(functions, LMap):
        errors.append(TreeError(pos_of(data, "functions", top), "functions is a mapping of function: outcomes "
                                                                "(a list, or one outcome)"))
    for fname, outcomes in (functions.items() if isinstance(functions, LMap) else ()):
        fn = definition.functions.get(fname)
        if fn is None:
            errors.append(TreeError(functions.key_pos[fname], "module %r has no function %r%s" % (
                name, fname, did_you_mean(fname, definition.functions) or " (its functions: %s)" % (
                    ", ".join(definition.functions) or "none"))))
            continue
        where = pos_of(functions, fname, top)
        if isinstance(outcomes, list) and not outcomes:
            errors.append(TreeError(where, "functions.%s: an empty list of outcomes (leave the function out for "
                                           "the default)" % fname))
            continue
        items, positions = (list(outcomes), outcomes.item_pos) if isinstance(outcomes, LList) else ([outcomes], [where])
        for raw, at in zip(items, positions):
            try:
                outcome_from_dict(raw)
            except MockError as exc:
                errors.append(TreeError(next((raw.key_pos[k] for k in raw if k not in _OUTCOME_KEYS), at)
                                        if isinstance(raw, LMap) else at, "%s: %s" % (fname, exc)))
                continue
            found = _Found()
            check_reason(raw, at, found)
            check_outputs(fn, raw, found)
            errors.extend(found.errors)
    events = data.get("events")
    if events is not None and not isinstance(events, LList):
        errors.append(TreeError(pos_of(data, "events", top), "events is a list of {at, event, params}"))
    for i, ev in enumerate(events if isinstance(events, LList) else ()):
        at = events.item_pos[i]
        if not isinstance(ev, LMap) or "event" not in ev:
            errors.append(TreeError(at, "an event is a mapping {at, event, params} (the events of %s: %s)" % (
                name, ", ".join(definition.events) or "none")))
            continue
        for k in ev:
            if k not in _EVENT_KEYS:
                errors.append(TreeError(ev.key_pos[k], "unknown event key %r%s" % (k, did_you_mean(k, _EVENT_KEYS))))
        when = ev.get("at", 0.0)
        if not finite_number(when) or when < 0:
            errors.append(TreeError(pos_of(ev, "at", at), "at must be a number of seconds >= 0, got %s" % shown(when)))
        if str(ev["event"]) not in definition.events:
            errors.append(TreeError(pos_of(ev, "event", at), "module %r has no event %r%s" % (
                name, ev["event"], did_you_mean(ev["event"], definition.events) or " (its events: %s)" % (
                    ", ".join(definition.events) or "none"))))
        elif ev.get("params") is not None and not isinstance(ev["params"], LMap):
            errors.append(TreeError(pos_of(ev, "params", at), "params is a mapping of name: value"))
        else:
            try:
                definition.events[str(ev["event"])].build_values(dict(ev.get("params") or {}))
            except ProtocolError as exc:
                errors.append(TreeError(pos_of(ev, "params", at), str(exc)))
    if errors:
        raise TreeErrors(errors)
    try:
        return definition, scripted_module(definition, data)
    except MockError as exc:  # what the checks above do not see (an event's params, ...): at the module
        raise TreeErrors([TreeError(pos_of(data, "module", top), str(exc))])


class _Found:
    """Where the scenario checks put their problems."""

    def __init__(self) -> None:
        self.errors: List[TreeError] = []

    def add(self, at: Pos, message: str) -> None:
        self.errors.append(TreeError(at, message))


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


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m coordinator.testing.mocknode", description=__doc__.split("\n")[0],
                                epilog=FORMAT, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("script", help="the YAML script: the module the node plays and its outcomes (below)")
    p.add_argument("--modules", action="append", metavar="PATH",
                   help="definition file or directory (repeatable; default: the definitions bmtree finds)")
    return p


def main(argv: Optional[List[str]] = None) -> int:
    import rospy

    from modules.node import run_module

    args = make_parser().parse_args(rospy.myargv(argv if argv is not None else sys.argv)[1:])
    try:
        defs = load_definitions(args.modules or default_module_paths())
    except (OSError, DefinitionError) as exc:
        sys.stderr.write("error: %s\n" % exc)
        return 2
    try:
        definition, impl = load_script(args.script, defs)
    except TreeErrors as exc:
        sys.stderr.write("%s\n" % exc)
        return 2
    return run_module(definition, impl, "bm_%s" % definition.name)

if __name__ == "__main__":
    sys.exit(main())
