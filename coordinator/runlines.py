"""A run's lines for people: its calls, its stop and its summary, as ``bmtree run`` prints them at the
end and ``replay``/``watch`` label them."""
from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any, Dict, List, Optional, Set, Tuple

from py_trees.common import Status

from coordinator.context import CallRecord, late_answer_text, success_false_said
from coordinator.runevents import cleanup_at, status_word, steered_lines, terminal_text

if TYPE_CHECKING:
    from coordinator.runner import RunResult

__all__ = ["call_line", "cleanup_lines", "cleanup_stop_label", "late_line", "short_json", "shown_status", "stop_label",
           "summary_lines"]


def short_json(value: Any, width: int = 60) -> str:
    """``value`` as compact JSON, cut to ``width`` characters: inputs on a summary line stay one line."""
    text = json.dumps(value, ensure_ascii=False, separators=(",", ":"), default=str)
    return text if len(text) <= width else text[:width - 1] + "…"


def call_line(started: float, target: Any, status: Any, duration: Optional[float], error: Any,
              inputs: Any = None) -> str:
    """One call of an end-of-run summary (the live one and ``bmtree replay``'s print the same lines);
    ``inputs`` are given for the failing call: what it was asked is half of why it failed."""
    dur = "%.3fs" % duration if duration is not None else "-"
    line = "  +%7.3fs  %-26s %-11s %8s  %s" % (started, target, status, dur, error or "")
    if inputs is not None:
        line += "%sinputs %s" % ("  " if error else "", short_json(inputs))
    return terminal_text(line.rstrip(), newlines=False)   # a module's error of several lines: still one row


def late_line(text: str) -> str:
    """Under its call in an end-of-run summary (live and ``bmtree replay``): the answer that came after
    the call had ended (``text``: its notice, which says when). Not a call's line: no ``+`` time."""
    return terminal_text(" " * 14 + "late answer: " + text, newlines=False)


def stop_label(interrupted: bool, reason: str) -> Tuple[str, str]:
    """(status, error) shown for a call halted because the run was stopped from outside, instead of
    the call's own "halted by the tree": ``interrupted`` for Ctrl-C, the limit for ``max_duration``."""
    if interrupted:
        return "interrupted", ""
    return "halted", reason.split(" while ", 1)[0] or "the run was stopped"


def cleanup_stop_label(reason: str) -> Tuple[str, str]:
    """(status, error) shown for a call of a tree's cleanup halted when the cleanup was cut short,
    instead of the call's own "halted by the tree": ``interrupted`` for a Ctrl-C, else its time limit
    (``halted  did not end within 30 s (cleanup_timeout)``)."""
    if reason.startswith("interrupted"):
        return "interrupted", ""
    return "halted", reason.split(" while ", 1)[0] or "the cleanup was cut short"


def shown_status(result: RunResult, c: CallRecord, cleanup: Optional[Set[int]] = None,
                 cut: Optional[Set[int]] = None) -> Tuple[str, str]:
    """(status, error) of call ``c`` as an end-of-run summary shows it (and the kit's ``run.label``): a
    call the stop from outside halted says so (:func:`stop_label`), and so does one halted when the
    cleanup was cut short (:func:`cleanup_stop_label`: the calls :meth:`WithCleanup.end_cleanup` halted,
    as ``bmtree replay`` finds them: halted after the tick before the one that halted the cleanup).
    ``cleanup``, ``cut``: the ids of the cleanup's calls and of the cut ones, when known already."""
    status, error = str(c.status), c.error
    if status != "halted" or c.ended is None:
        return status, error
    if id(c) in (cut if cut is not None else {id(k) for k in result.cleanup_cut_calls}):
        return cleanup_stop_label(result.cleanup_reason)
    cleanup = cleanup if cleanup is not None else {id(k) for k in result.cleanup_calls}
    if result.stopped_at is not None and c.ended >= result.stopped_at and id(c) not in cleanup:
        return stop_label(result.status == Status.INVALID, result.reason)
    return status, error


