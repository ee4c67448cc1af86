"""Mocked modules built from definitions, served by the real module runtime on the run's clock.

A mock is a scripted module (:class:`MockModule`): each function follows its script of
outcomes (:mod:`modules.outcome`). The in-process transport serves it with the same
:class:`~modules.runtime.ModuleServer` a robot's module node uses, on the run's simulated
clock (:mod:`coordinator.testing.inprocess`), so it refuses what the real module refuses with the same texts: an unknown function,
missing or ill-typed inputs, a second non-concurrent call while one runs (``busy with call
…``); it answers cancels the same way. A scripted output that breaks the definition is refused
when scripted. Delays, hangs and events cost no time under a :class:`SimClock`. Values the
Blackboard node held before the run (:meth:`Mocks.stored`) go into the in-process Blackboard
through the real service, as results of earlier runs would.
"""
from __future__ import annotations

import dataclasses
import threading
import time
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple

from comm.errors import ProtocolError, did_you_mean
from comm.typewords import said_of
from coordinator.bounds import finite_number, shown
from coordinator.context import plain
from coordinator.testing.expected import legacy_times
from modules.definition import FunctionDefinition, ModuleDefinition
from modules.outcome import (
    Outcome,
    OutcomeError,
    OutcomeKind,
    die,
    fail,
    hang,
    reject,
    respond,
    succeed,
)
from modules.outcome import outcome_from_dict as _outcome_from_dict
from modules.outcome import outcome_to_dict as _outcome_to_dict
from modules.runtime import BasicModule

__all__ = ["MockError", "StoredNameError", "FunctionMock", "Mocks", "MockModule", "mock_module",
           "StoredEntry", "stored_value",
           # the outcome type (modules.outcome), re-exported for test authors
           "Outcome", "OutcomeKind", "OUTCOME_KINDS", "succeed", "fail", "hang", "die", "reject", "respond",
           "outcome_from_dict", "outcome_to_dict"]

#: how to give a mocked module's definition, said when there is none (a team's module, in a scenario run where
#: its catkin workspace is not sourced)
NO_DEFINITION = ("give its definition: modules: in the scenario file (a file or folder, relative to it), --modules "
                 "FILE.json or a folder, bmtree_modules in pytest.ini, or the export of its catkin package (bmtree "
                 "definitions in its package.xml) with the workspace sourced")

OUTCOME_KINDS = tuple(k.value for k in OutcomeKind if k != OutcomeKind.RESPOND)  # the written ones


class MockError(AssertionError):
    """A script that the real module could never follow (fails the test)."""


class StoredNameError(MockError):
    """A name given to :meth:`Mocks.stored` that no output of the definitions answers to, or that
    several do with types the value fits (a scenario file reports it at the name, not the value)."""


StoredEntry = Tuple[Optional[str], Optional[str], str, Any]
"""(module, function, output, message) of a value stored before the run; no module and
function for a plain name that several functions' outputs have."""


def _known(names: Any) -> str:
    return ", ".join(sorted(names)) or "none"


