"""A scenario's ``stored``, ``mocks`` and ``events``, checked where each is written and applied
to the run's mocks; and the small checks that every key of a scenario file shares."""
from __future__ import annotations

from typing import Any, Dict, List

from comm.errors import ProtocolError, did_you_mean
from comm.typewords import said_of
from coordinator.bounds import finite_number, shown
from coordinator.errors import Pos, TreeError
from coordinator.testing.expected import legacy_times
from coordinator.testing.mocks import (
    MockError,
    Mocks,
    StoredEntry,
    StoredNameError,
    outcome_from_dict,
    stored_value,
)
from coordinator.testing.scenariokeys import event_problem
from coordinator.testing.scenariokeys import function_of as _function
from coordinator.yamlsrc import LList, LMap, pos_of
from modules.definition import ModuleDefinition

__all__ = ["Problems", "check_keys", "check_outputs", "check_reason", "count", "event", "mapping", "number", "script", "stored"]

_EVENT_KEYS = ("at", "event", "params", "after", "nth")
_OUTCOME_KEYS = ("succeed", "fail", "reject", "hang", "die", "delay")


class Problems:
    """The problems of a scenario file, collected: every one is reported, not only the first."""

    def __init__(self) -> None:
        self.errors: List[TreeError] = []

    def add(self, at: Pos, message: str) -> None:
        self.errors.append(TreeError(at, message))


def check_keys(m: LMap, allowed: Any, what: str, out: Problems) -> None:
    """Each key of ``m`` one of ``allowed``: else an error with the closest one, or all of them."""
    for k in m:
        if k not in allowed:
            out.add(m.key_pos[k], "unknown %s key %r%s" % (what, k, did_you_mean(k, allowed) or " (%s keys: %s)" % (
                what, ", ".join(allowed))))


def number(m: LMap, key: str, default: float, at: Pos, out: Problems) -> float:
    """``m[key]`` as a non-negative number of seconds, else ``default`` after a positioned error."""
    value = m.get(key, default)
    if not finite_number(value) or value < 0:
        out.add(pos_of(m, key, at), "%s must be a number of seconds >= 0, got %s" % (key, shown(value)))
        return default
    return float(value)


def count(m: LMap, key: str, default: int, at: Pos, out: Problems) -> int:
    """``m[key]`` as a whole number >= 1, else ``default`` after a positioned error."""
    value = m.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        out.add(pos_of(m, key, at), "%s must be a whole number >= 1, got %r" % (key, value))
        return default
    return value


def mapping(m: Any, key: str, at: Pos, what: str, out: Problems) -> Any:
    """``m[key]`` as a mapping (empty when absent or null, or after a positioned error saying ``what``)."""
    value = m.get(key)
    if value is None:
        return {}
    if not isinstance(value, dict):
        out.add(pos_of(m, key, at), what)
        return {}
    return value


def stored(sc: LMap, at: Pos, defs: Dict[str, ModuleDefinition], out: Problems) -> List[List[StoredEntry]]:
    """``stored``: the values the Blackboard node held before the run, a mapping of Blackboard name:
    value or a list of them (oldest first, for a history), each checked where it is written."""
    raw = sc.get("stored")
    if raw is None:
        return []
    what = "stored is a mapping of Blackboard name (output or module/function/output): value, or a list of them"
    if isinstance(raw, LMap):
        batches, positions = [raw], [pos_of(sc, "stored", at)]
    elif isinstance(raw, LList) and raw and all(isinstance(b, LMap) for b in raw):
        batches, positions = list(raw), raw.item_pos
    else:
        out.add(pos_of(sc, "stored", at), what)
        return []
    found = []
    for batch, b_at in zip(batches, positions):
        entries = []
        for name, value in batch.items():
            try:
                entries.append(stored_value(defs, name, value, legacy=True))
            except StoredNameError as exc:
                out.add(batch.key_pos.get(name, b_at), str(exc))
            except MockError as exc:
                out.add(batch.val_pos.get(name, b_at), str(exc))
        found.append(entries)
    return found


