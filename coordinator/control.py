"""Steering a running tree (``bmtree run --control``): pause, resume, step, stop, breakpoints,
forced outcomes and tree-blackboard writes, over a request/reply topic pair.

Requests are JSON on ``/bmtree/run/control_request`` (``{"id", "command", ...}``); every
one gets a reply on ``/bmtree/run/control_reply`` (``{"id", "ok", "answer"}``) and is
written to the run stream's ``control`` channel (so to the run log) with who sent it.
ROS 1 has no authentication: anyone who reaches the master could steer, which is why
a run refuses every command unless it was started with ``--control``.

Commands are applied in the ticking thread, between ticks (:meth:`Controller.may_tick`):
while paused the runner does not tick, so no node starts, while messages are still
taken in (pending calls finish; their timeouts keep counting and are seen at the next tick).
An answer taken in while paused is told at once (``on_call_answer``: the run stream's
``call_answer``), so viewers do not show an answered call as running until the next tick.

``stop`` is another node's way to preempt the task (SMACH's ``request_preempt``): the runner takes
it (:meth:`Controller.take_stop`) and stops root as ``--max-duration`` does, so also while paused.

A node is named by its ``name`` or, when several share it, by ``NAME@ID`` (its id in the run
stream's ``nodes`` table): a command never applies to several nodes at once.

A request may name the run it is for (``to``: the run's ROS node, as ``bmtree watch`` sends
it): another run on the same master leaves it alone.
"""
from __future__ import annotations

import json
import logging
import os
import queue
import re
from typing import Any, Callable, Dict, List, Optional, Set, Tuple

from py_trees.common import Status

from comm.errors import ProtocolError, did_you_mean
from comm.messages import load_payload
from coordinator.context import WAKE
from coordinator.runevents import RunObserver, notify

log = logging.getLogger("bmtree.coordinator")

__all__ = ["Controller", "parse_command", "read_request", "Unreadable", "REQUEST", "REPLY", "COMMANDS", "MAX_REQUEST"]

REQUEST = "/bmtree/run/control_request"
REPLY = "/bmtree/run/control_reply"
COMMANDS = {"pause": [], "resume": [], "step": [], "stop": [], "break": ["node"], "clear": ["node"],
            "force": ["node", "outcome"], "set": ["key", "value"]}
MAX_REQUEST = 64 * 1024
MAX_STEERED = 100  # forced outcomes and writes a run keeps for its result (the run log has every command)


def parse_command(words: List[str]) -> Dict[str, Any]:
    """``["force", "go to the kitchen", "FAILURE"]`` -> a command; the last field takes the rest."""
    if not words or words[0] not in COMMANDS:
        raise ValueError("unknown command %r (one of: %s)" % (words[0] if words else "", ", ".join(COMMANDS)))
    fields = COMMANDS[words[0]]
    rest = words[1:]
    if fields == ["node", "outcome"] and len(rest) >= 2:
        return {"command": words[0], "node": " ".join(rest[:-1]), "outcome": rest[-1]}
    if fields == ["key", "value"] and len(rest) >= 2:
        return {"command": words[0], "key": rest[0], "value": " ".join(rest[1:])}
    if fields == ["node"] and rest:
        return {"command": words[0], "node": " ".join(rest)}
    if not fields and not rest:
        return {"command": words[0]}
    raise ValueError("usage: %s %s" % (words[0], " ".join(f.upper() for f in fields)))


def _same_type(old: Any, new: Any) -> bool:
    if old is None:
        return True
    if isinstance(old, bool) or isinstance(new, bool):
        return isinstance(old, bool) and isinstance(new, bool)
    if isinstance(old, float):
        return isinstance(new, (int, float))
    for kind in (int, str, list, dict):
        if isinstance(old, kind):
            return isinstance(new, kind)
    return type(old) is type(new)