def stored_value(definitions: Mapping[str, ModuleDefinition], name: Any, value: Any,
                 legacy: bool = False) -> StoredEntry:
    """What the Blackboard would hold under ``name`` (as a ``recall`` takes it) after a result
    with ``value``: the output's type comes from the definitions, the value is converted as a
    scripted output is. ``legacy``: times as older run logs wrote them are accepted (scenario
    files). StoredNameError for a name no output answers to (with a did-you-mean), or a plain
    name whose outputs have several types the value fits; MockError for a value that fits none."""
    prefix = "stored %r: " % (name,)
    parts = name.split("/") if isinstance(name, str) else []
    if len(parts) == 3 and all(parts):
        mod_name, fname, out = parts
        mod = definitions.get(mod_name)
        if mod is None:
            raise StoredNameError(prefix + "no module %r in the definitions%s" % (
                mod_name, did_you_mean(mod_name, definitions) or " (known: %s)" % _known(definitions)))
        fn = mod.functions.get(fname)
        if fn is None:
            raise StoredNameError(prefix + "module %r has no function %r%s" % (
                mod_name, fname, did_you_mean(fname, mod.functions) or " (functions: %s)" % _known(mod.functions)))
        outputs = {q.name: q for q in fn.outputs}
        if out not in outputs:
            raise StoredNameError(prefix + "%s has no output %r%s" % (
                fn.qualified, out, did_you_mean(out, outputs) or " (its outputs: %s)" % _known(outputs)))
        return mod_name, fname, out, _stored_message(prefix, fn, outputs[out], value, legacy)
    if len(parts) != 1 or not parts[0]:
        raise StoredNameError(prefix + "a Blackboard name is 'output' or 'module/function/output', as a recall "
                                       "takes it")
    candidates = [(fn, q) for mod in definitions.values() for fn in mod.functions.values() for q in fn.outputs
                  if q.name == name]
    if not candidates:
        known = {q.name for mod in definitions.values() for fn in mod.functions.values() for q in fn.outputs}
        raise StoredNameError(prefix + "no function of the definitions has an output %r%s" % (
            name, did_you_mean(name, known) or " (outputs: %s)" % _known(known)))
    fits: Dict[str, Any] = {}       # ROS type -> the value as that type
    misfits: Dict[str, str] = {}    # ROS type -> why the value does not fit it
    for fn, q in candidates:
        if q.rostype not in fits and q.rostype not in misfits:
            try:
                fits[q.rostype] = _stored_message("", fn, q, value, legacy)
            except MockError as exc:
                misfits[q.rostype] = str(exc)
    every = ", ".join("%s/%s/%s (%s)" % (fn.module, fn.name, q.name, q.rostype) for fn, q in candidates)
    if not fits:
        if len(misfits) == 1:
            raise MockError(prefix + next(iter(misfits.values())))
        raise MockError(prefix + "the value fits none of the types of the outputs named %r: %s; give "
                                 "'module/function/output' (candidates: %s)" % (name, "; ".join(misfits.values()), every))
    if len(fits) > 1:
        raise StoredNameError(prefix + "the value fits outputs named %r of %d types (%s): give 'module/function/output' "
                                       "(candidates: %s)" % (name, len(fits), ", ".join(sorted(fits)), every))
    rostype, msg = next(iter(fits.items()))
    owners = [fn for fn, q in candidates if q.rostype == rostype]
    if len(owners) == 1:  # only that function stores it: a qualified recall of it finds the value too
        return owners[0].module, owners[0].name, name, msg
    return None, None, name, msg


def _stored_message(prefix: str, fn: FunctionDefinition, q: Any, value: Any, legacy: bool) -> Any:
    """``value`` as output ``q`` of ``fn``: the scripted outputs' converter, and their words for a misfit."""
    try:
        return q.convert(legacy_times(q.rostype, value) if legacy else value)
    except ProtocolError as exc:
        raise MockError(prefix + said_of("%s output %r" % (fn.qualified, q.name), exc))


def outcome_from_dict(raw: Any) -> Outcome:
    """The written form of an outcome (:func:`modules.outcome.outcome_from_dict`); MockError if wrong."""
    try:
        return _outcome_from_dict(raw)
    except OutcomeError as exc:
        raise MockError(str(exc))


def _at(at: Any) -> float:
    """An event's ``at`` (seconds) as a float; MockError for what is not a finite number."""
    __tracebackhide__ = True
    if not finite_number(at):
        raise MockError("at must be a finite number of seconds, got %s" % shown(at))
    return float(at)


def outcome_to_dict(outcome: Outcome) -> Dict[str, Any]:
    """The written form of ``outcome``; MockError for a respond (Python cannot go to a mock node)."""
    try:
        return _outcome_to_dict(outcome)
    except OutcomeError:
        raise MockError("a respond(...) outcome runs Python and cannot be sent to a mock node process")


def _zero(fn: FunctionDefinition) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for p in fn.outputs:
        out[p.name] = True if p.name == "success" and p.rostype == "std_msgs/Bool" else {}
    return out


