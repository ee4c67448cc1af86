"""A recorded run as a ``bmtree test`` scenario: the field run becomes a regression test.

Every module answers as it did (per function, in call order: outputs, failure or
rejection text, and how long it took); a call whose module's node died (``module_lost``)
dies as it did, with the same text, after the same time; a call that never got an answer
(timed out, halted, still running at the end) hangs. The expectations are the recorded result and
the calls in order with their inputs, so ``bmtree test`` reproduces the same path on
simulated time, and a changed tree shows which calls changed.

Events keep their place among the calls, not their clock time: simulated time skips what a
real run spends between a call's answer and the next call (about a millisecond a call), so
after twenty calls an event at its recorded time would come later than it did against the
calls, after a ``wait_event`` that in the run started after it. An event is written tied to
the call whose start or answer it last followed (``after: module.function``, ``nth`` for its
2nd, 3rd … call), ``at`` seconds after that call started: below the call's ``delay`` before
its answer, equal to it with the answer (it came before the tree took the answer), above it
after the tree took the answer. An event before the first call keeps its time in the run.

A run whose log has no end (the coordinator was killed, the robot lost power), or that was
interrupted (Ctrl-C, SIGTERM), becomes a scenario of what the tree saw until its last recorded tick: it stops there
(``max_duration``, so its status is ``failure``) after the same calls; answers and events
the tree had not ticked on yet are left out, so those calls hang.
"""
from __future__ import annotations

import heapq
import math
import os
from typing import Any, Dict, List, Optional, Tuple

import yaml

from coordinator.runlog import RunLog, RunLogError, empty_file
from coordinator.testing.expected import legacy_times

__all__ = ["scenario_from_log", "seen_until", "write_scenario", "cut_short"]


def cut_short(log: RunLog) -> bool:
    """The run did not end by itself: killed (no end record) or interrupted (Ctrl-C, SIGTERM)."""
    end = log.end
    return end is None or end.get("status") == "INVALID"


def _definitions(log: RunLog) -> Dict[str, Any]:
    """The module definitions the run had in files (none when they cannot be read now)."""
    from modules.definition import DefinitionError
    from modules.search import default_definitions

    given = [m for m in log.tree.get("modules") or [] if isinstance(m, str) and os.path.exists(m)]
    try:
        return default_definitions(given)
    except (DefinitionError, OSError):
        return {}


def _times(defs: Dict[str, Any], target: str, kind: str, values: Any) -> Dict[str, Any]:
    """``values`` (the inputs or outputs of a call of ``target``, or the params of an event) with the
    times older run logs recorded as nanoseconds in text (``"100000000000"``) as ``{secs, nsecs}``."""
    values = dict(values or {})
    mod, _, name = target.partition(".")
    definition = defs.get(mod)
    member = None if definition is None else (
        definition.events.get(name) if kind == "params" else definition.functions.get(name))
    if member is None:
        return values
    types = {q.name: q.rostype for q in getattr(member, kind)}
    return {k: legacy_times(types[k], v) if k in types else v for k, v in values.items()}


