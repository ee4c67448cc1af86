"""The words of the watch views: calls with their inputs and outputs in short, the tree node that
made a call and where its ``for_each`` is, the result, and what the terminal prints once its live
view has ended (README, "Watching a run"). Plain text: :mod:`coordinator.watchview` styles it.
"""
from __future__ import annotations

import json
import math
import re
import textwrap
from typing import Any, Dict, List, Optional

from coordinator.runevents import cleanup_at, cleanup_said, status_word, steered_lines, terminal_text
from coordinator.watchstate import SILENCE_NOTES, WatchState

__all__ = ["brief", "values_text", "cut", "share", "where_text", "pending_text", "call_text", "result_text",
           "wrap", "summary_lines"]

_BARE = re.compile(r"^[\w./@+-]+$")  # a string shown without quotes (``kitchen``, ``/map``, ``a.b``)


def brief(value: Any) -> str:
    """A value in few characters: ``{x:0,y:1.5,z:0}``, ``[a,b]``, ``kitchen``, ``"two words"``, ``NaN``."""
    if isinstance(value, bool) or value is None:
        return json.dumps(value)
    if isinstance(value, float):  # NaN, Infinity, -Infinity as the other panels, replay and the page say them
        return "%.6g" % value if math.isfinite(value) else json.dumps(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return value if _BARE.match(value) else json.dumps(value, ensure_ascii=False)
    if isinstance(value, dict):
        return "{%s}" % ",".join("%s:%s" % (k, brief(v)) for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return "[%s]" % ",".join(brief(v) for v in value)
    return json.dumps(value, ensure_ascii=False, default=str)


def values_text(values: Any) -> str:
    """A call's inputs or outputs: ``place kitchen``, ``position {x:0,y:0,z:0}, seen true``."""
    if isinstance(values, dict):
        return ", ".join("%s %s" % (k, brief(v)) for k, v in values.items())
    return "" if values is None else brief(values)


def cut(text: str, width: int) -> str:
    """``text`` in at most ``width`` characters (``…`` where it was cut)."""
    if width <= 0:
        return ""
    return text if len(text) <= width else text[:width - 1] + "…"


def share(first: str, second: str, room: int, first_share: float = 0.5) -> str:
    """Both texts in ``room`` characters (``first  second``): the shorter one whole if it fits in
    its share, the other one the rest; else each cut to its share. With ``first_share`` over a
    half, the first one is whole whenever the second one keeps 8 characters."""
    sep = "  " if first and second else ""
    if len(first) + len(sep) + len(second) <= room:
        return first + sep + second
    if not second:
        return cut(first, room)
    if not first:
        return cut(second, room)
    mine = max(8, int(room * first_share))
    if len(first) <= mine or (first_share > 0.5 and len(first) + len(sep) + 8 <= room):  # the first one first
        return first + sep + cut(second, room - len(first) - len(sep))
    if len(second) <= room - mine - len(sep):
        return cut(first, room - len(second) - len(sep)) + sep + second
    return cut(first, mine) + sep + cut(second, room - mine - len(sep))


def _names(state: WatchState) -> Dict[Any, Dict[str, Any]]:
    return {n.get("id"): n for n in state.nodes}


def where_text(state: WatchState, node: Any) -> str:
    """The tree node that made a call, with the element of each ``for_each`` and the attempt of each
    ``retry`` above it: ``'go to the room' (item 47 of 90, attempt 2)``; '' for a node the tree does not have."""
    by_id = _names(state)
    n = by_id.get(node)
    if n is None:
        return ""
    loops = []
    up = n.get("parent")
    seen = 0
    while up is not None and seen < 1000:  # a malformed tree must not loop
        seen += 1
        at = state.progress(up)
        if at and "{s}" not in str(at.get("text")):  # a loop's place (not a wait's seconds)
            loops.append(str(at["text"]))
        up = (by_id.get(up) or {}).get("parent")
    text = repr(str(n.get("name", "?")))
    return text + (" (%s)" % ", ".join(reversed(loops)) if loops else "")


def pending_text(state: WatchState, c: Dict[str, Any], t_now: float, width: int, target_width: int) -> str:
    """One pending call: target, elapsed time and timeout (or answered, or maybe still running
    after its run is gone), the node that made it and its inputs, in ``width`` characters."""
    if c.get("maybe_running"):
        when = "since %.2fs, maybe still running (run gone)" % float(c.get("t") or 0.0)
    elif c.get("answered") is not None:
        when = "answered (%s) at %.2fs, taken at next tick" % (c.get("answer") or "?", float(c["answered"]))
    else:
        to = c.get("timeout")
        when = "%6.1fs / %s" % (max(0.0, t_now - float(c.get("t") or 0.0)), ("%gs" % to) if to else "-")
    head = "  %-*s %s" % (target_width, c.get("target"), when)
    return head + "  " + share(where_text(state, c.get("node")), values_text(c.get("inputs")),
                               max(0, width - len(head) - 2), first_share=0.6)


def call_text(c: Dict[str, Any], width: int, target_width: int, status_width: int) -> str:
    """One finished call: start, target, status, duration, then its inputs and what it answered
    (``→ position {x:0,y:0,z:0}``) or its error, in ``width`` characters."""
    st = str(c.get("status"))
    head = "  %7.2fs %-*s %-*s %6.2fs" % (float(c.get("started") or 0.0), target_width, c.get("target"),
                                          status_width, st, float(c.get("duration") or 0.0))
    room = max(0, width - len(head) - 2)
    inputs = values_text(c.get("inputs"))
    if c.get("error"):
        tail = str(c.get("error"))
        body = share(inputs, tail, room, first_share=0.3)
    else:
        outputs = values_text(c.get("outputs"))
        body = share(inputs, "→ " + outputs if outputs else "", room)
    return head + ("  " + body if body else "")


def result_text(end: Dict[str, Any]) -> str:
    """The result line: ``result: FAILURE in 66.85s (282 ticks)  reason: …`` (``INTERRUPTED`` for a run
    stopped by Ctrl-C), then how a tree's cleanup ended (``cleanup (root stopped): succeeded in 0.41 s``);
    a run that is gone (the watch's own end) lived at least until it was found gone."""
    if end.get("gone"):
        head = "result: %s, gone at about %.2fs (%s ticks)" % (end.get("status"), float(end.get("duration") or 0.0),
                                                               end.get("ticks"))
    else:
        head = "result: %s in %.2fs (%s ticks)" % (status_word(end.get("status")), float(end.get("duration") or 0.0),
                                                    end.get("ticks"))
    cleanup = cleanup_said(end.get("cleanup"))
    steered = end.get("steered") if isinstance(end.get("steered"), list) else []
    return head + (("  reason: %s" % end["reason"]) if end.get("reason") else "") + ("  " + cleanup if cleanup else "") \
        + ("  steered: %s" % "; ".join(str(s) for s in steered) if steered else "")


def wrap(text: str, width: int, most: Optional[int] = None) -> List[str]:
    """``text`` wrapped to ``width`` (the lines after the first indented), at most ``most`` lines
    (the last one then ends with ``…``)."""
    lines = textwrap.wrap(text, max(10, width), subsequent_indent="  ", break_on_hyphens=False) or [""]
    if most is not None and len(lines) > most:
        lines = lines[:max(1, most)]
        lines[-1] = cut(lines[-1] + " …", width) if len(lines[-1]) + 2 <= width else cut(lines[-1], width - 1) + "…"
    return lines


def summary_lines(state: WatchState) -> List[str]:
    """What the terminal prints once its live view has ended (the alternate screen is gone with
    it): the result with the whole reason, the calls a run that is gone may have left running,
    and the other runs on the master, with how to watch them."""
    out: List[str] = []
    with state.lock:
        name = state.tree.get("name") or "?"
        end = state.end
        if end is None:
            if state.nodes:
                out.append("the watch ended before the run %s (at %.2fs, tick %d)" % (name, state.now(), state.tick))
        else:
            out.append(result_text(dict(end, reason="", cleanup=None, steered=None)))
            if end.get("reason"):
                out.append("reason: %s" % end["reason"])
                if end.get("at"):
                    out.append("at: %s" % end["at"])
            out.extend(steered_lines(end.get("steered")))
            if cleanup_said(end.get("cleanup")):
                out.append(cleanup_said(end.get("cleanup")))
                out.extend(cleanup_at(end.get("cleanup")))
            for c in state.pending.values():
                if c.get("maybe_running"):
                    where = where_text(state, c.get("node"))
                    out.append("maybe still running (run gone): %s since %.2fs%s%s" % (
                        c.get("target"), float(c.get("t") or 0.0), " in %s" % where if where else "",
                        ("  " + values_text(c.get("inputs"))) if c.get("inputs") else ""))
            if end.get("gone"):
                out.append("the run did not finish (exit 3): nobody stopped its calls (a bmtree module cancels "
                           "the calls of a caller that is gone; other modules may run them to their end)")
        for note in state.notes:  # the other runs (the run's node silent for a while is over: it ended)
            if note.get("what") not in SILENCE_NOTES:
                out.append(str(note.get("text")))
    return [terminal_text(line) for line in out]
