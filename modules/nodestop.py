"""A module's node that stops (Ctrl-C, SIGTERM, ``rosnode kill``, roslaunch) with calls in flight.

Without this, the process ended under its functions: ``self.context.sleep`` never returned, the code
after it ("stop the motors") never ran, and the coordinator heard nothing (its run said ``module_lost``
later). Here the node's stop cancels each call as a coordinator's cancel does (``context.cancelled``
set, ``context.sleep`` returns False, ``on_cancel`` callbacks run: the bridge passes the cancel to its
C++ node), waits up to the cancel grace for the code to return, and answers every call ``cancelled``
saying why (``the module's node /bm_arm is stopping (SIGINT); its code returned after the cancel``, or
``…, but its code has not returned 1s after the cancel: the node stops without it, …``), one log line
each; a call that comes meanwhile is refused. It runs as rospy's first pre-shutdown hook: after the
``rospy.on_shutdown`` hooks (an :class:`~modules.actions.Action` cancels its goals there, and answers
its own calls), before rospy closes the node's topics, so the answers reach the coordinator. The
author's ``shutdown()`` runs afterwards, as before.
"""
from __future__ import annotations

import logging
import re
import signal
import time
from typing import Any, List

from comm.messages import CallStatus
from modules.answers import stopped_text
from modules.errortext import which_call

__all__ = ["stop_calls", "stop_cause", "stop_with_node"]

log = logging.getLogger("bmtree.module")


def stop_calls(server: Any, why: str, grace: float) -> List[str]:
    """Cancel every call in flight of ``server`` (a :class:`~modules.runtime.ModuleServer`) because its node
    stops, and answer each within ``grace`` seconds (a little more to hand the answers over); calls that come
    from now on are refused. Returns the lines logged, one per call."""
    end = time.monotonic() + max(0.0, grace)
    with server._lock:
        server.stopping = why
        calls = list(server._calls.values())
        for c in (server._exclusive, server._waiting):  # a call without an id is not in _calls
            if c is not None and c not in calls:
                calls.append(c)
        queued, server._waiting = server._waiting, None
        if queued is not None:  # waits for a cancelled holder: its code never started
            queued.running = False
    owed, lines = [], []
    for call in calls:
        with server._lock:
            if call.answered:  # its cancel's grace was over already: it was answered then
                continue
            ours = not call.ctx.cancelled.is_set()
            if ours:
                call.stopping = why
        if ours and call.ctx.cancel():
            call.cancelled_at = server.scheduler.now()
        with server._lock:
            running = call.running
        if running:
            owed.append(call)
        else:  # never started, or waiting on an outcome's delay: nothing to stop
            server._finish(call, server.answers.result(call, CallStatus.CANCELLED, stopped_text(why)))
            lines.append(_said(log.info, "cancelled %s of %s: %s", which_call(call.ctx.call_id), call.fn.qualified,
                               why))
    if owed:
        server.answers_sent(owed, max(0.0, end - time.monotonic()))
    for call in owed:
        with server._lock:
            late = not call.answered
        if late:
            lines.append(_said(log.warning, "cancelled %s of %s: %s, but its code has not returned %gs after the "
                               "cancel; the node stops without it (what it drives may not have stopped)",
                               which_call(call.ctx.call_id), call.fn.qualified, why, grace))
            server._finish(call, server.answers.result(call, CallStatus.CANCELLED, stopped_text(why, grace)))
        elif call.stopping:
            lines.append(_said(log.info, "cancelled %s of %s: %s; its code returned", which_call(call.ctx.call_id),
                               call.fn.qualified, why))
    return lines


def _said(say: Any, text: str, *args: Any) -> str:
    say(text, *args)
    return text % args


def stop_cause(reason: str) -> str:
    """What rospy's shutdown ``reason`` means to a user: ``SIGINT`` for ``signal-2`` (the node's own stop),
    ``a shutdown request from /rosnode_…: user request`` (``rosnode kill``), the master's when another node
    took the name."""
    m = re.match(r"signal-(\d+)$", reason or "")
    if m:
        try:
            return signal.Signals(int(m.group(1))).name
        except ValueError:
            return "signal %s" % m.group(1)
    m = re.match(r"external shutdown request from \[(.*?)\]: \[?(.*?)\]?$", reason or "", re.S)
    if m:
        return "a shutdown request from %s%s" % (m.group(1), ": " + m.group(2) if m.group(2) else "")
    if "new node registered with same name" in (reason or ""):
        return "another node registered with its name"
    return reason or "stopped"


def stop_with_node(server: Any) -> None:
    """Stop ``server``'s calls when its ROS node shuts down, before the node's topics close (call after
    ``rospy.init_node``; the hook runs in the thread that shuts rospy down)."""
    import rospy

    from comm.nodelife import before_topics_close

    def hook(reason: str) -> None:
        try:
            server.stop("the module's node %s is stopping (%s)" % (rospy.get_name(), stop_cause(reason)))
        except Exception:  # the node must stop whatever happens here
            log.exception("stopping the calls in flight")

    before_topics_close(hook)
