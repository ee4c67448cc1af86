"""What happens during a run, as callbacks: the one interface of the display, the run
stream, the run log and the failure explanation.

The runner calls :meth:`RunObserver.on_start`, :meth:`~RunObserver.on_tick` and
:meth:`~RunObserver.on_end`; the :class:`~coordinator.context.RunContext` notifies
calls, events and tree-blackboard writes. Every ``now`` is the run clock's
``now()`` (not relative to the start), so observers on a simulated clock see
simulated time. Observers run in the ticking thread: they must be quick and must
not raise (a failing observer is logged and detached, the run goes on).
"""
from __future__ import annotations

import json
import logging
import re
import sys
from dataclasses import dataclass
from typing import Any, Callable, Dict, Iterable, List, Optional, TextIO, Tuple

import py_trees
from py_trees.common import Status

__all__ = ["terminal_text", "TerminalText", "tree_drawing", "Display", "NoticeLines", "include_setters", "RunObserver", "StatusWatcher", "Change", "Notice", "notify", "control_line", "status_word", "stop_status",
           "halted_word", "cleanup_said", "cleanup_at", "steered_lines",
           "CLEANUP_NOTICES", "IncludeArgs", "include_label"]

log = logging.getLogger("bmtree.coordinator")

Change = Tuple[Any, Status, Status]  # (behaviour, old status, new status)

# control characters (C0 but tab and newline, DEL, C1) and lone surrogates: a module's text holding them
# (``\x1b[2J``, a bare ``\r``) would clear, move or recolour the terminal it is shown on
_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\ud800-\udfff]")
_CONTROL_OR_NEWLINE = re.compile("[\x00-\x08\x0a-\x1f\x7f-\x9f\ud800-\udfff]")


def _escaped(m: Any) -> str:
    code = ord(m.group())
    if code in (10, 13):
        return "\\n" if code == 10 else "\\r"
    return "\\x%02x" % code if code < 0x100 else "\\u%04x" % code


def terminal_text(text: Any, newlines: bool = True) -> str:
    """``text`` safe to print on a terminal: each control character but tab (and newline, unless
    ``newlines`` is False: a line of a table or of a view that must stay one line) shown escaped
    (``\\x1b``), so that text from a module or a log never drives the terminal. Every terminal output
    of a run's text (``bmtree run``, ``watch``, ``replay``, ``runs``, errors) goes through it."""
    text = text if isinstance(text, str) else str(text)
    pattern = _CONTROL if newlines else _CONTROL_OR_NEWLINE
    return pattern.sub(_escaped, text) if pattern.search(text) else text


def tree_drawing(root: Any, name: Optional[Callable[[Any, str], str]] = None) -> str:
    """py_trees' drawing of ``root`` with statuses, each node's name (``name(b, b.name)``) and feedback
    (a module's text) escaped first: the drawing's own colours reach the terminal (escaped after the
    drawing, they showed as ``\x1b[32m✓\x1b[0m``)."""
    shown = {b: (b.name, b.feedback_message) for b in root.iterate()}
    try:
        for b, (was, feedback) in shown.items():
            b.name = terminal_text(name(b, was) if name is not None else was, newlines=False)
            b.feedback_message = terminal_text(feedback, newlines=False)
        return py_trees.display.unicode_tree(root, show_status=True)
    finally:
        for b, (was, feedback) in shown.items():
            b.name, b.feedback_message = was, feedback


class TerminalText:
    """A text stream that writes everything through :func:`terminal_text` (newlines kept)."""

    def __init__(self, stream: TextIO):
        self.stream = stream

    def write(self, text: str) -> int:
        return self.stream.write(terminal_text(text))

    def write_drawing(self, text: str) -> int:
        """A :func:`tree_drawing` as it is: its text is escaped already, its colours are its own."""
        return self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()

    def isatty(self) -> bool:
        return self.stream.isatty()


@dataclass
class Notice:
    """Something that happened to the ROS graph under the run, which explains what follows
    (the master went away, came back), delivered by the transport like a result; or an answer
    that came after its call had ended (``late_answer``, made by the run context: the module ran a
    call the run had given up on, and a ``retry`` may have sent it again)."""

    # master_down, master_back, other_run, blackboard_down, blackboard_back, late_answer; cleanup (a run
    # stopped from outside runs its tree's cleanup), cleanup_failed (the cleanup failed or was cut short),
    # shutdown_request (the run's node was asked to shut down: rosnode kill, a node of the same name)
    what: str
    text: str
    call_id: str = ""   # the call a late answer answers