class FunctionMock:
    """The script of one ``module.function``: outcomes in order, the last one repeats."""

    def __init__(self, fn: FunctionDefinition):
        self.fn = fn
        self.outcomes: List[Outcome] = []
        self.calls: List[Dict[str, Any]] = []
        self._default: Optional[Outcome] = None
        self.ignores_cancel = False   # every outcome ignores cancels (see ignoring_cancels)
        self.unscripted = 0   # calls answered by the default (no script): success, empty outputs

    def _check(self, outcome: Outcome) -> Outcome:
        """Complete a succeed's outputs with the defaults of :func:`_zero` and check them against the definition."""
        __tracebackhide__ = True
        if outcome.kind == OutcomeKind.SUCCEED:
            outputs = dict(_zero(self.fn), **outcome.outputs)
            try:
                self.fn.build_result(outputs)
            except ProtocolError as exc:
                raise MockError("scripted outputs of %s break its definition: %s" % (self.fn.qualified, exc)) from None
            outcome.outputs = outputs
        return outcome

    def script(self, *outcomes: Outcome) -> FunctionMock:
        """Replace the script; the last outcome repeats for further calls."""
        __tracebackhide__ = True
        checked = []
        for o in outcomes:  # a loop, not a comprehension: no frame of its own for pytest to show
            checked.append(self._check(o))
        self.outcomes = checked
        return self

    def then(self, *outcomes: Outcome) -> FunctionMock:
        __tracebackhide__ = True
        for o in outcomes:
            self.outcomes.append(self._check(o))
        return self

    def succeed(self, delay: float = 0.0, **outputs: Any) -> FunctionMock:
        __tracebackhide__ = True
        return self.script(succeed(delay, **outputs))

    def fail(self, reason: str = "failed (mock)", delay: float = 0.0) -> FunctionMock:
        return self.script(fail(reason, delay))

    def hang(self) -> FunctionMock:
        return self.script(hang())

    def die(self, reason: str = "its process died (mock)", delay: float = 0.0) -> FunctionMock:
        """The module's node dies during the call: it and the module's other calls in flight end
        ``module_lost`` (``module gripper lost: REASON``); the calls after it are answered again."""
        return self.script(die(reason, delay))

    def respond(self, fn: Callable[..., Any], delay: float = 0.0) -> FunctionMock:
        return self.script(respond(fn, delay))

    def fail_first(self, n: int, reason: str = "failed (mock)", **outputs: Any) -> FunctionMock:
        """Fail the first ``n`` calls, then succeed with ``outputs``."""
        __tracebackhide__ = True
        return self.script(*([fail(reason)] * n + [succeed(**outputs)]))

    def next_outcome(self) -> Outcome:
        if not self.outcomes:  # unscripted: succeed with zero outputs (checked once)
            self.unscripted += 1
            if self._default is None:
                self._default = self._check(succeed())
            return self._default
        index = min(len(self.calls) - 1, len(self.outcomes) - 1)
        return self.outcomes[index]

    def ignoring_cancels(self) -> FunctionMock:
        """Every outcome ignores cancels, as an original module behind ``bmtree-bridge`` does (it
        cannot be interrupted): a halted call is answered ``cancelled`` after the runtime's grace,
        and the module stays busy (``rejected: busy``) until the scripted delay is over."""
        self.ignores_cancel = True
        return self

    @property
    def says_more(self) -> bool:
        """The function has outputs besides a ``success`` flag: its default answer (empty text, zeros) is
        a value the tree may use, not just "it worked"."""
        return any(not (p.name == "success" and p.rostype == "std_msgs/Bool") for p in self.fn.outputs)

    def answer(self, inputs: Dict[str, Any], errors: List[MockError], strict: bool = False) -> Outcome:
        """Record a call (its inputs as plain data) and give its outcome; a respond's function
        gets the plain inputs, and its outputs are completed and checked like a succeed's (a
        MockError, also noted in ``errors``, and the runtime answers ``failed``). ``strict``: an
        unscripted call is answered ``failed`` (and counted: the test fails, see :meth:`Mocks.unscripted`)."""
        plain_inputs = {k: plain(v) for k, v in inputs.items()}
        self.calls.append(plain_inputs)
        if strict and not self.outcomes:   # the kit fails the test once the run is over, naming every one
            self.unscripted += 1
            return fail("not scripted (strict mocks)")
        outcome = self.next_outcome()
        if self.ignores_cancel:
            outcome = dataclasses.replace(outcome, ignores_cancel=True)
        if outcome.kind != OutcomeKind.RESPOND or outcome.fn is None:
            return outcome
        user_fn = outcome.fn

        def compute(**_messages: Any) -> Outcome:
            out = user_fn(**plain_inputs)
            try:
                checked = self._check(out if isinstance(out, Outcome) else succeed(**(out or {})))
            except MockError as exc:
                errors.append(exc)
                raise
            return dataclasses.replace(checked, ignores_cancel=True) if self.ignores_cancel else checked

        return dataclasses.replace(respond(compute, outcome.delay), ignores_cancel=outcome.ignores_cancel)