FOLD_OVER = 60   # calls of root a summary lists one by one; beyond, the middle ones are counted
FOLD_FIRST, FOLD_LAST = 10, 30


def summary_lines(result: RunResult, tree_name: str, every_call: str = "") -> List[str]:
    """The end-of-run summary: result (``INTERRUPTED`` for a run stopped by Ctrl-C), reason, the calls
    (the failing one with its inputs; those the stop from outside, or the end of a cut cleanup, halted
    said so). Of a root that made more than :data:`FOLD_OVER` calls, the first and last ones, the failing
    one and those that may still be running or answered late are listed, and the others counted by status
    in one line each run of them, so that a long run's summary stays short and its reason on the screen
    (``every_call``: where they all are, said on those lines)."""
    lines = ["", "%s: %s in %.2f s (%d ticks)" % (tree_name, status_word(result.status), result.duration,
                                                   result.ticks)]
    if result.reason and not result.succeeded:
        lines.append("reason: %s" % result.reason)
        if result.failed_at:
            lines.append("at: %s" % result.failed_at)
    lines.extend(steered_lines(result.steered))
    lines.append("calls:")
    cleanup = {id(c) for c in result.cleanup_calls}
    cut = {id(c) for c in result.cleanup_cut_calls}
    root = [c for c in result.calls if id(c) not in cleanup]
    folded: Dict[str, int] = {}
    for i, c in enumerate(root + [None] + list(result.cleanup_calls)):
        if c is None:
            lines.extend(_folded(folded, every_call))
            lines.extend(cleanup_lines(result))
            continue
        status, error = shown_status(result, c, cleanup, cut)
        if (len(root) > FOLD_OVER and FOLD_FIRST <= i < len(root) - FOLD_LAST and c is not result.failed_call
                and c.late_at is None and not c.maybe_running):
            folded[status] = folded.get(status, 0) + 1
            continue
        lines.extend(_folded(folded, every_call))
        folded = {}
        error = success_false_said(error, c.outputs)
        lines.append(call_line(c.started - result.started, c.target, status, c.duration, error,
                               c.inputs if c is result.failed_call else None))
        if c.late_at is not None:
            lines.append(late_line(late_answer_text(c, result.started)))
        elif c.maybe_running:
            lines.append(terminal_text(" " * 14 + "may still be running: %s" % c.maybe_running, newlines=False))
    return [terminal_text(line) for line in lines]   # a module's error, a tree's names: never the terminal's


def _folded(by_status: Dict[str, int], every_call: str) -> List[str]:
    """The line in place of calls not listed in a long run's summary: how many, by status."""
    n = sum(by_status.values())
    if not n:
        return []
    return ["  … %d call%s not listed (%s)%s" % (n, "" if n == 1 else "s", ", ".join(
        "%d %s" % (k, status) for status, k in sorted(by_status.items(), key=lambda sk: -sk[1])),
        ": %s" % every_call if every_call else "")]


def cleanup_lines(result: RunResult) -> List[str]:
    """The cleanup's line of an end-of-run summary (its calls follow it): how it ended, after which ending
    of root; nothing for a tree without ``cleanup:``."""
    if result.cleanup_status is None and not result.ended:
        return []
    if result.cleanup_status is None:
        return ["cleanup (root %s): did not run" % result.ended]
    said = {"SUCCESS": "succeeded", "FAILURE": "FAILED", "INVALID": "cut short"}[result.cleanup_status.value]
    took = " in %.2f s" % result.cleanup_duration if result.cleanup_duration is not None else ""
    why = ": %s" % result.cleanup_reason if result.cleanup_reason and result.cleanup_failed else ""
    return ["cleanup (root %s): %s%s%s" % (result.ended, said, took, why)] + cleanup_at(
        {"status": result.cleanup_status.value, "at": result.cleanup_failed_at})