def event(mocked: Mocks, ev: Any, ev_at: Pos, defs: Dict[str, ModuleDefinition], out: Problems) -> None:
    """Check one event of ``events`` and schedule it (its problems to ``out``, each where it is written)."""
    if not isinstance(ev, LMap) or "event" not in ev:
        out.add(ev_at, "an event needs 'event: module.event' (and 'at', 'params')")
        return
    check_keys(ev, _EVENT_KEYS, "event", out)
    params = ev.get("params") or {}
    if not isinstance(params, dict) or not all(isinstance(k, str) for k in params):
        out.add(pos_of(ev, "params", ev_at), "params is a mapping of name: value")
        return
    when = number(ev, "at", 0.0, ev_at, out)
    after = ev.get("after")
    if after is not None:
        fn, why = _function(defs, after)
        if fn is None:
            out.add(pos_of(ev, "after", ev_at), "after is the module.function whose call the event follows: %s" % why)
            return
    nth = count(ev, "nth", 1, ev_at, out)
    if "nth" in ev and after is None:
        out.add(pos_of(ev, "nth", ev_at), "nth counts the calls of the function 'after' names: give 'after' too")
    target = str(ev["event"])
    mod, _, name = target.partition(".")
    event = defs[mod].events.get(name) if mod in defs else None
    if event is not None:  # older run logs recorded a time as its nanoseconds in text
        types = {q.name: q.rostype for q in event.params}
        params = {k: legacy_times(types[k], v) if k in types else v for k, v in params.items()}
    try:
        if after is None:
            mocked.event(when, target, **dict(params))
        else:
            mocked.event_after(str(after), when, target, dict(params), nth)
    except MockError as exc:
        out.add(pos_of(ev, "event", ev_at) if event is None else ev_at, event_problem(str(exc), event, params))


def script(mocked: Mocks, mocks: Any, target: Any, outcomes: Any, at: Pos, out: Problems) -> None:
    """Script one mocked function (its problems to ``out``, each where it is written)."""
    t_at = mocks.key_pos.get(target, at) if isinstance(mocks, LMap) else at
    if not isinstance(target, str):
        out.add(t_at, "mocks: %r is not a module.function" % (target,))
        return
    if isinstance(outcomes, list) and not outcomes:
        out.add(pos_of(mocks, target, at), "mocks.%s: an empty list of outcomes (leave the function out for the "
                                           "mock's default)" % target)
        return
    if isinstance(outcomes, LList):
        outcomes_list, positions = list(outcomes), outcomes.item_pos
    else:
        outcomes_list, positions = [outcomes], [pos_of(mocks, target, at)]
    try:
        mock = mocked[target]
    except MockError as exc:
        out.add(t_at, str(exc))
        return
    written, before = [], len(out.errors)
    for raw, where in zip(outcomes_list, positions):
        try:
            written.append(outcome_from_dict(_legacy_outputs(mock.fn, raw)))
        except MockError as exc:  # at a misspelt key (fial:) when there is one
            out.add(next((raw.key_pos[k] for k in raw if k not in _OUTCOME_KEYS), where)
                    if isinstance(raw, LMap) else where, str(exc))
            continue
        check_reason(raw, where, out)
        check_outputs(mock.fn, raw, out)
    if len(out.errors) > before:
        return
    try:
        mock.script(*written)
    except MockError as exc:
        out.add(t_at, str(exc))


def _legacy_outputs(fn: Any, raw: Any) -> Any:
    """A ``succeed``'s outputs with the times that older run logs recorded as nanoseconds in text
    made ``{secs, nsecs}`` (scenarios written from those logs), by the outputs' types."""
    outputs = raw.get("succeed") if isinstance(raw, dict) else None
    if not isinstance(outputs, dict):
        return raw
    types = {q.name: q.rostype for q in fn.outputs}
    return dict(raw, succeed={k: legacy_times(types[k], v) if k in types else v for k, v in outputs.items()})


def check_reason(raw: Any, where: Pos, out: Problems) -> None:
    """``fail``/``reject`` take the reason as text, ``hang`` takes ``true``, ``die`` either."""
    for kind in ("fail", "reject"):
        if kind in raw and not isinstance(raw[kind], str):
            out.add(pos_of(raw, kind, where), "%s takes the reason as text (%s: blocked by a chair), got %r" % (
                kind, kind, raw[kind]))
    if "hang" in raw and raw["hang"] is not True:
        out.add(pos_of(raw, "hang", where), "hang takes true, got %r" % (raw["hang"],))
    if "die" in raw and raw["die"] is not True and not isinstance(raw["die"], str):
        out.add(pos_of(raw, "die", where), "die takes the reason as text (die: its process is gone), or true, "
                "got %r" % (raw["die"],))


def check_outputs(fn: Any, raw: Any, out: Problems) -> None:
    """A ``succeed``'s outputs against the function's definition: each problem at its output."""
    outputs = raw.get("succeed") if isinstance(raw, LMap) else None
    if not isinstance(outputs, LMap):
        return
    params = {q.name: q for q in fn.outputs}
    for name, value in outputs.items():
        q = params.get(name)
        if q is None:
            out.add(outputs.key_pos[name], "%s has no output %r%s" % (fn.qualified, name, did_you_mean(
                name, params) or " (its outputs: %s)" % (", ".join(params) or "none")))
            continue
        try:
            q.convert(legacy_times(q.rostype, value))
        except ProtocolError as exc:
            out.add(outputs.val_pos[name], said_of("%s output %r" % (fn.qualified, name), exc))