class Controller(RunObserver):
    """Takes commands from any thread (:meth:`submit`), applies them between ticks.

    Args:
        enabled: False: every command is refused ("control is not enabled").
        reply: called with each reply dict (the ROS reply topic).
    """

    def __init__(self, enabled: bool, reply: Callable[[Dict[str, Any]], None] = lambda r: None):
        self.enabled = enabled
        self.reply = reply
        self._paused = False
        self._paused_at: Optional[float] = None  # when the pause began (the run's clock)
        self._pause_why = ""   # " by /node", " at the breakpoint before 'x'": said with its length
        self._step = False
        self._stepping = False
        self._queue: Any = queue.Queue()  # of command dicts
        self.ctx: Any = None
        self.root: Any = None
        self.breaks: Dict[Any, bool] = {}
        self.force: Dict[Any, Status] = {}
        self._forced_by: Dict[Any, str] = {}
        #: what control changed in the run, as it took effect: (clock time, text); the run's result says it
        self.steered: List[Tuple[float, str]] = []
        self._held: Dict[Any, bool] = {}
        self._wrapped: Dict[Any, bool] = {}
        self._flying: Dict[str, Any] = {}  # call_id -> CallRecord of the calls in flight
        self._told: Set[str] = set()  # answers told while paused
        self._stop = ""  # the reason of a stop accepted and not yet taken by the runner
        self._stopped = False  # a stop was accepted: a second one is refused

    # from any thread ----------------------------------------------------------------------
    def submit(self, command: Dict[str, Any]) -> None:
        self._queue.put(command)
        if self.ctx is not None:
            self.ctx.inbox.put(WAKE)

    # in the ticking thread ----------------------------------------------------------------
    def on_start(self, tree: Any, root: Any, ctx: Any) -> None:
        self.ctx, self.root = ctx, root

    def on_call_start(self, record: Any) -> None:
        if self.enabled and record.call_id:
            self._flying[record.call_id] = record

    def on_call_end(self, record: Any) -> None:
        self._flying.pop(record.call_id, None)
        self._told.discard(record.call_id)

    def take_stop(self) -> str:
        """The reason of a ``stop`` accepted since the last call (``stopped by control (/node)``), or '':
        the runner stops root with it (as ``--max-duration`` does), once."""
        why, self._stop = self._stop, ""
        return why

    def _steered(self, text: str, at: Optional[float] = None) -> None:
        if len(self.steered) < MAX_STEERED:
            now = self.ctx.clock.now() if self.ctx is not None else 0.0
            self.steered.append((now if at is None else at, text))
            self.steered.sort(key=lambda s: s[0])   # (a pause is said when it ends, at its start)

    @property
    def paused(self) -> bool:
        """No tick while true; each pause, once over, is among what control changed (its length matters:
        the calls' timeouts kept counting)."""
        return self._paused

    @paused.setter
    def paused(self, value: bool) -> None:
        now = self.ctx.clock.now() if self.ctx is not None else 0.0
        if value and not self._paused:
            self._paused_at = now
        elif not value and self._paused and self._paused_at is not None:
            self._steered("paused %.1f s%s" % (now - self._paused_at, self._pause_why), at=self._paused_at)
            self._paused_at, self._pause_why = None, ""
        self._paused = value

    def unpause(self, why: str) -> None:
        """A run stopped from outside (Ctrl-C) while paused: the pause ends (said to the viewers), or its
        cleanup would wait out its time limit without a tick."""
        if self.paused:
            self.paused = False
            self._answer({"command": "resume", "by": "bmtree"}, True, why)

    def may_tick(self) -> bool:
        """Apply the commands that came; True if the runner may tick now."""
        while True:
            try:
                cmd = self._queue.get_nowait()
            except queue.Empty:
                break
            self._answer_guarded(cmd)
        if not self.paused:
            return True
        self._stepping = self._step
        self._step = False
        if not self._stepping:
            self._tell_answers()
        return self._stepping

    def _answer_guarded(self, cmd: Any) -> None:
        """Apply and answer one command; a malformed one (not a mapping, a command that is not text, a value
        too deep or too large to read) is refused with why, and never stops the ticking thread."""
        if isinstance(cmd, Unreadable):
            self._answer(_plain(cmd), False, "malformed command: %s" % cmd.args[0])
            return
        if not isinstance(cmd, dict) or not isinstance(cmd.get("command"), str):
            what = type(cmd.get("command")).__name__ if isinstance(cmd, dict) else type(cmd).__name__
            self._answer(_plain(cmd), False, "malformed command: 'command' is text (one of: %s), got %s" % (
                ", ".join(COMMANDS), what))
            return
        try:
            ok, answer = self._apply(cmd)
        except (Exception, RecursionError) as exc:  # a bug or an odd value: refused, the run goes on
            log.warning("control command refused: %s: %s", type(exc).__name__, exc)
            self._answer(_plain(cmd), False, "malformed command: %s: %s" % (type(exc).__name__, str(exc)[:200]))
            return
        if ok and cmd.get("command") == "set":
            self._steered("blackboard %s%s" % (answer, _by(cmd.get("by"))))
        self._answer(cmd, ok, answer)

    def _tell_answers(self) -> None:
        """While paused: the calls answered since, which their leaves take only at the next tick."""
        if self.ctx is None:
            return
        for call_id, rec in list(self._flying.items()):
            if rec.answered is not None and rec.ended is None and call_id not in self._told:
                self._told.add(call_id)
                for o in list(self.ctx.observers):  # an observer of an older kind may lack the method
                    if hasattr(o, "on_call_answer"):
                        notify([o], "on_call_answer", rec)

    def _answer(self, cmd: Dict[str, Any], ok: bool, answer: str) -> None:
        args = {k: v for k, v in cmd.items() if k not in ("id", "command", "by", "to")}
        record = {"command": str(cmd.get("command")), "args": args, "ok": ok, "answer": answer,
                  "by": str(cmd.get("by") or "?"), "paused": self.paused}
        if self.ctx is not None:
            notify(self.ctx.observers, "on_control", record, self.ctx.clock.now())
        try:
            self.reply({"id": cmd.get("id"), "ok": ok, "answer": answer})
        except Exception:  # a reply that cannot be sent must not stop the run
            pass

    def _nodes(self, name: Any) -> Tuple[List[Any], str]:
        """The nodes ``name`` designates (all so named; ``NAME@ID``/``@ID``: the one of that id in the run
        stream's ``nodes`` table), or why none."""
        from coordinator.runstream import preorder

        every = preorder(self.root)
        named = [b for b in every if b.name == name]
        if named or not isinstance(name, str):
            return named, ""
        head, at, num = name.rpartition("@")
        if at and num.isdecimal() and num.isascii() and len(num) <= 9:
            if int(num) >= len(every):
                return [], "no node of id %s in this tree (its ids are 0 to %d)" % (num, len(every) - 1)
            b = every[int(num)]
            if head and b.name != head:
                ids = ["%s@%d" % (head, i) for i, o in enumerate(every) if o.name == head]
                return [], "node %s is %r, not %r%s" % (num, b.name, head, " (%s: %s)" % (
                    "the nodes so named are" if len(ids) > 1 else "the node so named is", ", ".join(ids)) if ids else "")
            return [b], ""
        return [], "no node named %r in this tree%s" % (name, did_you_mean(name, {b.name for b in every}))

    def _label(self, b: Any) -> str:
        """How answers name ``b``: its name, with ``@ID`` when another node has the same name."""
        from coordinator.runstream import preorder

        every = preorder(self.root)
        if sum(1 for o in every if o.name == b.name) == 1:
            return b.name
        return "%s@%d" % (b.name, next(i for i, o in enumerate(every) if o is b))

    def _ambiguous(self, nodes: List[Any], cmd: Dict[str, Any]) -> str:
        """Why a command on a name several steerable nodes share is refused: each with where it is (file:line,
        its parents) and how to pick one; a command applied to all of them would steer ones nobody meant."""
        from coordinator.runstream import preorder

        ids = {b: i for i, b in enumerate(preorder(self.root))}
        said = []
        for b in nodes:
            node = getattr(b, "bmtree_node", None) or getattr(b, "node", None)
            pos = getattr(node, "pos", None)
            where = "%s:%s, " % (os.path.basename(str(pos.file)), pos.line) if pos is not None else ""
            up, p = [], b.parent
            while p is not None:
                up.insert(0, p.name)
                p = p.parent
            path = " > ".join(up if len(up) <= 3 else ["…"] + up[-3:])
            said.append("%s@%d (%s%s)" % (b.name, ids[b], where, "in %s" % path if path else "the top"))
        pick = "%s %s@%d%s" % (cmd.get("command"), nodes[0].name, ids[nodes[0]],
                               " %s" % cmd.get("outcome") if cmd.get("command") == "force" else "")
        return ("%d nodes are named %r: %s; say which one by its id (%s), or give them names of their own "
                "(name: in the tree)" % (len(nodes), cmd.get("node"), ", ".join(said), pick))

    def _stop_run(self, by: str) -> Tuple[bool, str]:
        """Accept a stop (the runner takes it at once) or say why not: a second stop, or one while a cleanup
        runs, is refused rather than cutting the cleanup short (it is what leaves the robot safe, it is bounded
        by its cleanup_timeout, and a preempt sent twice must not escalate; Ctrl-C in the run's terminal does)."""
        task = self._task()
        if task is not None and task.phase not in ("root", "between"):
            left = max(0.0, (task.cleanup_started or 0.0) + task.limit - self.ctx.clock.now())
            how = ("root was stopped already (%s)" % task.ended_reason.split(" while ", 1)[0] if task.ended == "stopped"
                   else "root has ended (%s)" % task.ended)
            return False, ("%s and its cleanup is running: a stop does not cut the cleanup short (it ends within %.3g s, "
                           "its cleanup_timeout; Ctrl-C in the run's terminal ends it at once)" % (how, left))
        if self._stopped:
            return False, "the run is stopping already"
        self._stopped = True
        self._stop = "stopped by control%s" % (" (%s)" % by if by and by != "?" else "")
        was, self.paused = self.paused, False  # paused, its cleanup would never be ticked
        said = ("stopping: root is halted and its calls cancelled, then the cleanup runs (at most %g s)" % task.limit
                if task is not None else "stopping: the running nodes are halted and their calls cancelled")
        return True, said + ("; the pause ends" if was else "")

    def _apply(self, cmd: Dict[str, Any]) -> Tuple[bool, str]:
        what = cmd.get("command")
        if not self.enabled:
            return False, "control is not enabled for this run (start it with 'bmtree run --control')"
        if what not in COMMANDS:
            return False, "unknown command %r (one of: %s)" % (what, ", ".join(COMMANDS))
        if self.root is None:
            return False, "the run has not started yet"
        if what == "pause":
            if not self.paused:
                self._pause_why = _by(cmd.get("by"))
            self.paused = True
            return True, "paused: no node starts; pending calls go on and their timeouts keep counting"
        if what == "resume":
            self.paused = False
            return True, "resumed"
        if what == "step":
            if not self.paused:
                return False, "step works while paused (pause first)"
            self._step = True
            return True, "one tick"
        if what == "stop":
            return self._stop_run(str(cmd.get("by") or ""))
        if what == "set":
            return self._set(cmd.get("key"), cmd.get("value"))
        nodes, missing = self._nodes(cmd.get("node"))
        if not nodes:
            return False, missing
        if what == "clear":  # harmless on each node so named
            had = [b for b in nodes if self.breaks.pop(b, None) is not None]
            return True, ("breakpoint on %r cleared" if had else "no breakpoint on %r (none was set)") % cmd.get("node")
        nodes, refused = self._still_ticked(nodes, cmd.get("node"))
        if refused:
            return False, refused
        if len(nodes) > 1:
            return False, self._ambiguous(nodes, cmd)
        b = nodes[0]
        if what == "break":
            self._wrap(b)
            self.breaks[b] = True
            return True, "will pause before %r starts" % self._label(b)
        outcome = str(cmd.get("outcome", "")).upper()
        if outcome not in ("SUCCESS", "FAILURE"):
            return False, "an outcome is SUCCESS or FAILURE, not %r" % cmd.get("outcome")
        self._wrap(b)
        self.force[b] = Status(outcome)
        self._forced_by[b] = _by(cmd.get("by"))
        return True, "%r will end in %s the next time it is ticked" % (self._label(b), outcome)

    def _task(self) -> Any:
        """The tree's top when it has a ``cleanup:`` (a WithCleanup: root, then the cleanup), else None."""
        from coordinator.nodes.task import WithCleanup

        return self.root if isinstance(self.root, WithCleanup) else None

    def _still_ticked(self, nodes: List[Any], name: Any) -> Tuple[List[Any], str]:
        """The nodes of ``nodes`` a command may steer, or why a command on ``name`` is refused: never the
        top of a tree with a cleanup (forcing it would skip the cleanup), and once root has ended (its
        cleanup runs) only the cleanup's nodes, the only ones ticked again."""
        from coordinator.runstream import preorder

        task = self._task()
        if task is not None and any(b is task for b in nodes):
            nodes = [b for b in nodes if b is not task]   # a node of root may have the tree's name too
            if not nodes:
                return [], ("%r is the tree's top (root, then the cleanup): it ends after its cleanup, whatever "
                            "happens; steer root's top node %r (the cleanup still runs) or a node of the cleanup "
                            "instead" % (name, task.root.name))
        if task is None or task.phase == "root":
            return nodes, ""
        cleanup = list(preorder(task.cleanup))
        live = [b for b in nodes if any(b is c for c in cleanup)]
        if live:
            return live, ""
        names = list(dict.fromkeys(b.name for b in cleanup))
        return [], ("root has ended and the cleanup is running: %r is not a node of the cleanup, so it will "
                    "not be ticked again; steer a node of the cleanup instead (%s)" % (name, ", ".join(names)))

    def _set(self, key: Any, text: Any) -> Tuple[bool, str]:
        from coordinator.nodes.task import CLEANUP_KEYS

        if key in CLEANUP_KEYS and self._task() is not None:
            return False, ("%r is read-only: bmtree sets 'ended' and 'ended_reason' when root ends, to tell the "
                           "cleanup how it ended; set another key" % key)
        bb = self.ctx.blackboard
        if not isinstance(key, str) or key not in bb:
            return False, "no tree-blackboard key %r%s (the keys are: %s)" % (
                key, did_you_mean(key, bb), ", ".join(sorted(bb)) or "none")
        if not isinstance(text, str):
            return False, "the value is YAML text (as 'bmtree control set KEY VALUE' sends it), got %s" % (
                type(text).__name__)
        from coordinator.errors import TreeErrors
        from coordinator.yamlsrc import load_value

        try:   # the tree files' reader and limits (size, depth, aliases): a value from the network
            value = load_value(text, "the value")
        except TreeErrors as exc:
            return False, "the value is not YAML bmtree reads: %s" % str(exc).splitlines()[0]
        old = bb[key]
        import genpy

        if isinstance(old, genpy.Message):  # a call's output
            from comm.errors import ProtocolError
            from comm.rostypes import from_message, rostype_of, to_message
            from comm.typewords import ValueMisfit

            rostype = rostype_of(old)
            try:  # as a call input takes it: the message's fields, or its one field's value
                value = to_message(rostype, value, allow_scalar=True)
            except ValueMisfit as exc:  # in the words the checker uses for a call's input
                return False, "%s %s" % (key, exc.said)
            except ProtocolError as exc:
                return False, "%s holds a %s; %s" % (key, rostype, exc)
            self.ctx.write(key, value)
            return True, "%s = %s" % (key, json.dumps(from_message(value), ensure_ascii=False, default=str))
        if not _same_type(old, value):
            return False, "%s holds %s; %r is %s" % (key, type(old).__name__, value, type(value).__name__)
        self.ctx.write(key, value)
        return True, "%s = %s" % (key, json.dumps(value, ensure_ascii=False, default=str))

    def _wrap(self, b: Any) -> None:
        """Replace ``b.tick`` (an instance attribute over py_trees' method) to honour breaks and forces."""
        if b in self._wrapped:
            return
        self._wrapped[b] = True
        original = b.tick

        def tick() -> Any:
            if self._held.get(b) and b.status != Status.RUNNING:
                self._held[b] = False  # halted while held: it never started
            if b in self.force:
                outcome = self.force.pop(b)
                if b.status == Status.RUNNING and not self._held.get(b):
                    b.stop(Status.INVALID)  # halts what it runs (calls are cancelled)
                self._held[b] = False
                b.status = outcome
                b.feedback_message = "forced to %s by control" % outcome.value
                self._steered("%r forced to %s%s" % (self._label(b), outcome.value, self._forced_by.pop(b, "")))
                yield b
                return
            if self._held.get(b):
                if self.paused and not self._stepping:
                    yield b
                    return
                self._held[b] = False
                b.status = Status.INVALID  # so the real tick starts it
            elif self.breaks.get(b) and b.status != Status.RUNNING:
                self._held[b] = True
                label = self._label(b)
                if not self.paused:
                    self._pause_why = " at the breakpoint before %r" % label
                self.paused = True
                self._answer({"command": "breakpoint", "node": label, "by": "bmtree"}, True,
                             "paused before %r starts" % label)
                b.status = Status.RUNNING  # held: the parent waits for it
                yield b
                return
            yield from original()

        b.tick = tick


