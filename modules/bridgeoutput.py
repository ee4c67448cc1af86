"""The C++ node's answers to the bridge: ``BM_output`` and the output values, matched to the call;
and its events (``BM_event``), checked and passed on as bmtree events.

The C++ node publishes a call's output values on the data topics, then ``BM_output`` naming them by
topic and occurrence; values of another call (one that timed out, or a previous bridge's) are told
apart and skipped. An event comes whole on a topic of its own, so it is never taken for an output.
Kept apart from sending calls and their timeouts (:mod:`modules.bridge`).
"""
from __future__ import annotations

import json
import logging
import time
from typing import Any, Dict, List, Optional

from comm.errors import ProtocolError
from comm.messages import load_payload
from modules.cppinfo import cpp_event, data_topic
from modules.definition import FunctionDefinition
from modules.runtime import Failure, Rejected

__all__ = ["CppCall", "CppOutputs"]

log = logging.getLogger("bmtree.bridge")

#: a refused event's warning is repeated at most this often (s): a timer that emits a wrong event
#: ten times a second must not flood the log


class CppCall:
    """What the bridge collects for the call the C++ node is running."""

    def __init__(self, fn: FunctionDefinition, topics: List[str]):
        self.fn = fn
        self.fresh: Dict[str, List[Any]] = {t: [] for t in topics}
        self.output: Optional[Dict[str, Any]] = None
        self.output_at = 0.0
        self.call_id = ""  # in BM_input and BM_cancel, for a node built with bmtree's library
        self.skip: Dict[str, int] = {}  # values still to come on a topic that belong to another call
        self.cancel_sent = False