class Mocks:
    """Every function of every module of the definitions, mocked: ``mocks["speech.say"]``."""

    def __init__(self, definitions: Mapping[str, ModuleDefinition]):
        self.definitions = dict(definitions)
        self._fns: Dict[str, FunctionMock] = {}
        self.scheduled_events: List[Tuple[float, str, str, Dict[str, Any]]] = []
        # events tied to a call: (module.function, which of its calls from 1, seconds after it started, module, event, params)
        self.call_events: List[Tuple[str, int, float, str, str, Dict[str, Any]]] = []
        self.errors: List[MockError] = []
        #: a call to a function without a script fails the test (MockError) instead of succeeding with
        #: empty outputs (the pytest ini key ``bmtree_strict_mocks``, ``TreeTest(strict=True)``)
        self.strict = False
        # values the Blackboard node held before the run: one list per stored() call, oldest first
        self.stored_values: List[List[StoredEntry]] = []

    def __getitem__(self, target: str) -> FunctionMock:
        __tracebackhide__ = True
        if target not in self._fns:
            mod, _, fname = target.partition(".")
            if mod not in self.definitions:
                raise MockError("no module %r to mock (known: %s; %s)" % (mod, ", ".join(sorted(self.definitions)),
                                                                          NO_DEFINITION))
            try:
                fn = self.definitions[mod].function(fname)
            except ProtocolError as exc:
                raise MockError(str(exc)) from None
            self._fns[target] = FunctionMock(fn)
        return self._fns[target]

    def unscripted(self, every: bool = False) -> Dict[str, int]:
        """``module.function`` -> how many of its calls were answered without a script (success, empty
        outputs; under ``strict``, failed), for the functions whose outputs say more than ``success`` (a
        test may pass on them while the tree used an empty text or a zero position), or ``every`` one."""
        return {t: f.unscripted for t, f in sorted(self._fns.items()) if f.unscripted and (every or f.says_more)}

    def stored(self, values: Mapping[str, Any]) -> Mocks:
        """Values the Blackboard node held before the run (stored by earlier runs), so that a
        ``recall`` of them can succeed: ``{"vision/find_object/room": "kitchen", "text": "yes"}``.
        Names as a ``recall`` takes them: ``module/function/output``, or a plain ``output`` when
        exactly one type among the definitions' outputs of that name fits the value (stored as that
        function's output if only one function has it, else as no particular function's: then only
        a plain recall finds it). Each call stores values newer than the previous call's, all older
        than the run's own results (a ``history`` request lists them after those, newest first).
        MockError (StoredNameError for a name) naming every problem; nothing is stored then."""
        __tracebackhide__ = True
        entries: List[StoredEntry] = []
        problems: List[MockError] = []
        for name, value in values.items():
            try:
                entries.append(stored_value(self.definitions, name, value))
            except MockError as exc:
                problems.append(exc)
        if len(problems) == 1:
            raise problems[0].with_traceback(None)
        if problems:
            raise MockError("; ".join(map(str, problems)))
        self.stored_values.append(entries)
        return self

    def ignoring_cancels(self, *targets: str) -> Mocks:
        """``module`` or ``module.function``: its outcomes ignore cancels, as an original module
        behind ``bmtree-bridge`` (see :meth:`FunctionMock.ignoring_cancels`)."""
        __tracebackhide__ = True
        for target in targets:
            mod, _, fname = target.partition(".")
            if not fname:
                if mod not in self.definitions:
                    raise MockError("no module %r to mock%s" % (mod, did_you_mean(mod, self.definitions) or " (known: %s; "
                                                                  "%s)" % (", ".join(sorted(self.definitions)), NO_DEFINITION)))
                for name in self.definitions[mod].functions:
                    self["%s.%s" % (mod, name)].ignoring_cancels()
            else:
                self[target].ignoring_cancels()
        return self

    def event(self, at: float, target: str, **params: Any) -> None:
        """Emit ``module.event`` with ``params`` at ``at`` seconds after the start (of the run, or of a mock node)."""
        __tracebackhide__ = True
        mod, name = self._checked_event(target, params)
        self.scheduled_events.append((_at(at), mod, name, dict(params)))

    def event_after(self, call: str, at: float, target: str, params: Optional[Dict[str, Any]] = None,
                    nth: int = 1) -> None:
        """Emit ``module.event`` with ``params`` ``at`` seconds after the ``nth`` call (from 1) of
        ``call`` (``module.function``) started, in process (never if the run makes no such call).
        Against that call's ``delay``: an ``at`` below it comes before its answer, equal to it with
        the answer (the tree takes both at its next tick), above it after the tree took the answer."""
        __tracebackhide__ = True
        self[call]  # a function there is
        if isinstance(nth, bool) or not isinstance(nth, int) or nth < 1:
            raise MockError("nth is a whole number >= 1, got %r" % (nth,))
        mod, name = self._checked_event(target, dict(params or {}))
        self.call_events.append((call, nth, _at(at), mod, name, dict(params or {})))

    def _checked_event(self, target: str, params: Dict[str, Any]) -> Tuple[str, str]:
        __tracebackhide__ = True
        mod, _, name = target.partition(".")
        ev = self.definitions.get(mod) and self.definitions[mod].events.get(name)
        if not ev:
            known = ["%s.%s" % (m, e) for m, d in self.definitions.items() for e in d.events]
            raise MockError("no event %r in the definitions%s" % (target, did_you_mean(target, known) or (
                " (module %r has no events)" % mod if mod in self.definitions and not self.definitions[mod].events
                else "")))
        try:
            ev.build_values(params)
        except ProtocolError as exc:
            raise MockError(str(exc)) from None
        return mod, name


