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
(``max_duration``, so its status is ``failure``; ``killed_at`` for a killed run of a tree with ``cleanup:``,
whose cleanup the run never reached) after the same calls; answers and events the tree had not ticked on
yet are left out, so those calls hang.

An answer the tree took after its call's ``timeout`` (before the timeout's tick) comes just before that
timeout. The expected ``reason`` is the run's (around a call id or a measured time). A run a scenario cannot
reproduce (steered; the Blackboard node, or a ``wait_event``'s module node, lost) is a RunLogError.
"""
from __future__ import annotations

import heapq
import math
import os
import re
import textwrap
from typing import Any, Dict, List, Optional, Tuple

import yaml

from coordinator.runlog import RunLog, RunLogError, empty_file
from coordinator.scenariomods import definition_paths, definitions_of
from coordinator.scenariomods import relative as _relative
from coordinator.testing.expected import legacy_times
from coordinator.testing.limits import DEFAULT_MAX_DURATION

__all__ = ["scenario_from_log", "seen_until", "write_scenario", "cut_short", "expected_reason"]

_BEFORE_TIMEOUT = 1e-6  # how long before its call's timeout an answer that beat it in the run comes


def cut_short(log: RunLog) -> bool:
    """The run did not end by itself: killed (no end record) or interrupted (Ctrl-C, SIGTERM)."""
    end = log.end
    return end is None or end.get("status") == "INVALID"


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


def _outcome(end: Dict[str, Any], defs: Optional[Dict[str, Any]] = None, timeout: Any = None) -> Dict[str, Any]:
    """The mock's outcome for a call that ended as ``end`` says; ``timeout``: the call's (its ``call_start``'s),
    which an answer the tree took must beat (:func:`_before_timeout`)."""
    answer = end.get("answer")
    delay = _before_timeout(round(float(end.get("duration") or 0.0), 6), timeout)
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


def _before_timeout(delay: float, timeout: Any) -> float:
    """``delay``, or just under ``timeout`` when it is not: the run's tree took an answer (or a module's loss:
    after the coordinator's 10 s wait for its restart, under ``timeout: 10``) before the timeout's tick, which a
    simulated clock never delays: there the call would end ``no answer within 10s``."""
    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not math.isfinite(timeout) \
            or timeout <= 2 * _BEFORE_TIMEOUT or delay < timeout - _BEFORE_TIMEOUT:
        return delay
    return math.floor((timeout - _BEFORE_TIMEOUT) * 1e6 + 1e-6) / 1e6   # microseconds, as the delays are written


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


def scenario_from_log(log: RunLog, out_path: str, moved: Optional[List[str]] = None,
                      notes: Optional[List[str]] = None) -> Dict[str, Any]:
    """The scenario file's content for ``log``, with the tree path and the definitions the run used that are
    not the simulated robot's (``modules:``, :mod:`coordinator.scenariomods`) relative to ``out_path``;
    RunLogError for a run a scenario could not reproduce. ``moved`` gets the answers moved before their call's
    timeout (:func:`_before_timeout`: ``target #n (after Ss)``), ``notes`` what the header says of ``modules:``."""
    tree = log.tree
    end = log.end
    seen = log  # what the tree acted on
    stop_at: Optional[float] = None
    stopped = _cleanup_stop(log) or _control_stop(log)
    killed = _killed_in_cleanup(log)
    in_root = False   # killed while root ran, in a tree with cleanup: killed_at
    if stopped is not None:  # the cleanup ran after the stop: root stops then, the cleanup runs as it did
        stop_at = stopped
    elif cut_short(log) and killed is None:
        seen, stop_at = seen_until(log)
        in_root = _killed_in_root(log)
        if in_root:  # killed, not stopped: its cleanup never ran, nor does the scenario's (max_duration would run it)
            killed, stop_at = stop_at, None
    steered = [r for r in log.of_type("control") if r.get("ok") and r.get("command") in ("force", "set")]
    if steered:  # a scenario scripts the modules; what a person forced or wrote is not theirs to redo
        first = steered[0]
        raise RunLogError("%s: the run was steered (%d forced outcome%s or blackboard write%s, the first at %.3fs: %s "
                          "%s); a scenario replays what the modules did, so it could not end the same way" % (
                              log.path, len(steered), "s" if len(steered) > 1 else "", "s" if len(steered) > 1 else "",
                              float(first.get("t") or 0.0), first.get("command"),
                              " ".join(str(v) for v in (first.get("args") or {}).values())))
    _refuse_unreproducible(seen)
    path = tree.get("path")
    if not path or not os.path.isfile(path):
        raise RunLogError("%s: the recorded tree %s is not there any more" % (log.path, path))
    module_paths, said = definition_paths(log)
    notes = [] if notes is None else notes
    notes.extend(said)
    defs = definitions_of(log, module_paths)
    ends = {r.get("call_id"): r for r in seen.of_type("call_end")}
    mocks: Dict[str, List[Dict[str, Any]]] = {}
    calls: List[Dict[str, Any]] = []
    answered: Dict[Any, float] = {}  # call_id -> when its answer comes, after its start
    moved = [] if moved is None else moved
    for start in seen.of_type("call_start"):
        target = str(start.get("target"))
        finished = ends.get(start.get("call_id"))
        outcome = _outcome(finished, defs, start.get("timeout")) if finished else {"hang": True}
        mocks.setdefault(target, []).append(outcome)
        if "hang" not in outcome:
            answered[start.get("call_id")] = float(outcome.get("delay", 0.0))
            took = round(float((finished or {}).get("duration") or 0.0), 6)
            if took > outcome.get("delay", 0.0):
                moved.append("%s #%d (after %gs)" % (target, len(mocks[target]), took))
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
        if "max_duration" not in scenario and killed >= DEFAULT_MAX_DURATION:   # else that default stops it first
            scenario["max_duration"] = math.ceil(killed) + 1
    status = "failure" if stop_at is not None or in_root else str(  # stopped, or killed while root ran
        (end or {}).get("status", "") or _root_status(log)).lower()
    if stopped is not None:  # what the cleanup was told (ended_reason) is the replayed stop's reason
        said = _stop_reason(log)
        calls = _restated(calls, said, replayed_reason(said, stopped))
    reason = expected_reason(_run_reason(log, status, stop_at, killed))
    scenario["expect"] = dict({"status": status}, **({"reason": reason} if reason else {}), calls=calls)
    cleanup = (end or {}).get("cleanup")
    if isinstance(cleanup, dict) and cleanup.get("status") is not None:
        scenario["expect"]["cleanup"] = "success" if cleanup.get("status") == "SUCCESS" else "failure"
    folder = os.path.dirname(os.path.abspath(out_path))
    data: Dict[str, Any] = {"tree": _relative(path, folder)}
    if module_paths:
        data["modules"] = list(dict.fromkeys(_relative(m, folder) for m in module_paths))
    data["scenarios"] = [scenario]
    return data


def _run_reason(log: RunLog, status: str, stop_at: Optional[float], killed: Optional[float]) -> str:
    """Why the run failed, as the scenario's run says it: the end's reason; a stop's restated as the
    scenario's stop (:func:`replayed_reason`); for a run killed in its cleanup, what the cleanup was told.
    '' when it succeeded, or was killed while root ran (its log has no reason)."""
    end, said = log.end, _stop_reason(log)
    if status != "failure" or (end is None and (killed is None or not said)):   # killed in root: no reason said
        return ""
    if end is not None and end.get("status") != "INVALID" and stop_at is None:
        return said
    return replayed_reason(said, stop_at) if stop_at is not None else said


def expected_reason(reason: str) -> Any:
    """``reason`` as a scenario's ``expect: reason``: the text; or, when it holds what differs from run to
    run (a call id, a measured time: ``succeeded in 0.004s``), the pieces around them, which the
    scenario's reason must contain in this order. '' for no reason."""
    pieces = [p for p in _VOLATILE.split(reason) if p.strip()]
    if len(pieces) == 1 and pieces[0] == reason:
        return reason
    return pieces or ""


_VOLATILE = re.compile(r"\b[0-9a-f]{16}\b|\b\d+\.\d{3}s\b")  # a call's (request's) id; a time as "%.3fs" says it

# The failures of a node a scenario cannot reproduce: its kind, its reason's pattern, and what the error says
_UNREPRODUCIBLE = {
    "recall": (re.compile(r"^Blackboard node lost: |^no answer from the Blackboard node within |"
                          r"the Blackboard node did not store the result of "), "of the Blackboard node",
               "a scenario's Blackboard never goes down nor loses a result", "in which the Blackboard node stayed up"),
    "wait_event": (re.compile(r"'s node (is gone|was restarted) \(.*(event can come|lost meanwhile)"),
                   "%s's node was lost while it waited", "a scenario's module dies only during a call to it (die), "
                   "unseen by a wait_event", "in which that node stayed up")}


def _refuse_unreproducible(seen: RunLog) -> None:
    """RunLogError (one line) when a node failed for what a scenario cannot reproduce (:data:`_UNREPRODUCIBLE`)."""
    nodes = {n.get("id"): n for n in seen.tree.get("nodes") or [] if isinstance(n, dict)}
    found = [(r, nodes[c[0]], c[2]) for r in seen.of_type("tick") for c in r.get("changes") or []
             if isinstance(c, list) and len(c) > 2 and c[1] == "FAILURE" and isinstance(c[2], str)
             and isinstance(c[0], int) and c[0] in nodes and nodes[c[0]].get("kind") in _UNREPRODUCIBLE
             and _UNREPRODUCIBLE[nodes[c[0]]["kind"]][0].search(c[2])]
    if not found:
        return
    r, node, why = found[0]
    _, what, cannot, instead = _UNREPRODUCIBLE[node["kind"]]
    if "%s's" in what:
        what = what % str(node.get("target") or "its module").split(".")[0]
    raise RunLogError("%s: the %s '%s' failed at %.3fs because %s (%s)%s; %s, so a scenario could not end the same "
                      "way: make it from a run %s" % (
                          seen.path, node["kind"], node.get("name"), float(r.get("t") or 0.0), what, _line(why),
                          " (and %d more such failure%s)" % (len(found) - 1, "s" if len(found) > 2 else "")
                          if len(found) > 1 else "", cannot, instead))


def _with_cleanup(log: RunLog) -> bool:
    nodes = log.tree.get("nodes") or []
    return bool(nodes) and isinstance(nodes[0], dict) and nodes[0].get("kind") == "with_cleanup"


def _killed_in_root(log: RunLog) -> bool:
    """A run of a tree with ``cleanup:`` killed (no end record) while root ran: its cleanup never began."""
    return log.end is None and _with_cleanup(log) and _killed_in_cleanup(log) is None


def _killed_in_cleanup(log: RunLog) -> Optional[float]:
    """For a run of a tree with ``cleanup:`` killed (no end record) while its cleanup ran: when its log
    ends (its last record, rounded up to the microsecond), the scenario's ``killed_at``; else None."""
    if log.end is not None or not _with_cleanup(log):
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


_HEADER_START = "# Written by 'bmtree replay"


def _line(text: Any) -> str:
    """``text`` on one line, for the header's comments."""
    return " ".join(str(text or "").split())


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
    moved: List[str] = []
    notes: List[str] = []
    data = scenario_from_log(log, out_path, moved, notes)
    end = log.end
    scenario = data["scenarios"][0]
    killed = ("# It was killed at %gs while the cleanup ran (its log ends there): killed_at ends\n"
              "# the scenario then; the calls still running then hang.\n" % scenario["killed_at"]
              if "killed_at" in scenario else "")
    if _control_stop(log) is not None:
        how = ("# The run was stopped by control (%s) at %gs: this stops root then\n"
               "# (max_duration: a stop, so its status is failure%s).\n" % (
                   _line(_stop_reason(log)), scenario["max_duration"], ", then the cleanup runs as it did, and\n"
                   "# reads 'stopped after %g s' as ended_reason" % scenario["max_duration"]
                   if log.end.get("cleanup") else ""))
    elif _cleanup_stop(log) is not None:
        how = ("# The run was %s (%s) at %gs, then its cleanup ran: this stops root\n"
               "# then (max_duration: a stop, so its status is failure, and the cleanup reads\n"
               "# 'stopped after %g s' as ended_reason), then the cleanup runs as it did.\n" % (
                   "interrupted" if end is not None else "stopped", _line(_stop_reason(log)), scenario["max_duration"],
                   scenario["max_duration"])) + killed
    elif _killed_in_root(log):
        how = ("# The run has no end (it was killed while root ran, before its cleanup): this ends at its\n"
               "# last recorded tick, %gs (killed_at: root is halted there, and the cleanup does not run),\n"
               "# after the same calls; the calls still running then hang.\n" % scenario["killed_at"])
    elif killed:
        how = "# Root ended by itself (%s), then its cleanup ran.\n" % scenario["expect"]["status"] + killed
    elif cut_short(log):
        how = ("# The run %s: this stops at its last recorded tick, %gs, after the\n"
               "# same calls; the calls still running then hang.\n" % (
                   "has no end (it was killed)" if end is None else "was interrupted (%s)" % _line(end.get("reason")),
                   data["scenarios"][0]["max_duration"]))
    else:
        how = "# and the run must end the same way (%s%s) with the same calls.\n" % (
            end.get("status"), ": %s" % _line(end.get("reason")) if end.get("reason") else "")
    if moved:
        how += ("# The run's tree took these answers after their call's timeout, before the timeout's tick (which\n"
                "# a simulated clock does not delay): here they come just before it: %s.\n" % _line(", ".join(moved)))
    how += "".join("# %s\n" % part for n in notes for part in textwrap.wrap(
        _line(n) + ".", 100, break_on_hyphens=False, break_long_words=False))
    header = (_HEADER_START + " %s --scenario': the modules answer as they did in that run,\n" % (
        os.path.basename(log.path)) + how)
    text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, allow_unicode=True, width=110)
    with open(out_path, "w", encoding="utf-8") as fh:
        fh.write(header + text)
