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

import logging
from dataclasses import dataclass
from typing import Any, Dict, Iterable, List, Tuple

from py_trees.common import Status

__all__ = ["RunObserver", "StatusWatcher", "Change", "Notice", "notify", "control_line"]

log = logging.getLogger("bmtree.coordinator")

Change = Tuple[Any, Status, Status]  # (behaviour, old status, new status)


@dataclass
class Notice:
    """Something that happened to the ROS graph under the run, which explains what follows
    (the master went away, came back), delivered by the transport like a result; or an answer
    that came after its call had ended (``late_answer``, made by the run context: the module ran a
    call the run had given up on, and a ``retry`` may have sent it again)."""

    # master_down, master_back, other_run, blackboard_down, blackboard_back, late_answer; cleanup (a run
    # stopped from outside runs its tree's cleanup), cleanup_failed (the cleanup failed or was cut short)
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
