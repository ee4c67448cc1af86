"""``bmtree runs`` and ``bmtree replay``: recorded runs listed, shown again, or made a scenario.

A replay rebuilds the recorded tree's shape as plain py_trees behaviours and applies the
recorded status changes to it (:mod:`coordinator.replaystate`), showing them to the live
display itself, so it prints exactly what the live display printed (and, with
``--at``/``--step``/``--failure``, the tree, the tree blackboard and the calls in flight at a
moment; the report after it, ``--at`` and ``--failure`` also list the last module events received).
``--scenario`` writes a ``bmtree test`` file whose mocks answer as the modules
answered (see :mod:`coordinator.scenariogen`).
"""
from __future__ import annotations

import datetime
import os
import sys
import types
from typing import Any, Callable, Dict, List, Optional, Set, TextIO, Tuple

from coordinator.context import LATE_ANSWER, success_false_said
from coordinator.replaystate import Failure, Replay
from coordinator.runevents import (
    CLEANUP_NOTICES,
    TerminalText,
    cleanup_at,
    cleanup_said,
    control_line,
    status_word,
    steered_lines,
    terminal_text,
)
from coordinator.runlines import short_json
from coordinator.runlog import RunLog, RunLogError, default_runs_dir, list_runs, read_log, writer_alive
from coordinator.runner import Display, call_line, cleanup_stop_label, late_line, stop_label

__all__ = ["Failure", "Replay", "find_run", "read_run", "cmd_runs", "cmd_replay"]


def find_run(ref: str, directory: Optional[str] = None) -> str:
    """A run log by path, ``last``, number in ``bmtree runs`` (1 = newest), start of its name, of its run's id
    or of its start time as ``bmtree runs`` shows it."""
    if os.path.isfile(ref):
        return ref
    directory = directory or default_runs_dir()
    problems: List[str] = []
    runs = list_runs(directory, problems)
    if not runs:
        raise RunLogError("no recorded runs in %s%s" % (directory, "".join("; " + p for p in problems[:3])))
    if ref in ("last", "latest"):
        return runs[-1].path
    if ref.isdigit() and len(ref) <= 6:
        k = int(ref)
        if not 1 <= k <= len(runs):
            raise RunLogError("there are %d recorded runs in %s; %s is not one of them" % (len(runs), directory, ref))
        return runs[-k].path
    # the start of its file name (the process's start) or of its run's id (a --record file's name is the
    # user's), or of its start as 'bmtree runs' shows it (the first tick, seconds later with --sim:
    # 20261126-072501 or "2026-11-26 07:25:01")
    hits = [r.path for r in runs if os.path.basename(r.path).startswith(ref) or str(r.extra.get("run") or
                                                                                   "\0").startswith(ref) or any(
        _start_text(r.started, form).startswith(ref) for form in ("%Y%m%d-%H%M%S", "%Y-%m-%d %H:%M:%S"))]
    if len(hits) != 1:
        raise RunLogError("%s runs in %s start with %r (use the number shown by 'bmtree runs')" % (
            "no" if not hits else "%d" % len(hits), directory, ref))
    return hits[0]


def _start_text(started: Any, form: str) -> str:
    try:
        return datetime.datetime.fromtimestamp(float(started)).strftime(form)
    except (TypeError, ValueError, OverflowError, OSError):
        return "?"


def cmd_runs(args: Any) -> int:
    from coordinator.cliutil import err

    directory = args.dir or default_runs_dir()
    problems: List[str] = []
    runs = list_runs(directory, problems)
    for problem in problems:  # each log that is not listed, or is listed without its last record: why
        err("warning: %s" % problem)
    if not runs:
        print("no recorded runs in %s" % directory)
        return 0
    print("recorded runs in %s (newest first):" % directory)
    print("%3s  %-19s  %-24s %9s  %-11s %s" % ("#", "start", "tree", "duration", "result", "reason"))
    for k, r in enumerate(reversed(runs[-args.limit:] if args.limit else runs), 1):
        start = _start_text(r.started, "%Y-%m-%d %H:%M:%S")
        dur = "%.2fs" % r.duration if isinstance(r.duration, (int, float)) else "-"
        print(terminal_text("%3d  %-19s  %-24s %9s  %-11s %s" % (k, start, r.name[:24], dur, status_word(r.status),
                                                                r.reason), newlines=False))
    return 0


