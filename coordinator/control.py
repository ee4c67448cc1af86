"""Steering a running tree (``bmtree run --control``): pause, resume, step, breakpoints,
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

A request may name the run it is for (``to``: the run's ROS node, as ``bmtree watch`` sends
it): another run on the same master leaves it alone.
"""
from __future__ import annotations

import itertools
import json
import queue
import threading
import time
from typing import Any, Callable, Dict, List, Set, Tuple

import yaml
from py_trees.common import Status

from comm import settle_new_connection
from comm.errors import did_you_mean
from comm.nodelife import registering
from coordinator.context import WAKE
from coordinator.runevents import RunObserver, notify

__all__ = ["Controller", "ControlClient", "ros_controller", "parse_command", "REQUEST", "REPLY", "COMMANDS"]

REQUEST = "/bmtree/run/control_request"
REPLY = "/bmtree/run/control_reply"
COMMANDS = {"pause": [], "resume": [], "step": [], "break": ["node"], "clear": ["node"],
            "force": ["node", "outcome"], "set": ["key", "value"]}
MAX_REQUEST = 64 * 1024


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
        self.paused = False
        self._step = False
        self._stepping = False
        self._queue: Any = queue.Queue()  # of command dicts
        self.ctx: Any = None
        self.root: Any = None
        self.breaks: Dict[Any, bool] = {}
        self.force: Dict[Any, Status] = {}
        self._held: Dict[Any, bool] = {}
        self._wrapped: Dict[Any, bool] = {}
        self._flying: Dict[str, Any] = {}  # call_id -> CallRecord of the calls in flight
        self._told: Set[str] = set()  # answers told while paused

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

    def may_tick(self) -> bool:
        """Apply the commands that came; True if the runner may tick now."""
        while True:
            try:
                cmd = self._queue.get_nowait()
            except queue.Empty:
                break
            self._answer(cmd, *self._apply(cmd))
        if not self.paused:
            return True
        self._stepping = self._step
        self._step = False
        if not self._stepping:
            self._tell_answers()
        return self._stepping

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

    def _nodes(self, name: Any) -> List[Any]:
        from coordinator.runstream import preorder

        return [b for b in preorder(self.root) if b.name == name] if self.root is not None else []

    def _apply(self, cmd: Dict[str, Any]) -> Tuple[bool, str]:
        what = cmd.get("command")
        if not self.enabled:
            return False, "control is not enabled for this run (start it with 'bmtree run --control')"
        if what not in COMMANDS:
            return False, "unknown command %r (one of: %s)" % (what, ", ".join(COMMANDS))
        if self.root is None:
            return False, "the run has not started yet"
        if what == "pause":
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
        if what == "set":
            return self._set(cmd.get("key"), cmd.get("value"))
        nodes = self._nodes(cmd.get("node"))
        if not nodes:
            from coordinator.runstream import preorder

            names = {b.name for b in preorder(self.root)}
            return False, "no node named %r in this tree%s" % (cmd.get("node"), did_you_mean(cmd.get("node"), names))
        if what != "clear":
            nodes, refused = self._still_ticked(nodes, cmd.get("node"))
            if refused:
                return False, refused
        if what == "break":
            for b in nodes:
                self._wrap(b)
                self.breaks[b] = True
            return True, "will pause before %r starts" % cmd.get("node")
        if what == "clear":
            for b in nodes:
                self.breaks.pop(b, None)
            return True, "no breakpoint on %r" % cmd.get("node")
        outcome = str(cmd.get("outcome", "")).upper()
        if outcome not in ("SUCCESS", "FAILURE"):
            return False, "an outcome is SUCCESS or FAILURE, not %r" % cmd.get("outcome")
        for b in nodes:
            self._wrap(b)
            self.force[b] = Status(outcome)
        return True, "%r will end in %s the next time it is ticked" % (cmd.get("node"), outcome)

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
        try:
            value = yaml.safe_load(text) if isinstance(text, str) else text
        except yaml.YAMLError as exc:
            return False, "the value is not YAML: %s" % str(exc).splitlines()[0]
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
                self.paused = True
                self._answer({"command": "breakpoint", "node": b.name, "by": "bmtree"}, True,
                             "paused before %r starts" % b.name)
                b.status = Status.RUNNING  # held: the parent waits for it
                yield b
                return
            yield from original()

        b.tick = tick


class ControlClient:
    """Sends commands to the run on this master and waits for each reply (watch keys, web buttons, CLI)."""

    _ids = itertools.count(1)

    def __init__(self, request: str = REQUEST, reply: str = REPLY):
        import rospy
        from std_msgs.msg import String

        self._String = String
        self._replies: Dict[Any, Dict[str, Any]] = {}
        self._cond = threading.Condition()
        self._sub = rospy.Subscriber(reply, String, self._got, queue_size=100)
        self._pub = rospy.Publisher(request, String, queue_size=100)
        self._prefix = "%s-%d" % (rospy.get_name(), int(time.time() * 1000) % 100000)

    def _got(self, msg: Any) -> None:
        try:
            rep = json.loads(msg.data)
            key = rep.get("id")
        except (ValueError, AttributeError):
            return
        with self._cond:
            self._replies[key] = rep
            self._cond.notify_all()

    def send(self, command: Dict[str, Any], timeout: float = 10.0) -> Dict[str, Any]:
        """The run's reply, or ``{"ok": False, "answer": ...}`` if no run answers within ``timeout``."""
        end = time.monotonic() + timeout
        waited = False
        while (self._pub.get_num_connections() < 1 or self._sub.get_num_connections() < 1) and \
                time.monotonic() < end:
            waited = True
            time.sleep(0.05)  # a message sent before the connection is up is lost
        if waited:
            settle_new_connection()  # the run's reply publisher, which this side counted first
        cid = "%s-%d" % (self._prefix, next(self._ids))
        self._pub.publish(self._String(json.dumps(dict(command, id=cid))))
        with self._cond:
            while cid not in self._replies:
                left = end - time.monotonic()
                if left <= 0:
                    return {"ok": False, "answer": "no run answered on %s within %gs" % (REQUEST, timeout)}
                self._cond.wait(left)
            return self._replies.pop(cid)

    def close(self) -> None:
        self._sub.unregister()
        self._pub.unregister()


def ros_controller(enabled: bool, max_bytes: int = MAX_REQUEST) -> Controller:
    """A Controller fed by the request topic and answering on the reply topic (also when not
    enabled: then it refuses, so a user is told why nothing happens)."""
    import rospy
    from std_msgs.msg import String

    with registering():
        pub = rospy.Publisher(REPLY, String, queue_size=100)
    ctl = Controller(enabled, reply=lambda r: pub.publish(String(json.dumps(r, default=str))))

    def got(msg: Any) -> None:
        try:
            if len(msg.data) > max_bytes:
                raise ValueError("larger than %d bytes" % max_bytes)
            cmd = json.loads(msg.data)
            if not isinstance(cmd, dict):
                raise ValueError("not a JSON object")
        except (ValueError, TypeError, AttributeError) as exc:
            pub.publish(String(json.dumps({"id": None, "ok": False, "answer": "bad request: %s" % exc})))
            return
        if cmd.get("to") not in (None, "", rospy.get_name()):
            return  # for another run on this master (bmtree watch names the run it shows)
        header = getattr(msg, "_connection_header", None) or {}
        cmd["by"] = str(header.get("callerid", "?"))
        ctl.submit(cmd)

    with registering():
        ctl.subscription = rospy.Subscriber(REQUEST, String, got, queue_size=100)
    return ctl
