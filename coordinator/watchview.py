"""The terminal view of a run: the tree with statuses, pending calls, tree blackboard,
events and call log, drawn with ``rich`` to fit the terminal (README, "Watching a run").

The tree folds to fit: finished or idle subtrees collapse to one line, and if it
still does not fit, a window around the running branch is shown. Every line is cut,
never wrapped, so redrawing in place leaves no stale lines; the result is wrapped into
lines of its own (over a few at most). The words of calls and of the result are
:mod:`coordinator.watchtext`'s. Where the output is not a terminal, :class:`LinePrinter`
writes one line per change instead.
"""
from __future__ import annotations

import heapq
import json
import re
import threading
import time
from typing import Any, Dict, List, Optional, TextIO, Tuple

from rich.console import Group
from rich.text import Text

from coordinator.runevents import CLEANUP_NOTICES, cleanup_said, control_line, status_word, terminal_text
from coordinator.watchstate import HELD, WatchState, fill
from coordinator.watchtext import call_text, pending_text, result_text, values_text, wrap
from coordinator.watchtext import cut as _cut

__all__ = ["render", "tree_lines", "LinePrinter", "TimeOrderedLines", "STYLE"]

# "was SUCCESS" / "was FAILURE": the node's last outcome, faded, after py_trees reset it (WatchState.label);
# INTERRUPTED: the top node of a tree with cleanup: after a Ctrl-C (the run's status)
STYLE = {"RUNNING": "bold yellow", "SUCCESS": "green", "FAILURE": "bold red", "HALTED": "magenta",
         "INTERRUPTED": "bold magenta", "was SUCCESS": "dim green", "was FAILURE": "dim red", "": "dim"}
MARK = {"RUNNING": "*", "SUCCESS": "+", "FAILURE": "x", "HALTED": "~", "INTERRUPTED": "~", "was SUCCESS": "+",
        "was FAILURE": "x", "": "-"}
BREAK = "●"  # before the name of a node with a breakpoint


def _short(value: Any, width: int = 60) -> str:
    text = json.dumps(value, ensure_ascii=False, separators=(",", ":"), default=str)
    return text if len(text) <= width else text[:width - 1] + "…"


def _children(nodes: List[Dict[str, Any]]) -> Tuple[Dict[Any, List[int]], Dict[int, Dict[str, Any]]]:
    kids: Dict[Any, List[int]] = {}
    by_id = {}
    for n in nodes:
        by_id[n["id"]] = n
        kids.setdefault(n.get("parent"), []).append(n["id"])
    return kids, by_id