def _stop(replay: Replay) -> Tuple[Optional[int], str, Callable[[Dict[str, Any]], Tuple[str, str]]]:
    """A stop from outside: its tick record (None if the run was not stopped so), what it was
    (``interrupted at 2.110s``), and the (status, error) of a call as a summary shows it: the
    calls that stop halted are said so (``interrupted``), not "halted by the tree", and so are those
    the end of a cleanup cut short halted (its time limit, a second Ctrl-C)."""
    log = replay.log
    end = log.end or {}
    stop = replay.stop_tick()
    interrupted = end.get("status") == "INVALID"
    what = ""
    if stop is not None:  # the stop's own time: the last tick before it may be long before
        what = "%s at %.3fs" % ("interrupted" if interrupted else "stopped", replay.stop_time(stop))
    after = max((i for i, r in enumerate(log.records) if r.get("type") == "tick" and i != stop
                 and (stop is None or i < stop)), default=-1)
    stopped_calls = set()
    if stop is not None:
        stopped_calls = {str(r.get("call_id")) for r in log.records[after + 1:stop]
                         if r.get("type") == "call_end" and r.get("status") == "halted"}

    said = end.get("cleanup") if isinstance(end.get("cleanup"), dict) else {}
    cut_calls = replay.cut_calls() if said.get("status") not in (None, "SUCCESS") else set()

    def label(c: Dict[str, Any]) -> Tuple[str, str]:
        if str(c.get("call_id")) in stopped_calls:
            return stop_label(interrupted, str(end.get("reason") or ""))
        if str(c.get("call_id")) in cut_calls:  # the cleanup's time limit, or a second Ctrl-C
            return cleanup_stop_label(str(said.get("reason") or ""))
        return str(c.get("status")), success_false_said(c.get("error"), c.get("outputs"))

    return stop, what, label


def _report(replay: Replay, out: TextIO) -> None:
    log = replay.log
    end = log.end
    name = log.tree.get("name", "?")
    out.write("\n")
    if end is None and writer_alive(log.tree):
        out.write("%s: RUNNING: still running (pid %s); its log so far goes to %.3fs: `bmtree watch` shows it live\n"
                  % (name, log.tree.get("pid"), replay.t))
    elif end is None:
        out.write("%s: UNFINISHED: last seen alive at %.2fs (its log's last record is at %.3fs%s), and the log has "
                  "no end: the process was killed?\n" % (
                      name, log.last_alive, replay.t, "; that record was cut" if log.truncated else ""))
    else:
        out.write("%s: %s in %.2f s (%s ticks)\n" % (name, status_word(end.get("status")), float(end.get("duration") or 0.0),
                                                     end.get("ticks")))
        if end.get("reason") and end.get("status") != "SUCCESS":
            out.write("reason: %s\n" % end.get("reason"))
            if end.get("at"):
                out.write("at: %s\n" % end["at"])
        out.write("".join(line + "\n" for line in steered_lines(end.get("steered"))))
    ended, _others = replay.failures()
    failing = replay.failing_call(ended)[0] if ended is not None else None
    _stop_tick, _what, label = _stop(replay)
    late = {str(n.get("call_id")): n for n in replay.notices if n.get("what") == LATE_ANSWER and n.get("call_id")}
    listed: Set[str] = set()  # the calls whose late answer is listed under them
    out.write("calls:\n")
    cleanup = [c for c in replay.finished if c.get("node") in replay.cleanup_ids]
    for c in [c for c in replay.finished if c.get("node") not in replay.cleanup_ids] + [None] + cleanup:
        if c is None:
            said = cleanup_said((end or {}).get("cleanup"))
            out.write("".join(line + "\n" for line in [said] + cleanup_at((end or {}).get("cleanup")) if said))
            continue
        status, error = label(c)
        out.write(call_line(float(c.get("started") or 0.0), c.get("target"), status, float(c.get("duration") or 0.0),
                            error, failing.get("inputs") if failing is not None
                            and failing.get("call_id") == c.get("call_id") else None) + "\n")
        answer = late.get(str(c.get("call_id")))  # the answer that came after the call had ended
        if answer is not None:
            listed.add(str(c.get("call_id")))
            out.write(late_line(str(answer.get("text"))) + "\n")
    for c in replay.pending.values():
        out.write("  +%7.3fs  %-26s %-11s %8s\n" % (float(c.get("t") or 0.0), c.get("target"), "no end", "-"))
    _events(replay.events, out, "events:", REPORT_EVENTS)
    graph = [n for n in replay.notices  # late answers are listed under their calls
             if n.get("what") != LATE_ANSWER or str(n.get("call_id")) not in listed]
    for head, notices in (("the ROS graph:", [n for n in graph if n.get("what") not in CLEANUP_NOTICES]),
                          ("the cleanup:", [n for n in graph if n.get("what") in CLEANUP_NOTICES])):
        if notices:
            out.write(head + "\n")
            for n in notices:
                out.write("  +%7.3fs  %s\n" % (float(n.get("t") or 0.0), n.get("text")))
    if replay.control:
        out.write("control:\n")
        for c in replay.control:
            out.write("  +%7.3fs  %s\n" % (float(c.get("t") or 0.0), control_line(c)))