class RunObserver:
    """Every method is optional: the base class does nothing."""

    def on_start(self, tree: Any, root: Any, ctx: Any) -> None:
        """Before the first tick: ``tree`` is the loaded TreeFile (or None), ``root`` the py_trees root."""

    def on_tick(self, root: Any, changes: List[Change], now: float) -> None:
        """After every tick, with the status changes of that tick in the order they happened."""

    def on_call_start(self, record: Any) -> None:
        """A call was sent (a CallRecord with its inputs)."""

    def on_call_end(self, record: Any) -> None:
        """A call ended: its status, error, outputs and duration are set."""

    def on_call_answer(self, record: Any) -> None:
        """While the run is paused (``--control``), the answer to a call came (``record.answered``,
        ``record.result``); its leaf takes it at the next tick, which tells ``on_call_end``."""

    def on_event(self, event: Any, now: float) -> None:
        """A module event arrived."""

    def on_blackboard_write(self, key: str, value: Any, now: float) -> None:
        """A tree-blackboard key was written."""

    def on_recall(self, values: List[Dict[str, Any]], now: float) -> None:
        """A ``recall`` read values from the Blackboard node (before writing them to its keys): per
        value ``key``, ``name`` asked, ``rostype``, ``value`` (the message) and where it came from,
        ``basic_mod``, ``function``, ``call_id``, ``stamp`` (an earlier run's result, or this one's)."""

    def on_end(self, result: Any) -> None:
        """The run ended (a RunResult, with its reason)."""

    def on_control(self, record: Any, now: float) -> None:
        """A control command was answered (``bmtree run --control``): command, args, ok, answer, by."""

    def on_notice(self, notice: Notice, now: float) -> None:
        """The transport noticed something about the ROS graph, or a call was answered after it had
        ended (a :class:`Notice`)."""


def control_line(record: Dict[str, Any]) -> str:
    """A control record as one line: ``force 'grasp' FAILURE by /bmtree_ctl_1: 'grasp' will end in …``."""
    args = record.get("args") if isinstance(record.get("args"), dict) else {}
    words = [str(record.get("command", "?"))] + [repr(v) if k in ("node", "key") else str(v) for k, v in args.items()]
    verdict = "" if record.get("ok", True) else "refused: "
    return "%s by %s: %s%s" % (" ".join(words), record.get("by") or "?", verdict, record.get("answer", ""))


def notify(observers: List[RunObserver], method: str, *args: Any) -> None:
    """Call ``method`` on every observer; one that raises is logged and removed."""
    for o in list(observers):
        try:
            getattr(o, method)(*args)
        except Exception:  # an observer must never stop the run
            log.exception("run observer %r failed in %s; detached", o, method)
            observers.remove(o)


class StatusWatcher:
    """Turns one tick into the status changes it caused, in order.

    A behaviour's status is read when the tick yields it (a retried child's FAILURE
    is seen before the retry resets it); behaviours changed without being visited
    (halted by a parent) are found by a sweep over those not INVALID before.
    """

    def __init__(self) -> None:
        self._last: Dict[Any, Status] = {}

    def changes(self, visited: Iterable[Tuple[Any, Status]]) -> List[Change]:
        last = self._last
        out: List[Change] = []
        invalid = Status.INVALID
        for b, s in visited:
            old = last.get(b, invalid)
            if old is not s:
                out.append((b, old, s))
                if s is invalid:
                    del last[b]
                else:
                    last[b] = s
        for b, old in list(last.items()):
            s = b.status
            if s is not old:
                out.append((b, old, s))
                if s is invalid:
                    del last[b]
                else:
                    last[b] = s
        return out


#: the kinds of notice about a tree's cleanup (not about the ROS graph)
CLEANUP_NOTICES = ("cleanup", "cleanup_failed")


def status_word(status: Any) -> str:
    """A run's status as people read it: py_trees' ``INVALID`` of a run stopped from outside (Ctrl-C)
    is ``INTERRUPTED``; machine-readable records keep ``INVALID``."""
    text = str(getattr(status, "value", status))
    return "INTERRUPTED" if text == "INVALID" else text


def stop_status(reason: str) -> str:
    """The status of a run stopped from outside, from the runner's reason for it (the ``ended_reason`` a
    tree's cleanup reads): ``INVALID`` (shown ``INTERRUPTED``) for a Ctrl-C or another signal
    (``interrupted while …``), ``FAILURE`` for a time limit (``stopped after 60 s while …``), as the
    run's ``end`` record says it once it comes."""
    return "INVALID" if reason.startswith("interrupted") else "FAILURE"


def halted_word(b: Any) -> str:
    """What a behaviour halted while running is shown as: ``HALTED``; the top node of a tree with
    ``cleanup:`` (``with_cleanup``, which stands for the whole run: it ends so only when root was stopped
    from outside) the run's status, ``INTERRUPTED`` for a Ctrl-C, as the watch and its page show it. ``b``
    says how root ended by its ``ended`` and ``ended_reason`` (a WithCleanup's; a replay's stand-in's)."""
    reason = getattr(b, "ended_reason", None)
    if getattr(b, "ended", "") == "stopped" and isinstance(reason, str):
        return status_word(stop_status(reason))
    return "HALTED"