def tree_lines(state: WatchState, height: int, now: Optional[float] = None) -> List[Text]:
    """The tree as at most ``height`` lines: folded around the running branch if it is too long.
    A node with a breakpoint is marked ``●``; one a breakpoint holds says so (``RUNNING (held at
    breakpoint)``), an outcome forced by control ``(forced)``; a running loop or wait where it is
    (``item 2 of 3``, ``attempt 2``, ``waited 3.2 s``: ``now`` is the run's time for the seconds)."""
    kids, by_id = _children(state.nodes)
    rows: List[Tuple[int, int, int]] = []  # (id, depth, hidden descendants)

    def walk(i: int, depth: int, fold: bool) -> None:
        below = kids.get(i, [])
        if fold and below and state.label(i) != "RUNNING":
            rows.append((i, depth, _count(i)))
            return
        rows.append((i, depth, 0))
        for c in below:
            walk(c, depth + 1, fold)

    def _count(i: int) -> int:
        return sum(1 + _count(c) for c in kids.get(i, []))

    for fold in (False, True):
        rows = []
        for r in kids.get(None, []):
            walk(r, 0, fold)
        if len(rows) <= height:
            break
    start = 0
    if len(rows) > height:  # a window around the deepest running node
        running = [k for k, (i, _d, _h) in enumerate(rows) if state.label(i) == "RUNNING"]
        focus = running[-1] if running else 0
        start = max(0, min(focus - height // 2, len(rows) - height + 2))
    out: List[Text] = []
    if start:
        out.append(Text("  ↑ %d more" % start, style="dim"))
    window = rows[start:start + height - len(out) - (1 if start + height < len(rows) else 0)]
    for i, depth, hidden in window:
        n = by_id[i]
        label = state.label(i)
        line = Text("  " * depth)
        line.append("%s " % MARK.get(label, "~"), style=STYLE.get(label, ""))
        if i in state.breaks:
            line.append(BREAK + " ", style="bold red")
        line.append(state.name(i), style="bold" if label == "RUNNING" else "dim" if label.startswith("was") else "")
        if n.get("shape") not in (None, "leaf"):
            line.append(" [%s]" % n.get("kind", n.get("shape")), style="dim")
        if label:
            line.append("  %s" % label, style=STYLE.get(label, ""))
            note = state.note(i)
            if note:
                line.append(" (%s)" % note, style="bold magenta" if note == HELD else "magenta")
        progress = state.progress(i) if label == "RUNNING" else None
        if progress:  # a for_each's element, a retry's attempt, how long a wait has waited
            line.append("  " + fill(progress, state.t if now is None else now), style="dim")
        if hidden:
            line.append("  (+%d folded)" % hidden, style="dim")
        fb = state.feedback.get(i)
        if fb and label in ("FAILURE", "was FAILURE"):
            line.append("  " + fb, style=STYLE[label] if label != "FAILURE" else "red")
        out.append(line)
    rest = len(rows) - start - len(window)
    if rest > 0:
        out.append(Text("  ↓ %d more" % rest, style="dim"))
    return out


def _section(title: str) -> Text:
    return Text(title, style="bold cyan")


def _panel(title: str, shown: List[Text], total: int, empty: str) -> List[Text]:
    """A section's title (``(6 of 8)`` when cut: ``total`` is how many there are, also the ones
    no longer kept) and the lines it shows."""
    head = _section("%s%s" % (title, "" if total else ": " + empty))
    if total > len(shown):
        head.append(" (%d of %d%s)" % (len(shown), total, ", last written" if title == "tree blackboard" else ""),
                    style="dim")
    return [head] + shown


def render(state: WatchState, width: int, height: int, footer: str = "", now: Optional[float] = None,
           title: str = "bmtree watch", result: str = "wrap", footer_wrap: bool = False) -> Group:
    """The whole view, exactly ``height`` lines or fewer, none longer than ``width``. ``now``: the
    run's time advanced by the wall clock since its last record (:func:`now_since`) for the header's
    clock and the pending calls' elapsed times; ``title``: what shows it (``bmtree run``);
    ``result``: the result line wrapped to at most a sixth of the height (``wrap``), whole
    (``full``) or left out (``none``: the watch prints it after the view); ``footer_wrap``: the footer
    (an answer to a command: a refusal lists the nodes a shared name may mean) wrapped over at most a
    sixth of the height. While the run's node does not answer the watch (:meth:`WatchState.silence`), a
    line under the header says that what is shown may be stale."""
    with state.lock:
        name = state.tree.get("name") or "(waiting for a run on the run stream)"
        # between records the run's clock moves on: a long call makes no record until it ends
        t_now = state.t if now is None or state.end or not state.nodes else max(state.t, now)
        head = Text()
        head.append("%s " % title, style="bold")
        head.append("%s  t=%.1fs  tick %d" % (name, t_now, state.tick))
        if state.paused:
            head.append("  PAUSED", style="bold magenta")
        if state.end:
            head.append("  %s" % status_word(state.end.get("status")), style=STYLE.get(str(state.end.get("status")), ""))
        # the run's node does not answer the watch (a link down, its process stopped): over two lines at most
        silent = state.silence()
        stale = [Text(line, style="bold yellow") for line in wrap(silent, width, 2)] if silent else []
        pending = list(state.pending.values())
        tw = max([16] + [len(str(c.get("target"))) for c in pending])
        plines = [Text(pending_text(state, c, t_now, width, min(24, tw)),
                       style="yellow" if c.get("maybe_running") else "dim" if c.get("answered") is not None else "")
                  for c in pending]
        written = [k for k in state.written if k in state.blackboard]  # oldest write first
        known = set(written)
        written = [k for k in state.blackboard if k not in known] + written
        # by time, and at one time in the order they came (a breakpoint hit right after a resume
        # comes after it); the run's events before its control answers
        timed = [(float(e.get("t") or 0.0), Text("  %7.2fs %s" % (float(e.get("t") or 0.0), event_text(e, 40)),
                                                 style=_notice_style(e)))
                 for e in state.all_events()]
        timed += [(float(c.get("t") or 0.0), Text("  %7.2fs control %s" % (float(c.get("t") or 0.0), control_line(c)),
                                                  style="magenta")) for c in state.control]
        timed.sort(key=lambda x: x[0])
        ev = [text for _t, text in timed]
        shown = state.shown_calls()  # those the stop from outside halted: "interrupted", as the summary says
        tw = max([16] + [len(str(c.get("target"))) for c in shown])
        sw = max([9] + [len(str(c.get("status"))) for c in shown])
        calls = [Text(call_text(c, width, min(24, tw), sw), style="red" if c.get("status") != "succeeded" else "")
                 for c in shown]
        end = []
        if state.end and result != "none":
            style = STYLE.get(str(state.end.get("status")), "")
            most = None if result == "full" else max(2, height // 6)
            end = [Text(line, style=style) for line in wrap(result_text(state.end), width, most)]

        def board(take: int) -> List[Text]:
            """The keys shown in order; cut, the most recently written ones (a stale one matters least)."""
            keys = sorted(written if take >= len(written) else written[len(written) - take:])
            return [Text("  %s = %s" % (k, _short(state.blackboard[k], max(20, width - len(k) - 6)))) for k in keys]

        # budget: header, footer, result; the panels get a share, the tree the rest, and the lines
        # the tree leaves unused go back to the panels that were cut
        foot = [] if not footer else [footer] if not footer_wrap else wrap(footer, width, max(1, height // 6))
        fixed = 1 + len(stale) + len(foot) + len(end)
        room = max(4, height - fixed)
        sizes = [len(plines), len(written), len(ev), len(calls)]
        share = max(1, room // 3 // len(sizes)) if height < 30 else max(2, room // 2 // len(sizes))
        takes = [min(n, share) for n in sizes]
        tree = tree_lines(state, max(3, room - len(sizes) - sum(takes)), t_now)
        spare = room - len(tree) - len(sizes) - sum(takes)
        while spare > 0 and any(t < n for t, n in zip(takes, sizes)):
            for k, n in enumerate(sizes):  # one line each in turn, so that no cut panel takes them all
                if spare > 0 and takes[k] < n:
                    takes[k] += 1
                    spare -= 1
        body = (_panel(state.pending_title(), plines[:takes[0]], len(plines), "none")
                + _panel("tree blackboard", board(takes[1]), len(written), "empty")
                + _panel("last events", ev[len(ev) - takes[2]:], len(ev), "none")
                + _panel("call log", calls[len(calls) - takes[3]:], max(len(calls), state.calls_total), "none"))
        out = [head] + stale + tree + body + end + [Text(line, style="dim") for line in foot]
    out = [_safe(line) for line in out[:height]]
    for line in out:
        line.no_wrap = True
        line.overflow = "ellipsis"
        line.truncate(width, overflow="ellipsis")
    return Group(*out)


def _safe(line: Text) -> Text:
    """``line`` with its control characters escaped (:func:`terminal_text`; rich passes an ESC through):
    a module's error text must not drive the terminal, nor a newline break the one-line layout."""
    plain = line.plain
    safe = terminal_text(plain, newlines=False)
    return line if safe == plain else Text(safe, style=line.style)


def _notice_style(rec: Dict[str, Any]) -> str:
    """Notices stand out among the events: about the graph or the cleanup, yellow; a failed cleanup red."""
    if rec.get("type") != "notice":
        return ""
    return "red" if rec.get("what") == "cleanup_failed" else "yellow"


def event_text(rec: Dict[str, Any], width: int = 60) -> str:
    """A module's event (``people.lostPerson {...}``) or a notice (about the graph, the tree's cleanup), as text."""
    if rec.get("type") == "notice":
        return str(rec.get("text"))
    return "%s.%s %s" % (rec.get("module"), rec.get("event"), _short(rec.get("params"), width))


class LinePrinter:
    """One line per change (statuses, calls, events, writes, control, the end), for logs and pipes.

    A call that ended halted is printed once it is known whether the stop from outside halted it
    (:meth:`WatchState.call_settled`), as ``interrupted`` then, as the run's summary says it."""

    def __init__(self, out: TextIO):
        self.out = out
        self._end: Optional[Tuple[int, str]] = None  # the end's line, held until its last tick is printed
        self._noted = 0  # the watch's own notices printed (another run started)
        self._held: List[Dict[str, Any]] = []  # call_end records that ended halted, until their label is known
        self._shown = ""  # the run whose lines are printed (its header said)
        self._caught_runs: List[str] = []  # the runs whose catching up was said (once each)
        self._progress: Dict[Any, str] = {}  # what was said of each loop's place (item, attempt)

    def _start(self, rec: Dict[str, Any], state: WatchState) -> None:
        """The header of the run shown from now on, then its records that came before its tree: those of
        the run shown before (held lines) are said first, and lines in run-time order start anew."""
        self.finish()
        boundary = getattr(self.out, "boundary", None)
        if callable(boundary):
            boundary()   # the lines held of the run before go out now, ordered among themselves
        self._shown = state.run
        self._progress = {}
        self._write(self._note_lines(state) + [
            "run %s: %s (%d nodes)" % (rec.get("run"), rec.get("name"), len(rec.get("nodes") or []))])
        for r in state.taken:
            self.record(r, state)

    def _place(self, i: int, t: float, state: WatchState) -> str:
        """`` (item 2 of 3)``: where a running loop is, said when the watch catches up (then not again)."""
        kind = next((str(n.get("kind")) for n in state.nodes if n.get("id") == i), "")
        p = state.progress(i) if kind in ("for_each", "retry", "repeat") else None
        if not p:
            return ""
        self._progress[i] = str(p.get("text"))
        return " (%s)" % (fill(p, t) if p.get("until") is not None else str(p.get("text")).replace("{s}", "its delay"))

    def _progress_lines(self, t: float, state: WatchState) -> List[str]:
        """A line for each running for_each now at another element, and each retry at another attempt or
        waiting its delay before one (``[  1.200s] attempt   go to the item: attempt 2``), as the terminal
        shows them (a retry's first attempt is its RUNNING line)."""
        out = []
        said: Dict[Any, str] = {}
        for n in state.nodes:
            i, kind = n.get("id"), str(n.get("kind"))
            p = state.progress(i) if kind in ("for_each", "retry", "repeat") else None
            if not p:
                continue
            said[i] = str(p.get("text"))
            if self._progress.get(i) == said[i] or said[i] == "attempt 1" or said[i].startswith("attempt 1 of "):
                continue
            text = fill(p, t) if p.get("until") is not None else said[i].replace("{s}", "its delay")
            out.append("[%7.3fs] %-9s %s: %s" % (t, {"retry": "attempt", "repeat": "run"}.get(kind, "item"),
                                                  state.name(i), text))
        self._progress = said
        return out

    def finish(self) -> None:
        """Print the held lines (the calls' and the end's), if their tick or end never came."""
        lines, self._held = [self._call_line(c, None) for c in self._held], []
        if self._end is not None:
            lines.append(self._end[1])
            self._end = None
        self._write(lines)

    def _call_line(self, rec: Dict[str, Any], state: Optional[WatchState]) -> str:
        status, error = state.call_label(rec) if state is not None else (rec.get("status"), rec.get("error"))
        status = "lost" if status == "module_lost" else status  # (9 wide: its error says which module was lost)
        outputs = values_text(rec.get("outputs")) if not error else ""
        return "[%7.3fs] %-9s %s %s" % (float(rec.get("t") or 0.0), status, rec.get("target"), error or (
            "→ " + _cut(outputs, 100) if outputs else ""))

    def _settled(self, state: WatchState) -> List[str]:
        """The lines of the held calls whose label is now known (in the order they came)."""
        done = [c for c in self._held if state.call_settled(c)]
        self._held = [c for c in self._held if not any(c is d for d in done)]
        return [self._call_line(c, state) for c in done]

    def _write(self, lines: List[str]) -> None:
        for line in lines:
            self.out.write(terminal_text(line) + "\n")
        self.out.flush()

    def _note_lines(self, state: WatchState) -> List[str]:
        """The watch's own notices not printed yet (another run started, the run's node silent)."""
        if state.notes_made < self._noted:  # another run shown (--follow): its notes start anew
            self._noted = 0
        new = min(state.notes_made - self._noted, len(state.notes))
        self._noted = state.notes_made
        return ["[%7.3fs] notice    %s" % (float(n.get("t") or 0.0), n.get("text"))
                for n in (state.notes[-new:] if new > 0 else [])]

    def notes(self, state: WatchState) -> None:
        """Print the watch's own notices that came between records (the run's node stopped answering:
        no record comes then). Called with ``state.lock`` held."""
        self._write(self._note_lines(state))

    def record(self, rec: Dict[str, Any], state: WatchState) -> None:
        kind = rec.get("type")
        t = float(rec.get("t") or 0.0)
        plain = {n.get("id"): n.get("name") for n in state.nodes}

        def name(i: Any) -> Any:  # an include with the values of its arguments, as the other views show it
            return state.name(i) if i in plain else plain.get(i, i)

        if kind == "tree" and state.nodes and rec.get("run") == state.run and self._shown != state.run:
            self._start(rec, state)
            return
        lines = self._note_lines(state)
        if not state.nodes or (rec.get("run") and rec.get("run") != state.run):
            # another run's record (the state keeps it aside, a notice says so), or one of the run to show
            # that came before its tree (topics are not ordered among them): said after its header
            self._write(lines)
            return
        if kind == "call_end" and rec.get("status") == "halted":
            self._held.append(rec)
        lines += self._settled(state)
        if kind == "tree":
            pass  # the same run's tree again (latched)
        elif kind == "snapshot" and state.run not in self._caught_runs and (
                any(r is rec for r in state.loaded) or (state.caught_up and rec.get("n") == state.tick)):
            self._caught_runs.append(state.run)  # the periodic snapshots after the first say nothing new
            running = ["%s RUNNING%s" % (name(int(k)), self._place(int(k), t, state))
                       for k, v in (rec.get("status") or {}).items() if v == "RUNNING"]
            pending = ["%s since %.3fs" % (c.get("target"), float(c.get("t") or 0.0)) for c in rec.get("pending") or []]
            done = max(int(rec.get("ncalls") or 0), len(rec.get("calls") or []))
            lines.append("[%7.3fs] caught up at tick %s: %s; pending calls: %s; %d call%s done" % (
                t, rec.get("n"), ", ".join(running) or "nothing running", ", ".join(pending) or "none",
                done, "" if done == 1 else "s"))
        elif kind == "tick":
            for ch in rec.get("changes") or []:
                status = ch[1]
                if status == "INVALID":
                    if state.halted.get(ch[0]):  # (the top node of a tree with cleanup: the run's status)
                        word = state.label(ch[0]) if state.status.get(ch[0], "INVALID") == "INVALID" else "HALTED"
                        lines.append("[%7.3fs] %-9s %s" % (t, word, name(ch[0])))
                    continue
                why = state._said(ch[0], str(ch[2])) if len(ch) > 2 and ch[2] else ""  # (a retry's attempts)
                note = state.note(ch[0]) if state.status.get(ch[0]) == status else ""
                if note and why.startswith("forced to"):
                    note = ""  # its reason says it
                extra = "".join(" (%s)" % w for w in (note, why) if w)
                lines.append("[%7.3fs] %-9s %s%s" % (t, status, name(ch[0]), extra))
            lines += self._progress_lines(t, state)
        elif kind == "call_start":
            lines.append("[%7.3fs] call      %s %s" % (t, rec.get("target"), _short(rec.get("inputs"))))
        elif kind == "call_end" and rec.get("status") != "halted":
            lines.append(self._call_line(rec, state))
        elif kind == "call_answer":
            lines.append("[%7.3fs] answered  %s (%s), taken at the next tick" % (t, rec.get("target"), rec.get("answer")))
        elif kind == "event":
            lines.append("[%7.3fs] event     %s" % (t, event_text(rec)))
        elif kind == "notice":  # about the ROS graph, or the tree's cleanup
            lines.append("[%7.3fs] %-9s %s" % (t, "cleanup" if rec.get("what") in CLEANUP_NOTICES else "notice",
                                               event_text(rec)))
        elif kind == "write":
            lines.append("[%7.3fs] write     %s = %s" % (t, rec.get("key"), _short(rec.get("value"))))
        elif kind == "control":
            lines.append("[%7.3fs] control   %s" % (t, control_line(rec)))
        elif kind == "end":
            line = "[%7.3fs] end       %s%s" % (t, status_word(rec.get("status")),
                                                (": %s" % rec["reason"]) if rec.get("reason") else "")
            said = cleanup_said(rec.get("cleanup"))
            if said:  # a tree with cleanup: how it ended (the run's status stays root's)
                line += "; " + said
            ticks = rec.get("ticks")
            for c in state.pending.values() if rec.get("gone") else ():
                line += "\n[%7.3fs] maybe still running (run gone): %s since %.3fs %s" % (
                    t, c.get("target"), float(c.get("t") or 0.0), _short(c.get("inputs")))
            if isinstance(ticks, int) and state.tick < ticks:  # latched, it can overtake the queued last ticks
                self._end = (ticks, line)
            else:
                lines.append(line)
        if kind == "tick" and self._end is not None and state.tick >= self._end[0]:
            lines.append(self._end[1])
            self._end = None
        for line in lines:  # a module's text holds no control character the terminal would obey
            self.out.write(terminal_text(line.rstrip()) + "\n")
        if lines:
            self.out.flush()


def now_since(state: WatchState, anchor: List[float]) -> float:
    """The run's time now, advanced between records by the wall clock (for elapsed times)."""
    mono = time.monotonic()
    if not anchor or anchor[0] != state.t:
        anchor[:] = [state.t, mono]
    return anchor[0] + (mono - anchor[1]) if not state.end else state.t


_STAMP = re.compile(r"^\[\s*(-?\d+(?:\.\d+)?)s\]")


class TimeOrderedLines:
    """A text stream that writes the lines of :class:`LinePrinter` in the order of their run time.

    Over ROS the run stream's records come on several topics, ordered per topic only: a tick's
    status changes could be printed after the calls that followed them (``[0.084s] cleanup …`` and then
    ``[0.080s] SUCCESS look``). Each line waits ``window`` seconds for an earlier one that may still come,
    then lines go out earliest first (a line without a time goes with the one before it).
    :meth:`close` writes what is held.
    """

    def __init__(self, out: TextIO, window: float = 0.3):
        self.out = out
        self.window = window
        self._partial = ""
        self._held: List[Tuple[float, int, float, str]] = []   # (run time, arrival order, arrived, line)
        self._seq = 0
        self._last_t = float("-inf")
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._pump, name="watch-lines", daemon=True)
        self._thread.start()

    def write(self, text: str) -> int:
        with self._lock:
            if self._stop.is_set():   # closed: a line that comes later (another topic's, after the end) goes at once
                self.out.write(text)
                self.out.flush()
                return len(text)
            self._partial += text
            *lines, self._partial = self._partial.split("\n")
            now = time.monotonic()
            for line in lines:
                m = _STAMP.match(line)
                if m:
                    self._last_t = float(m.group(1))
                self._seq += 1
                heapq.heappush(self._held, (self._last_t, self._seq, now, line))
        return len(text)

    def flush(self) -> None:
        self._release(time.monotonic() - self.window)

    def boundary(self) -> None:
        """Another run's lines come next (``watch --follow``): those held go out now, and the order starts
        anew (its times begin at 0 again; the run's header, which has none, is not kept behind them)."""
        self._release(float("inf"))
        with self._lock:
            self._last_t = float("-inf")

    def _release(self, arrived_by: float) -> None:
        with self._lock:
            lines = []
            while self._held and self._held[0][2] <= arrived_by:
                lines.append(heapq.heappop(self._held)[3])
            if lines:
                self.out.write("".join(line + "\n" for line in lines))
                self.out.flush()

    def _pump(self) -> None:
        while not self._stop.wait(self.window / 3):
            self.flush()

    def close(self) -> None:
        """Write every line held (the watch ends); later lines are written at once."""
        with self._lock:
            self._stop.set()
            lines = [heapq.heappop(self._held)[3] for _ in range(len(self._held))]
            self.out.write("".join(line + "\n" for line in lines) + self._partial)
            self._partial = ""
            self.out.flush()