REPORT_EVENTS = 20  # the events the report after a replay lists: the last ones
MOMENT_EVENTS = 10  # those --at and --failure list, received by the moment they show


def _event_line(rec: Dict[str, Any]) -> str:
    """A module event the run received, in the columns of a call's line: when, ``module.event``, its
    params as compact JSON cut as a call's inputs are (none shown when the record has none)."""
    name = "%s.%s" % (rec.get("module") or "?", rec.get("event") or "?")
    params = short_json(rec["params"]) if rec.get("params") is not None else ""
    return terminal_text(("  +%7.3fs  %-26s %s" % (float(rec.get("t") or 0.0), name, params)).rstrip(),
                         newlines=False)


def _events(events: List[Dict[str, Any]], out: TextIO, head: str, limit: int) -> None:
    """The module events ``events`` (received so far), the last ``limit`` of them, under ``head``; nothing
    without any."""
    if not events:
        return
    out.write(head + "\n")
    left_out = len(events) - limit
    if left_out > 0:
        out.write("  … %d earlier event%s left out\n" % (left_out, "" if left_out == 1 else "s"))
    for rec in events[-limit:]:
        out.write(_event_line(rec) + "\n")


def _jump_to_failure(replay: Replay, out: TextIO) -> None:
    """``--failure``: the failure the run's reason names (not one the tree recovered from or went on
    past), where, why, the call that failed with its inputs, the state after that tick and the last events
    received before it; for a run stopped from outside or killed, when that was, the state at its last
    tick before it and the last events received before it."""
    log = replay.log
    ended, others = replay.failures()
    end = log.end or {}

    def where(f: Failure) -> str:
        n = replay.nodes.get(f.node, {})
        inside = " in %s" % f.within if f.within else ""
        return "'%s' (%s:%s)%s: %s" % (n.get("name"), n.get("file", "?"), n.get("line", "?"), inside, f.message)

    def got_past(f: Failure) -> str:
        n = replay.nodes.get(f.by, {}) if f.by is not None else {}
        if not n:
            return ""
        return " (%s: '%s' [%s] %s)" % ("recovered" if f.recovered else "moved past", n.get("name"),
                                        n.get("kind", n.get("shape")),
                                        "succeeded after it" if f.recovered else "went on")

    stop, stopped, label = _stop(replay)
    shown = ended
    events: Optional[List[Dict[str, Any]]] = None   # the events shown: by default, those before the failure's tick
    before = "the failure"
    if ended is not None:
        replay.to_tick(ended.index)
        out.write("the failure that ended the run, at %.3fs: %s\n" % (ended.t, where(ended)))
    elif stop is not None or end.get("status") in ("FAILURE", "INVALID") or not end:
        ticks = [i for i, r in enumerate(log.records) if r.get("type") == "tick" and i != stop
                 and (stop is None or i < stop)]
        last = ticks[-1] if ticks else 0
        replay.until(lambda rec: replay.index > last)
        if not end:
            why = ("its log has no end record: the process was killed (or lost power) at about %.2fs, when it "
                   "was last seen alive (its log was last written or touched then)" % log.last_alive)
            when = "its last tick"
        else:
            why = "%s%s" % (end.get("reason") or "the run ended %s" % end.get("status"),
                            " (at %.3fs)" % replay.stop_time(stop) if stopped else "")
            when = "its last tick before %s" % ("it was stopped" if stopped else "its end")
        # those until the stop (or the end of its log), not only until its last tick: a wait_event skips
        # the events it does not want without a tick
        events = [r for r in log.records[:stop] if r.get("type") == "event"]
        before = "it was stopped" if stopped else "its end" if end else "its log ends"
        out.write("no leaf's failure ended this run: %s\nthe state at %s, at %.3fs:\n" % (why, when, replay.t))
    elif others:
        shown = others[0]
        replay.to_tick(shown.index)
        out.write("the run succeeded; the tree recovered from %d failure%s, the first at %.3fs: %s\n" % (
            len(others), "" if len(others) == 1 else "s", shown.t, where(shown)))
    else:
        said = end.get("cleanup") if isinstance(end.get("cleanup"), dict) else {}
        if said.get("status") not in (None, "SUCCESS"):   # root's result first: the cleanup's is beside it
            out.write("the run %s: no leaf of root failed\n" % ("succeeded" if end.get("status") == "SUCCESS"
                                                                 else "ended %s" % end.get("status")))
        else:
            out.write("no leaf failed in this run\n")
        out.write("".join(line + "\n" for line in steered_lines(end.get("steered"))))
        _cleanup_failure(replay, out, label)
        return
    if end.get("reason") and end.get("status") != "SUCCESS" and ended is not None:
        out.write("the run ended %s: %s\n" % (end.get("status"), end.get("reason")))
    if shown is not None:
        start, stop_rec = replay.failing_call(shown)
        if start is not None:
            status, error = label(stop_rec) if stop_rec is not None else ("no end", "")
            out.write("the failing call:\n%s\n" % call_line(
                float(start.get("t") or 0.0), start.get("target"), status,
                float(stop_rec.get("duration") or 0.0) if stop_rec is not None else None, error, start.get("inputs")))
    # what an operator changed (a pause: the timeouts kept counting; a forced outcome, a write)
    out.write("".join(line + "\n" for line in steered_lines(end.get("steered"))))
    if ended is not None and others:
        out.write("before it, the tree recovered from or went on past %d failure%s:\n" % (len(others), "" if len(others) == 1 else "s"))
        for f in others[:5]:
            out.write("  +%7.3fs  %s%s\n" % (f.t, where(f), got_past(f)))
        if len(others) > 5:
            out.write("  … and %d more\n" % (len(others) - 5))
    _cleanup_failure(replay, out, label)
    replay.snapshot(out, stopped if ended is None and stopped else "")
    _events(replay.events if events is None else events, out, "events received before %s:" % before, MOMENT_EVENTS)