class Unreadable(ValueError):
    """A request that cannot be read (not a JSON object, too large, nested too deep): refused as every
    malformed command is (:meth:`Controller._answer_guarded`). Its args: why, who sent it, and its ``id``
    and ``to`` as read from the text if they can be (None otherwise)."""


def read_request(text: Any, max_bytes: int = MAX_REQUEST, by: str = "?") -> Any:
    """The command of a request's JSON text, or an :class:`Unreadable` saying why there is none; never raises."""
    try:
        return load_payload(text, max_bytes)  # size, then depth, before the parser (it recurses)
    except ProtocolError as exc:
        return Unreadable("the request cannot be read: %s" % str(exc)[:200], by, _said(text, "id", max_bytes),
                          _said(text, "to", max_bytes))


def _said(text: Any, key: str, max_bytes: int) -> Any:
    """The text value of ``key`` in a request that cannot be parsed, if it can be read from its text."""
    found = re.search(r'"%s"\s*:\s*"([^"\\]{1,200})"' % key, text[:max_bytes]) if isinstance(text, str) else None
    return found.group(1) if found else None


def _plain(cmd: Any) -> Dict[str, Any]:
    """What a refused malformed command's record keeps: its id, command and sender as short text."""
    if isinstance(cmd, Unreadable):
        return {"id": cmd.args[2], "command": "?", "by": cmd.args[1]}
    if not isinstance(cmd, dict):
        return {"command": "?"}
    return {k: str(cmd[k])[:80] for k in ("id", "command", "by", "to") if k in cmd}



def _by(who: Any) -> str:
    """`` by /bmtree_ctl_1`` (who sent a command), or '' when it does not say."""
    return " by %s" % who if who and who != "?" else ""