def cleanup_said(said: Any) -> str:
    """How a tree's cleanup ended, from the ``cleanup`` of an ``end`` record: ``cleanup (root stopped):
    succeeded in 0.41 s`` (``FAILED …: why``, ``cut short …: why``); '' for a run without one."""
    if not isinstance(said, dict):
        return ""
    status = said.get("status")
    if status is None:
        return "cleanup (root %s): did not run" % said.get("ended")
    word = {"SUCCESS": "succeeded", "FAILURE": "FAILED"}.get(str(status), "cut short")
    why = ": %s" % said.get("reason") if said.get("reason") and status != "SUCCESS" else ""
    return "cleanup (root %s): %s in %.2f s%s" % (said.get("ended"), word, float(said.get("duration") or 0.0), why)


def steered_lines(steered: Any) -> List[str]:
    """What ``bmtree control`` changed in a run, under its result: a result it steered is not the tree's own."""
    texts = [str(s) for s in steered] if isinstance(steered, list) else []
    return ["steered: %s" % s for s in texts[:5]] + (
        ["steered: … and %d more (the run log has every control command)" % (len(texts) - 5)] if len(texts) > 5 else [])


def cleanup_at(said: Any) -> List[str]:
    """The line under :func:`cleanup_said`'s of a failed cleanup: where its failure is written."""
    if not isinstance(said, dict) or said.get("status") != "FAILURE" or not said.get("at"):
        return []
    return ["  at: %s" % said["at"]]


_ARG = re.compile(r"(?:^|(?<=, ))([A-Za-z_][A-Za-z0-9_]*)=")


def _short(value: Any, width: int) -> str:
    text = json.dumps(value, ensure_ascii=False, separators=(",", ":"), default=str)
    return text if len(text) <= width else text[:width - 1] + "…"


def include_label(name: str, values: Optional[Dict[str, Any]], width: int = 40, most: int = 160) -> str:
    """An include's name with the values its arguments had (``fetch_item(item="milk")``, not
    ``fetch_item(item=$item)``), each cut to ``width`` characters and the whole to ``most``; the name
    as it is without values."""
    head, paren, inner = name.partition("(")
    if not values or not paren or not inner.endswith(")"):
        return name
    inner = inner[:-1]
    keys = list(_ARG.finditer(inner))
    parts = []
    for k, m in enumerate(keys):
        key = m.group(1)
        text = inner[m.end():keys[k + 1].start() - 2 if k + 1 < len(keys) else len(inner)]
        parts.append("%s=%s" % (key, _short(values[key], width) if key in values else text))
    if not parts:
        return name
    label = "%s(%s)" % (head, ", ".join(parts))
    return label if len(label) <= most else label[:most - 2] + "…)"


class IncludeArgs:
    """The values an include's arguments had: what its ``arguments of …`` leaf wrote, i.e. the tree
    blackboard writes of the tick in which that leaf last succeeded (the name of an include says only
    ``search_room(room=$room)``; the values say which room it was). ``setters``: the id of each such
    leaf -> the id of its include (ids of the run stream, or behaviours).

    Writes and ticks come in order from a log or the run itself; over ROS topics a write may come
    after its tick (another topic): given the run times (``t``), a write older than the last tick
    goes to the include whose tick it belongs to."""

    def __init__(self, setters: Dict[Any, Any]):
        self.setters = setters
        self.values: Dict[Any, Dict[str, Any]] = {}
        self._window: Dict[str, Any] = {}
        self._span: Dict[Any, Tuple[float, float]] = {}  # include -> (previous tick's t, its tick's t)
        self._last: Optional[float] = None

    @staticmethod
    def of_nodes(nodes: Iterable[Dict[str, Any]]) -> IncludeArgs:
        """For the nodes of a ``tree`` record."""
        by_id = {n.get("id"): n for n in nodes if isinstance(n, dict)}
        return IncludeArgs({i: n.get("parent") for i, n in by_id.items() if n.get("kind") == "set"
                            and str(n.get("name", "")).startswith("arguments of ")
                            and by_id.get(n.get("parent"), {}).get("kind") == "include"})

    def write(self, key: str, value: Any, t: Optional[float] = None) -> None:
        if t is not None and self._last is not None and t < self._last:  # came after its tick
            for inc, (lo, hi) in self._span.items():
                if lo < t <= hi:
                    self.values.setdefault(inc, {})[key] = value
            return
        self._window[key] = value

    def tick(self, changes: Iterable[Any], t: Optional[float] = None) -> None:
        """A tick's changes (``[id, status, …]``; status a text or a py_trees Status)."""
        for change in changes:
            inc = self.setters.get(change[0])
            if inc is not None and str(getattr(change[1], "value", change[1])) == "SUCCESS":
                self.values[inc] = dict(self._window)
                if t is not None:
                    self._span[inc] = (self._last if self._last is not None else float("-inf"), t)
        self._window = {}
        if t is not None:
            self._last = t if self._last is None else max(self._last, t)

    def name(self, node_id: Any, name: str, width: int = 40) -> str:
        """``name`` (the include's) with its arguments' values, when known."""
        return include_label(name, self.values.get(node_id), width)