def _cleanup_failure(replay: Replay, out: TextIO, label: Callable[[Dict[str, Any]], Tuple[str, str]]) -> None:
    """For ``--failure``: that the tree's cleanup failed or was cut short, why, and its last call that did
    not succeed (not the failure that ended the run: the run's result stays root's); nothing otherwise."""
    end = replay.log.end or {}
    said = end.get("cleanup") if isinstance(end.get("cleanup"), dict) else {}
    if said.get("status") in (None, "SUCCESS"):
        return
    out.write("the cleanup (root %s) %s: %s; the run's result stays root's\n" % (
        said.get("ended"), "failed" if said.get("status") == "FAILURE" else "was cut short",
        said.get("reason") or "no reason given"))
    starts = {str(r.get("call_id")): r for r in replay.log.of_type("call_start")}
    bad = [r for r in replay.log.of_type("call_end") if r.get("node") in replay.cleanup_ids
           and r.get("status") != "succeeded"]
    if bad:
        start = starts.get(str(bad[-1].get("call_id")), {})
        status, error = label(bad[-1])
        out.write("its call that did not succeed:\n%s\n" % call_line(
            float(start.get("t") or 0.0), bad[-1].get("target"), status, float(bad[-1].get("duration") or 0.0),
            error, start.get("inputs")))