class CppOutputs:
    """The answer side of :class:`modules.bridge.CppBridge` (a base class of it, on its state): the
    C++ node's data and ``BM_output`` messages taken for the call outstanding (``_call``) or the one
    owed (``_owed``), and the outputs read from them."""

    def _on_data(self, msg: Any, topic: str) -> None:
        if msg._connection_header.get("callerid") != self.cpp_node:
            return  # our own input, or another node's: never an output of the C++ node
        with self._cond:
            call = self._call
            if call is not None and topic in call.fresh:
                if call.skip.get(topic):
                    call.skip[topic] -= 1
                    return
                call.fresh[topic].append(msg)
                if call.output is not None:  # before BM_output nobody waits for data: no wake-up
                    self._cond.notify_all()

    def _on_output(self, msg: Any) -> None:
        if msg._connection_header.get("callerid") != self.cpp_node:
            return
        try:
            out = load_payload(msg.data, self.max_bytes)
        except ProtocolError as exc:
            out = {"status": "failed", "error": "malformed BM_output from %s: %s" % (self.cpp_node, exc)}
        with self._cond:
            call = self._call
            answers = out.get("call_id")
            if isinstance(answers, str) and (call is None or answers != call.call_id) and (
                    self._owed is None or answers != self._owed_id):
                # a library node names the call it answers: this one is not ours (it began before
                # this bridge started: the previous bridge's, killed during it)
                log.warning("ignored a BM_output from %s for call %s, which this bridge did not send (a call of "
                            "a previous bridge?)", self.cpp_node, answers)
                topics = out.get("outparam_topics")
                if call is not None and isinstance(topics, list):  # its values came (or come) first on each topic
                    for t in topics:
                        if isinstance(t, str) and t in call.fresh:
                            if call.fresh[t]:
                                call.fresh[t].pop(0)
                            else:
                                call.skip[t] = call.skip.get(t, 0) + 1
                return
            if call is None and self._owed is not None and not self._owed[2]:
                log.info("the C++ node %s answered %s after the call had timed out; it takes calls again",
                         self.cpp_node, self._owed[0])
                self._owed = (self._owed[0], self._owed[1], time.monotonic())
                return
            if call is None or call.output is not None:
                log.warning("ignored a BM_output from %s with no call outstanding", self.cpp_node)
                return
            call.output = out
            call.output_at = time.monotonic()
            self._cond.notify_all()

    def _on_event(self, msg: Any) -> None:
        """An event of the C++ node (``BM_event``, rospy's thread): checked against the definition and
        published as a bmtree event; a bad one, or one from another node, is logged (naming the node
        that sent it) and dropped. Never raises."""
        sender = str(msg._connection_header.get("callerid"))
        try:
            if not self.cpp_node:
                log.debug("ignored a BM_event from %s before the C++ node was found", sender)
                return
            try:
                event, params = cpp_event(load_payload(msg.data, self.max_bytes), self.definition)
                if sender != self.cpp_node:
                    self._refused_event(sender, "events are taken from the C++ node only")
                    return
                self._server.emit(event, params)
            except ProtocolError as exc:
                self._refused_event(sender, str(exc))
        except Exception as exc:  # a bug here must not end rospy's thread of the topic
            log.error("could not pass on an event of %s (%s: %s)", sender, type(exc).__name__, exc)

    def _refused_event(self, sender: str, why: str) -> None:
        """Say that an event was dropped; the same reason at most every 10 s (:class:`comm.saylimit.SayLimit`)."""
        more = self._event_warnings.due((sender, why))
        if more is None:
            return
        module = self.definition.name
        if sender == self.cpp_node:
            who = "the C++ node %s of module %r" % (sender, module)
        else:
            who = "%s on /%s/BM_event, which is not the C++ node of module %r (%s)" % (
                sender, module, module, self.cpp_node)
        log.warning("dropped an event from %s: %s%s", who, why, more)

    def _lacking(self, call: CppCall) -> List[str]:
        """Output values listed in BM_output that have not arrived yet, in words."""
        topics = call.output.get("outparam_topics") if call.output else None
        if not isinstance(topics, list):
            return []
        out = []
        for topic in sorted(set(t for t in topics if isinstance(t, str))):
            want = topics.count(topic)
            got = len(call.fresh.get(topic, []))
            if topic in call.fresh and got < want:
                out.append("%d of %d values arrived on %s" % (got, want, topic))
        return out

    def _outputs(self, call: CppCall) -> Dict[str, Any]:
        """The function's outputs by name; Failure/Rejected for an error or a malformed BM_output."""
        out = call.output or {}
        status, error = out.get("status"), out.get("error")
        # the status decides, not the error's text: a C++ function that throws bmtree::Failure("") sends
        # "failed" with an empty error, which was taken for a success (or for outputs that are missing)
        if status not in (None, "succeeded", "failed", "rejected", "cancelled"):
            raise Failure("malformed BM_output from %s: unknown status %s (expected succeeded, failed, rejected or "
                          "cancelled)" % (self.cpp_node, json.dumps(status)[:80]))
        if error or status in ("failed", "rejected", "cancelled"):
            text = str(error) if error else "the C++ node %s gave no message (its BM_output says %s with an empty " \
                "error)" % (self.cpp_node, status)
            if status == "rejected":
                raise Rejected(text)
            raise Failure(text)
        names = out.get("outparam_names")
        topics = out.get("outparam_topics")
        if not (isinstance(names, list) and isinstance(topics, list) and len(names) == len(topics)
                and all(isinstance(x, str) for x in names + topics)):
            raise Failure("malformed BM_output from %s: expected lists of strings 'outparam_names' and "
                          "'outparam_topics' of equal length, got %s" % (self.cpp_node, json.dumps(out)[:200]))
        module = self.definition.name
        wanted = {p.name: data_topic(module, p.rostype) for p in call.fn.outputs}
        values: Dict[str, Any] = {}
        problems = []
        seen: Dict[str, int] = {}
        for name, topic in zip(names, topics):
            k = seen.get(topic, 0)
            seen[topic] = k + 1
            if name not in wanted:
                problems.append("unknown output %r" % name)
            elif topic != wanted[name]:
                problems.append("output %r came on %s, its type's topic is %s" % (name, topic, wanted[name]))
            elif k < len(call.fresh.get(topic, [])):
                values[name] = call.fresh[topic][k]
        missing = [n for n in wanted if n not in names]
        if missing:
            problems.append("missing output %s" % ", ".join(repr(m) for m in missing))
        if problems:
            raise Failure("%s: the C++ node's BM_output does not match the definition: %s" % (
                call.fn.qualified, "; ".join(problems)))
        return values