class NoticeLines(RunObserver):
    """Without the display (``-q``, ``run.launch``): the notices about the ROS graph (the master
    went away and came back, another run started) still reach the operator, on stderr."""

    def __init__(self, stream: TextIO = sys.stderr):
        self.stream = stream
        self._start = 0.0

    def on_start(self, tree: Any, root: Any, ctx: Any) -> None:
        self._start = ctx.clock.now()

    def on_notice(self, notice: Any, now: float) -> None:
        self.stream.write(terminal_text("[%7.3fs] NOTICE    %s" % (now - self._start, notice.text)) + "\n")
        self.stream.flush()


class Display(RunObserver):
    """Shows the tree with statuses: redrawn in place on a terminal, as changed lines otherwise."""

    def __init__(self, stream: TextIO = sys.stdout, tty: Optional[bool] = None, min_interval: float = 0.1):
        self.stream = stream
        self.tty = stream.isatty() if tty is None else tty
        self.min_interval = min_interval
        self.root: Optional[py_trees.behaviour.Behaviour] = None
        self._drawn: Optional[float] = None
        self._lines = 0
        self._start = 0.0
        self._note = ""  # the latest control answer or notice, under the tree on a terminal
        self._args = IncludeArgs({})  # the values of the includes' arguments (their names say them)

    def on_start(self, tree: Any, root: Any, ctx: Any) -> None:
        self.root = root
        self._start = ctx.clock.now()
        self._args = IncludeArgs(include_setters(root))

    def on_blackboard_write(self, key: str, value: Any, now: float) -> None:
        self._args.write(key, value)

    def on_tick(self, root: Any, changes: List[Change], now: float) -> None:
        self.root = root
        if self._args.setters:  # (a replay shows names it has made already)
            self._args.tick([(b, status) for b, _before, status in changes])
        now -= self._start          # shown as seconds since the start
        if self.tty:
            if self._drawn is None or now - self._drawn >= self.min_interval:
                self._draw(now)
            return
        for b, before, status in changes:
            if status != Status.INVALID:
                extra = " (%s)" % b.feedback_message if status == Status.FAILURE and b.feedback_message else ""
                self.stream.write(terminal_text("[%7.3fs] %-9s %s%s" % (now, status.value, self._label(b), extra)) + "\n")
            elif before == Status.RUNNING:
                self.stream.write(terminal_text("[%7.3fs] %-9s %s" % (now, halted_word(b), self._label(b))) + "\n")
        self.stream.flush()

    def _label(self, b: Any) -> str:
        """A behaviour's name; an include's with its arguments' values (``fetch_item(item="milk")``)."""
        return self._args.name(b, b.name) if self._args.values else b.name

    def on_control(self, record: Any, now: float) -> None:
        self._line(now, "CONTROL", control_line(record), "control: ")

    def on_notice(self, notice: Any, now: float) -> None:
        self._line(now, "NOTICE", notice.text)

    def _line(self, now: float, kind: str, text: str, label: str = "") -> None:
        """A line between the status changes; on a terminal the latest stays under the tree."""
        if self.tty:
            self._note = label + text
            if self.root is not None:
                self._draw(now - self._start)
            return
        self.stream.write(terminal_text("[%7.3fs] %-9s %s" % (now - self._start, kind, text)) + "\n")
        self.stream.flush()

    def on_end(self, result: Any) -> None:
        if self.tty and self.root is not None:
            self._draw(result.duration)

    def _draw(self, now: float) -> None:
        self._drawn = now
        text = tree_drawing(self.root, self._args.name)   # includes with their arguments' values
        if self._note:
            text += "\n" + terminal_text(self._note)
        if self._lines:
            self.stream.write("\x1b[%dA\x1b[J" % self._lines)
        self.stream.write(text + "\n")
        self._lines = text.count("\n") + 1
        self.stream.flush()


def include_setters(root: Any) -> Dict[Any, Any]:
    """The ``arguments of …`` leaf of each include under ``root`` -> the include (behaviours)."""
    out = {}
    for b in root.iterate():
        node = getattr(b.parent, "bmtree_node", None) if b.parent is not None else None
        if b.name.startswith("arguments of ") and getattr(node, "kind", None) == "include":
            out[b] = b.parent
    return out