def _test_command(log: RunLog, scenario: str) -> str:
    """``bmtree test`` of ``scenario`` (whose ``modules:`` names the definition files the run used that are
    not the simulated robot's: :mod:`coordinator.scenariomods`), and a word on the modules it knew only from
    the live graph (their definitions are in no file it had)."""
    import shlex

    from coordinator.scenariomods import definition_paths
    from modules.definition import DefinitionError
    from modules.search import default_definitions

    command = "bmtree test %s" % shlex.quote(scenario)
    try:
        known = set(default_definitions(definition_paths(log)[0]))
    except (DefinitionError, OSError) as exc:  # changed since the run: the test will say what is wrong
        return "%s (its definitions: %s)" % (command, str(exc).splitlines()[0])
    used = {str(n["target"]).split(".", 1)[0] for n in log.tree.get("nodes") or []
            if isinstance(n, dict) and isinstance(n.get("target"), str)}
    missing = sorted(used - known)
    recorded = log.tree.get("definitions") if isinstance(log.tree.get("definitions"), dict) else {}
    gone = [m for m in missing if isinstance(recorded.get(m), str)]   # the run's file is not here any more
    live = [m for m in missing if m not in gone]
    said = ["adding --modules with the definition of %s (the run had it from the live graph)" % ", ".join(live)] \
        if live else []
    said += ["adding --modules with the definition of %s (the run's, %s, is not here)" % (m, recorded[m]) for m in gone]
    return ", ".join([command] + said)


def read_run(ref: str, directory: Optional[str]) -> RunLog:
    """The log ``ref`` names (:func:`find_run`), read, with a warning on stderr for each line skipped."""
    from coordinator.cliutil import err

    log = read_log(find_run(ref, directory))
    for line in log.warning_lines():
        err(line)
    return log


def cmd_replay(args: Any) -> int:
    out: Any = TerminalText(sys.stdout)  # a module's error text, a log's names: never the terminal's controls
    log = read_run(args.run, args.dir)
    path = log.path
    if args.scenario:
        from coordinator.scenariogen import write_scenario

        write_scenario(log, args.scenario)
        out.write("wrote %s (run it with: %s)\n" % (args.scenario, _test_command(log, args.scenario)))
        return 0
    replay = Replay(log)
    started = datetime.datetime.fromtimestamp(float(log.tree.get("started") or 0.0))
    out.write("replay of %s: %s, started %s\n" % (path, log.tree.get("name"), started.strftime("%Y-%m-%d %H:%M:%S")))
    if args.failure:
        _jump_to_failure(replay, out)
        return 0
    if args.at is not None:
        at = args.at
        while replay.index < len(log.records) and float(log.records[replay.index].get("t") or 0.0) <= at:
            replay.next()
        lived = log.last_alive
        out.write("at %.3fs%s:\n" % (at, " (past the run's end at %.3fs: its last state)" % lived if at > lived else ""))
        replay.snapshot(out)
        _events(replay.events, out, "events received by %.3fs:" % at, MOMENT_EVENTS)
        return 0
    if args.step:
        interactive = sys.stdin.isatty()
        while True:
            rec = replay.next()
            if rec is None:
                break
            if rec.get("type") != "tick":
                continue
            out.write("\n--- tick %s at %.3fs ---\n" % (rec.get("n"), replay.t))
            replay.snapshot(out)
            if interactive:
                out.write("[Enter: next tick, q: quit] ")
                out.flush()
                if sys.stdin.readline().strip().lower().startswith("q"):
                    return 0
        _report(replay, out)
        return 0
    if args.speed:
        _play(replay, sys.stdout, args.speed)  # (its display escapes its own text: it moves the cursor)
    else:
        display = Display(out, tty=False)
        while replay.next(display) is not None:
            pass
    _report(replay, out)
    return 0


def _play(replay: Replay, out: TextIO, speed: float) -> None:
    """At ``speed`` times the recorded pace; on a terminal redrawn in place, as the live display does."""
    import time

    display = Display(out)
    shown = 0.0
    while True:
        index = replay.index
        if index >= len(replay.log.records):
            break
        rec = replay.log.records[index]
        if rec.get("type") == "tick":
            time.sleep(max(0.0, (float(rec.get("t") or 0.0) - shown) / speed))
            shown = float(rec.get("t") or 0.0)
        replay.next(display)
    display.on_end(types.SimpleNamespace(duration=replay.t))
