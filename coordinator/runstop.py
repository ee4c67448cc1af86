"""How ``bmtree run`` says it was stopped from outside: Ctrl-C, or a shutdown request of its node
(``rosnode kill``, a node of the same name), which stops it as Ctrl-C does."""
from __future__ import annotations

import time
from typing import Any, Dict, List, Sequence

from coordinator.cliutil import err

__all__ = ["RequestNotice", "interrupted_line", "shutdown_notice"]

NOTICE_FIRST = 1.0  # s a shutdown request waits for its notice to be in the run before it stops it


def interrupted_line(result: Any, started: bool, request: str = "", running: Sequence[Any] = ()) -> str:
    """What ``bmtree run`` says when a stop signal ended it (``started``: the tree was ticking; ``result``:
    the run's, None if it had none; ``request``: rospy's reason when a shutdown request of the run's node
    stopped it, not Ctrl-C; ``running``: the calls that may still run on their module, their cancel not
    confirmed): what happened to the calls, then how the cleanup, if any, went."""
    by = " by a shutdown request of its node (%s)" % request if request else ""
    if not started:
        return "interrupted during start-up%s: nothing was called" % by
    mine = {id(c) for c in getattr(result, "cleanup_calls", None) or []}
    sent = result is not None and any(id(c) not in mine for c in result.calls)
    line = ("interrupted%s: running calls were cancelled" % by if sent
            else "interrupted%s before any call was sent" % by)
    if running:   # why, as each call's summary row says it (no answer to its cancel, or code still running)
        why: Dict[str, List[str]] = {}
        for c in running:
            targets = why.setdefault(str(c.maybe_running or "its module did not confirm the cancel"), [])
            if str(c.target) not in targets:
                targets.append(str(c.target))
        line += " (but %s)" % "; ".join("%s may still be running: %s" % (", ".join(sorted(t)), w)
                                        for w, t in why.items())
    status = getattr(result, "cleanup_status", None)
    if status is None:
        return line + (", and the cleanup did not run" if getattr(result, "ended", "") else "")
    why = result.cleanup_reason or "no reason given"
    if status.value == "SUCCESS":
        return line + ", then the cleanup ran"
    if status.value == "INVALID" or why.startswith("interrupted"):
        where = why.partition(" while ")[2]
        return line + ", then the cleanup was cut short by %s" % ("Ctrl-C" if request else "a second Ctrl-C") + (
            " while %s" % where if where else "")
    if why.startswith("did not end within"):
        return line + ", then the cleanup was cut short: %s" % why
    return line + ", then the cleanup failed: %s" % why


def shutdown_notice(node: str, reason: str) -> str:
    """What a run says when its node is asked to shut down (rospy's ``reason``): that it stops as on
    Ctrl-C, and who asked, since nobody at its terminal did."""
    if "new node registered with same name" in reason:
        who = "another node registered with this run's node name %s, so the ROS master shut it down" % node
    elif reason.startswith("external shutdown request"):
        who = "this run's node %s was asked to shut down (rosnode kill?)" % node
    else:
        who = "rospy shuts this run's node %s down" % node
    return "%s: %s; stopping the run as Ctrl-C does" % (who, reason)


class RequestNotice:
    """Tells a shutdown request (called in rospy's XML-RPC thread, before the run is stopped): a
    notice in the run once it ticks (display, run log and stream), handed to the ticking thread
    and waited for (bounded) so that it comes before the stop's own; on stderr otherwise."""

    def __init__(self) -> None:
        self.ctx: Any = None  # the run's context, once it ticks

    def __call__(self, reason: str) -> None:
        import rospy

        from coordinator.runevents import Notice

        text = shutdown_notice(rospy.get_name(), reason)
        ctx = self.ctx
        if ctx is not None:
            notice = Notice("shutdown_request", text)
            ctx.inbox.put(notice)
            end = time.monotonic() + NOTICE_FIRST
            while time.monotonic() < end:
                if any(n is notice for n in ctx.notices):
                    return
                time.sleep(0.005)
        err(text)