class MockModule(BasicModule):
    """A module whose functions follow the scripts of ``mocks``: the real runtime serves it, in
    process (:class:`InProcessTransport`) or as a node (:mod:`coordinator.testing.mocknode`).
    Its functions are concurrent exactly where the definition says so. Make one with
    :func:`mock_module` (one method per function of the definition)."""

    def __init__(self, mocks: Mocks, module: str):
        super().__init__()
        self._mocks = mocks
        self._module = module

    def _start_events(self) -> None:
        """Schedule this module's events of ``mocks`` on the module's clock, from now."""
        assert self._server is not None, "module not bound to a server"
        for at, mod, name, params in self._mocks.scheduled_events:
            if mod == self._module:
                self._server.scheduler.call_later(at, lambda name=name, params=params: self.emit(name, **params))

    def setup(self, node: Any) -> None:
        """As a node: the events' times count from when a subscriber (the coordinator under test)
        connected to the events, so that none is emitted before anyone listens."""
        publisher = getattr(node, "event_publisher", None)
        if publisher is None or not any(mod == self._module for _, mod, _, _ in self._mocks.scheduled_events):
            self._start_events()
            return

        def start_when_heard() -> None:
            import rospy

            while publisher.get_num_connections() < 1 and not rospy.is_shutdown():
                time.sleep(0.02)
            self._start_events()

        threading.Thread(target=start_when_heard, name="%s-events" % self._module, daemon=True).start()


def mock_module(mocks: Mocks, module: str) -> MockModule:
    """A :class:`MockModule` with one method per function of ``module``'s definition."""
    methods = {name: _scripted("%s.%s" % (module, name), name) for name in mocks.definitions[module].functions}
    return type("Mock_%s" % module, (MockModule,), methods)(mocks, module)


def _scripted(target: str, name: str) -> Callable[..., Outcome]:
    def method(self: MockModule, **inputs: Any) -> Outcome:
        return self._mocks[target].answer(inputs, self._mocks.errors, self._mocks.strict)
    method.__name__ = name
    return method