def _outcome(end: Dict[str, Any], defs: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    answer = end.get("answer")
    delay = round(float(end.get("duration") or 0.0), 6)
    if answer == "succeeded":
        out: Dict[str, Any] = {"succeed": _times(defs or {}, str(end.get("target")), "outputs", end.get("outputs"))}
    elif answer == "failed":
        out = {"fail": str(end.get("error") or "failed")}
    elif answer == "rejected":
        out = {"reject": str(end.get("error") or "rejected")}
    elif answer is None and end.get("status") == "module_lost":  # its node died: the mock dies as it did
        error, lost = str(end.get("error") or ""), "module %s lost: " % str(end.get("target")).split(".", 1)[0]
        out = {"die": error[len(lost):] if error.startswith(lost) else error or True}
    else:  # no answer (timeout, halted) or the answer to a cancel
        return {"hang": True}
    if delay:
        out["delay"] = delay
    return out


def _events(seen: RunLog, answered: Dict[Any, float], defs: Dict[str, Any]) -> List[Dict[str, Any]]:
    """The events of ``seen``, each tied to the call it last followed (see the module's docstring).

    ``answered``: call_id -> how long after its start the call's scripted answer comes (the calls
    that answer in the scenario; the others hang)."""
    out: List[Dict[str, Any]] = []
    calls: Dict[Any, Dict[str, Any]] = {}  # call_id -> target, nth, start, where its call_end is
    per_target: Dict[str, int] = {}
    ended_at = {r.get("call_id"): i for i, r in enumerate(seen.records) if r.get("type") == "call_end"}
    latest: Optional[Tuple[float, Any]] = None     # (when, call_id): the last call start or answer so far
    answers: List[Tuple[float, int, Any]] = []     # the answers of the calls started, by time
    for i, r in enumerate(seen.records):
        kind, cid = r.get("type"), r.get("call_id")
        if kind == "call_start":
            target = str(r.get("target"))
            per_target[target] = per_target.get(target, 0) + 1
            start = float(r.get("t") or 0.0)
            calls[cid] = {"target": target, "nth": per_target[target], "start": start, "end": ended_at.get(cid)}
            latest = (start, cid)
            if cid in answered:
                heapq.heappush(answers, (start + answered[cid], i, cid))
        elif kind == "call_end" and cid in answered and cid in calls:
            when = calls[cid]["start"] + answered[cid]  # the tree takes it in this tick: it came before
            if latest is None or when >= latest[0]:
                latest = (when, cid)
        elif kind == "event":
            t = float(r.get("t") or 0.0)
            while answers and answers[0][0] <= t:  # answers that came before the event
                when, _, done = heapq.heappop(answers)
                taken = calls[done]["end"]
                if (taken is None or taken > i) and (latest is None or when >= latest[0]):  # else counted at its call_end
                    latest = (when, done)
            ev: Dict[str, Any] = {"event": "%s.%s" % (r.get("module"), r.get("event"))}
            if latest is None:  # before the first call: its time in the run
                ev["at"] = t
            else:
                call = calls[latest[1]]
                ev["after"] = call["target"]
                if call["nth"] > 1:
                    ev["nth"] = call["nth"]
                at = t - call["start"]
                delay = answered.get(latest[1])
                if delay is not None:
                    if call["end"] is None or call["end"] > i:  # the tree had not taken the answer yet
                        at = min(at, delay)
                    else:                                       # it had: after that tick
                        at = max(at, delay + 1e-6)
                ev["at"] = round(max(at, 0.0), 6)
            if r.get("params"):
                ev["params"] = _times(defs, ev["event"], "params", r["params"])
            out.append(ev)
    return out


def _stored(seen: RunLog, defs: Dict[str, Any]) -> Dict[str, Any]:
    """What the Blackboard node held before the run, as far as the run's ``recall``s read it: each
    value recalled that no call of this run produced (an earlier run's result), under the name of
    the output that stored it (``module/function/output`` when the definitions have it, else the
    plain name). The run's own results need nothing: the scenario's mocks produce them again."""
    made = {r.get("call_id") for r in seen.of_type("call_start")}
    out: Dict[str, Any] = {}
    for rec in seen.of_type("recall"):
        for v in rec.get("values") or []:
            if not isinstance(v, dict) or not isinstance(v.get("name"), str) or (
                    v.get("call_id") is not None and v.get("call_id") in made):
                continue
            output = v["name"].split("/")[-1]
            mod, fn = v.get("basic_mod"), v.get("function")
            qualified = "%s/%s/%s" % (mod, fn, output)
            known = mod in defs and fn in defs[mod].functions and any(
                q.name == output for q in defs[mod].functions[fn].outputs)
            name = qualified if known else v["name"]
            if name not in out:
                out[name] = v.get("value")
    return out


def seen_until(log: RunLog) -> Tuple[RunLog, float]:
    """A killed run's log cut after its last tick, and that tick's time (seconds, rounded up
    to the microsecond): what the tree had acted on when the log stopped."""
    last = max((i for i, r in enumerate(log.records) if r.get("type") == "tick"), default=None)
    if last is None:
        raise RunLogError("%s: the run has no end record and no tick (it was killed before its first tick); "
                          "there is nothing to replay" % log.path)
    t = float(log.records[last].get("t") or 0.0)
    return RunLog(log.path, log.records[:last + 1], log.truncated), math.ceil(t * 1e6) / 1e6


def scenario_from_log(log: RunLog, out_path: str) -> Dict[str, Any]:
    """The scenario file's content for ``log``, with the tree path and the definitions the run was given
    (``modules:``) relative to ``out_path``."""
    tree = log.tree
    end = log.end
    seen = log  # what the tree acted on
    stop_at: Optional[float] = None
    stopped = _cleanup_stop(log) or _control_stop(log)
    killed = _killed_in_cleanup(log)
    if stopped is not None:  # the cleanup ran after the stop: root stops then, the cleanup runs as it did
        stop_at = stopped
    elif cut_short(log) and killed is None:
        seen, stop_at = seen_until(log)
    steered = [r for r in log.of_type("control") if r.get("ok") and r.get("command") in ("force", "set")]
    if steered:  # a scenario scripts the modules; what a person forced or wrote is not theirs to redo
        first = steered[0]
        raise RunLogError("%s: the run was steered (%d forced outcome%s or blackboard write%s, the first at %.3fs: %s "
                          "%s); a scenario replays what the modules did, so it could not end the same way" % (
                              log.path, len(steered), "s" if len(steered) > 1 else "", "s" if len(steered) > 1 else "",
                              float(first.get("t") or 0.0), first.get("command"),
                              " ".join(str(v) for v in (first.get("args") or {}).values())))
    path = tree.get("path")
    if not path or not os.path.isfile(path):
        raise RunLogError("%s: the recorded tree %s is not there any more" % (log.path, path))
    defs = _definitions(log)
    ends = {r.get("call_id"): r for r in seen.of_type("call_end")}
    mocks: Dict[str, List[Dict[str, Any]]] = {}
    calls: List[Dict[str, Any]] = []
    answered: Dict[Any, float] = {}  # call_id -> when its answer comes, after its start
    for start in seen.of_type("call_start"):
        target = str(start.get("target"))
        finished = ends.get(start.get("call_id"))
        outcome = _outcome(finished, defs) if finished else {"hang": True}
        mocks.setdefault(target, []).append(outcome)
        if "hang" not in outcome:
            answered[start.get("call_id")] = float(outcome.get("delay", 0.0))
        calls.append({target: _times(defs, target, "inputs", start.get("inputs"))})
    events = _events(seen, answered, defs)
    stored = _stored(seen, defs)
    scenario: Dict[str, Any] = {}
    scenario["name"] = "as recorded in run %s" % tree.get("run")
    if tree.get("inputs"):
        scenario["inputs"] = dict(tree["inputs"])
    if stored:
        scenario["stored"] = stored
    scenario["mocks"] = mocks
    if events:
        scenario["events"] = events
    if stop_at is not None:
        scenario["max_duration"] = stop_at
    elif tree.get("max_duration") is not None:
        scenario["max_duration"] = tree["max_duration"]
    if killed is not None:
        scenario["killed_at"] = killed
    status = "failure" if stop_at is not None else str((end or {}).get("status", "") or _root_status(log)).lower()
    if stopped is not None:  # what the cleanup was told (ended_reason) is the replayed stop's reason
        said = _stop_reason(log)
        calls = _restated(calls, said, replayed_reason(said, stopped))
    scenario["expect"] = {"status": status, "calls": calls}
    cleanup = (end or {}).get("cleanup")
    if isinstance(cleanup, dict) and cleanup.get("status") is not None:
        scenario["expect"]["cleanup"] = "success" if cleanup.get("status") == "SUCCESS" else "failure"
    folder = os.path.dirname(os.path.abspath(out_path))
    data: Dict[str, Any] = {"tree": _relative(path, folder)}
    modules = _module_paths(log, folder)
    if modules:
        data["modules"] = modules
    data["scenarios"] = [scenario]
    return data


def _killed_in_cleanup(log: RunLog) -> Optional[float]:
    """For a run of a tree with ``cleanup:`` killed (no end record) while its cleanup ran: when its log
    ends (its last record, rounded up to the microsecond), the scenario's ``killed_at``; else None."""
    nodes = log.tree.get("nodes") or []
    if log.end is not None or not (nodes and isinstance(nodes[0], dict) and nodes[0].get("kind") == "with_cleanup"):
        return None
    from coordinator.replaystate import Replay

    cleanup = Replay(log).cleanup_ids
    if not any(c[0] in cleanup for r in log.of_type("tick") for c in r.get("changes") or []):
        return None
    return math.ceil(max(float(r.get("t") or 0.0) for r in log.records) * 1e6) / 1e6


def _root_status(log: RunLog) -> str:
    """How root ended in a run killed while its cleanup ran: SUCCESS or FAILURE (or INVALID: stopped)."""
    from coordinator.replaystate import Replay

    main = Replay(log).main
    ends = [c[1] for r in log.of_type("tick") for c in r.get("changes") or [] if c[0] == main
            and c[1] in ("SUCCESS", "FAILURE", "INVALID")]
    return ends[0] if ends else ""


def _stop_reason(log: RunLog) -> str:
    """Why root was stopped, as the run said it (its end's reason; a killed run's, as the cleanup was told)."""
    if log.end is not None:
        return str(log.end.get("reason") or "")
    told = [r.get("value") for r in log.of_type("write") if r.get("key") == "ended_reason"]
    return str(told[0]) if told else ""


def _control_stop(log: RunLog) -> Optional[float]:
    """For a run stopped by ``bmtree control stop`` (root halted, then its cleanup, if any): when root
    was stopped (its stop's tick), the scenario's ``max_duration``; else None."""
    if log.end is None or not any(r.get("ok") and r.get("command") == "stop" for r in log.of_type("control")):
        return None
    from coordinator.replaystate import Replay

    stop = Replay(log).stop_tick()
    return None if stop is None else math.ceil(float(log.records[stop].get("t") or 0.0) * 1e6) / 1e6


def _cleanup_stop(log: RunLog) -> Optional[float]:
    """For an interrupted run (Ctrl-C, SIGTERM) of a tree with ``cleanup:``, or one killed while the cleanup
    that followed a stop ran: when root was stopped (its stop's tick, which the cleanup's ticks follow),
    the scenario's ``max_duration``; else None."""
    end = log.end
    if end is None and _killed_in_cleanup(log) is None:
        return None
    if end is not None and (end.get("status") != "INVALID" or not isinstance(end.get("cleanup"), dict)):
        return None
    from coordinator.replaystate import Replay

    stop = Replay(log).stop_tick()
    return None if stop is None else math.ceil(float(log.records[stop].get("t") or 0.0) * 1e6) / 1e6


def replayed_reason(reason: str, stop_at: float) -> str:
    """The reason a scenario that stops at ``stop_at`` (``max_duration``) gives for the stop the run
    gave as ``reason`` (``interrupted while 'go' was running``, ``stopped by control (/n) while 'go' was
    running`` -> ``stopped after 4.3 s while 'go' was running``)."""
    _, sep, rest = reason.partition(" while ")
    return "stopped after %g s%s%s" % (stop_at, sep, rest)


def _restated(value: Any, said: str, replayed: str) -> Any:
    """``value`` (the expected calls) with the run's reason ``said`` in its texts (what the cleanup wrote
    of ``ended_reason``) as the scenario's run gives it (``replayed``)."""
    if not said:
        return value
    if isinstance(value, str):
        return value.replace(said, replayed)
    if isinstance(value, list):
        return [_restated(v, said, replayed) for v in value]
    if isinstance(value, dict):
        return {k: _restated(v, said, replayed) for k, v in value.items()}
    return value


def _relative(path: str, folder: str) -> str:
    """``path`` relative to ``folder`` (absolute when it cannot be: another drive)."""
    try:
        return os.path.relpath(os.path.abspath(path), folder)
    except ValueError:
        return os.path.abspath(path)


def _module_paths(log: RunLog, folder: str) -> List[str]:
    """The definition files and folders the run was given (``--modules``, ``--module``), for the scenario
    file's ``modules:`` key, relative to its folder: without them the scenario alone cannot mock those
    modules (``no module 'arm' to mock``). Paths that are not there any more are left out."""
    out: List[str] = []
    for m in log.tree.get("modules") or []:
        if isinstance(m, str) and os.path.exists(m):
            rel = _relative(m, folder)
            if rel not in out:
                out.append(rel)
    return out


_HEADER_START = "# Written by 'bmtree replay"


def write_scenario(log: RunLog, out_path: str) -> None:
    """Write the scenario of ``log`` to ``out_path``: a new file, or one this wrote before (a
    tree or anything else of the user's there is refused, RunLogError, never overwritten)."""
    if os.path.lexists(out_path) and not empty_file(out_path):
        try:
            with open(out_path, encoding="utf-8") as fh:
                ours = fh.read(len(_HEADER_START)) == _HEADER_START
        except (OSError, UnicodeDecodeError):
            ours = False
        if not ours:
            raise RunLogError("--scenario %s: the file exists and was not written by 'bmtree replay --scenario'; "
                              "bmtree does not overwrite it (choose a new name)" % out_path)
    data = scenario_from_log(log, out_path)
    end = log.end
    scenario = data["scenarios"][0]
    killed = ("# It was killed at %gs while the cleanup ran (its log ends there): killed_at ends\n"
              "# the scenario then; the calls still running then hang.\n" % scenario["killed_at"]
              if "killed_at" in scenario else "")
    if _control_stop(log) is not None:
        how = ("# The run was stopped by control (%s) at %gs: this stops root then\n"
               "# (max_duration: a stop, so its status is failure%s).\n" % (
                   _stop_reason(log), scenario["max_duration"], ", then the cleanup runs as it did, and\n"
                   "# reads 'stopped after %g s' as ended_reason" % scenario["max_duration"]
                   if log.end.get("cleanup") else ""))
    elif _cleanup_stop(log) is not None:
        how = ("# The run was %s (%s) at %gs, then its cleanup ran: this stops root\n"
               "# then (max_duration: a stop, so its status is failure, and the cleanup reads\n"
               "# 'stopped after %g s' as ended_reason), then the cleanup runs as it did.\n" % (
                   "interrupted" if end is not None else "stopped", _stop_reason(log), scenario["max_duration"],
                   scenario["max_duration"])) + killed
    elif killed:
        how = "# Root ended by itself (%s), then its cleanup ran.\n" % scenario["expect"]["status"] + killed
    elif cut_short(log):
        how = ("# The run %s: this stops at its last recorded tick, %gs, after the\n"
               "# same calls; the calls still running then hang.\n" % (
                   "has no end (it was killed)" if end is None else "was interrupted (%s)" % end.get("reason"),
                   data["scenarios"][0]["max_duration"]))
    else:
        how = "# and the run must end the same way (%s%s) with the same calls.\n" % (
            end.get("status"), ": %s" % end.get("reason") if end.get("reason") else "")
    header = (_HEADER_START + " %s --scenario': the modules answer as they did in that run,\n" % (
        os.path.basename(log.path)) + how)
    text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, allow_unicode=True, width=110)
    with open(out_path, "w", encoding="utf-8") as fh:
        fh.write(header + text)
