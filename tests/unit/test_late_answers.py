"""An answer that comes after its call ended (a link that dropped and came back: TCP delivers late what it
held back, and the cancel may never reach the module): the module ran the call, and a ``retry`` may have
sent it again. The run says so with a ``late_answer`` notice, and the call's record keeps the answer.

The mocks ignore cancels (as a module that never got the cancel): an answer within the runtime's grace
after the cancel is the scripted one, not ``cancelled``."""
from __future__ import annotations

import io
import json
import logging
from typing import Any, List, Tuple

from comm.messages import FunctionResult
from coordinator.context import RecordStatus
from coordinator.replay import Replay
from coordinator.replay import _report as replay_summary
from coordinator.runevents import RunObserver
from coordinator.runlog import read_log
from coordinator.runner import Display, NoticeLines, summary_lines
from coordinator.testing import fail, succeed
from tests.unit.test_call_status import tree  # noqa: F401  (the fixture: a one-file tree on the mocks)
from tests.unit.test_recording import recorded

RETRIED = """
  retry: 3
  child: {call: navigation.go_to, inputs: {place: kitchen}, timeout: 6}
"""

HALTED = """
  sequence:
    - force_success:
        timeout: 5
        child: {call: navigation.go_to, inputs: {place: kitchen}, timeout: none}
    - wait: 2
"""


class Notices(RunObserver):
    """The notices of a run, with their times from its start; with ``stray``, a result for a call id the
    run never made is delivered as soon as the run sends its first call."""

    def __init__(self, stray: Any = None) -> None:
        self.seen: List[Tuple[float, str, str]] = []
        self.stray = stray
        self.ctx: Any = None

    def on_start(self, tree_file: Any, root: Any, ctx: Any) -> None:
        self.ctx = ctx

    def on_call_start(self, record: Any) -> None:
        if self.stray is not None:
            self.ctx.inbox.put(self.stray)
            self.stray = None

    def on_notice(self, notice: Any, now: float) -> None:
        self.seen.append((now - self.ctx.started, notice.what, notice.text))


def driven_twice(mocks: Any) -> None:
    """The first go_to answers 0.8 s after its 6 s timeout, while the retry's second one waits for the module."""
    mocks["navigation.go_to"].ignoring_cancels().script(succeed(delay=6.8, room="kitchen"),
                                                          succeed(delay=1, room="kitchen"))


def test_a_call_answered_after_its_timeout_is_a_notice_that_the_module_ran_it(tree):  # noqa: F811
    t = tree(RETRIED)
    driven_twice(t.mocks)
    shown, quiet, notices = io.StringIO(), io.StringIO(), Notices()
    run = t.run(observers=[Display(shown, tty=False), NoticeLines(quiet), notices])
    assert run.succeeded, run.reason
    first, second = run.calls("navigation.go_to")
    text = ("navigation.go_to (call %s, timed out at 6.00s) answered succeeded at 6.80s: the module did run it"
            % first.call_id)
    assert notices.seen == [(6.8, "late_answer", text)]
    assert "[  6.800s] NOTICE    %s\n" % text in shown.getvalue()   # the terminal, and without it (-q)
    assert quiet.getvalue() == "[  6.800s] NOTICE    %s\n" % text
    # the record keeps the answer the tree no longer took; the call itself stays a timeout
    assert first.status == RecordStatus.TIMEOUT and first.error == "no answer within 6s"
    assert (first.late_status, first.late_at, first.late_error) == ("succeeded", 6.8, "")
    assert first.late_result is not None and first.late_result.call_id == first.call_id
    assert first.result is None and first.outputs == {}
    assert second.status == "succeeded" and second.late_status is None and second.late_at is None


def test_a_halted_call_answered_anyway_says_it_was_cancelled(tree):  # noqa: F811
    t = tree(HALTED)
    t.mocks["navigation.go_to"].ignoring_cancels().script(fail("blocked by a chair", delay=5.5))
    notices = Notices()
    run = t.run(observers=[notices])
    assert run.succeeded, run.reason
    (call,) = run.calls("navigation.go_to")
    assert call.status == "halted"
    assert (call.late_status, call.late_at, call.late_error) == ("failed", 5.5, "blocked by a chair")
    assert notices.seen == [(5.5, "late_answer", "navigation.go_to (call %s, halted at 5.00s) answered failed (blocked "
                                               "by a chair) after it was cancelled, at 5.50s: the module did run it"
                             % call.call_id)]


def test_the_run_log_records_the_notice_and_replay_lists_it_under_its_call(tree, sim_defs, tmp_path):  # noqa: F811
    path = tree(RETRIED).path
    log, run = recorded(path, sim_defs, tmp_path, driven_twice)
    first = run.calls("navigation.go_to")[0]
    with open(log) as f:
        records = [json.loads(line) for line in f]
    text = ("navigation.go_to (call %s, timed out at 6.00s) answered succeeded at 6.80s: the module did run it"
            % first.call_id)
    assert [r for r in records if r["type"] == "notice"] == [
        {"v": 1, "type": "notice", "run": records[0]["run"], "t": 6.8, "what": "late_answer", "text": text,
         "call_id": first.call_id}]
    replay = Replay(read_log(log))
    while replay.next() is not None:
        pass
    out = io.StringIO()
    replay_summary(replay, out)
    listed = out.getvalue().split("calls:\n", 1)[1].splitlines()
    assert listed[:2] == ["  +  0.000s  navigation.go_to           timeout       6.000s  no answer within 6s",
                          "              late answer: " + text]
    assert "the ROS graph" not in out.getvalue()   # listed under its call, not as news of the graph
    live = summary_lines(run.result, "t")           # the live summary lists it the same way
    assert live[live.index("calls:") + 1:] == listed


def test_answers_that_are_no_news_make_no_notice(tree):  # noqa: F811
    """An answer for a call id the run never made is logged, and the ``cancelled`` that answers the run's own
    cancel is expected: neither is a notice, nor kept as a late answer."""
    t = tree(RETRIED)
    driven_twice(t.mocks)
    logged: List[str] = []

    class Lines(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            logged.append(record.getMessage())

    handler = Lines()
    logger = logging.getLogger("bmtree.coordinator")
    logger.addHandler(handler)
    try:
        notices = Notices(stray=FunctionResult(call_id="00000000feedbeef", basic_mod="navigation", function="go_to"))
        run = t.run(observers=[notices])
    finally:
        logger.removeHandler(handler)
    assert run.succeeded, run.reason
    first = run.calls("navigation.go_to")[0]
    assert [n[1] for n in notices.seen] == ["late_answer"]   # the late answer only
    assert first.call_id in notices.seen[0][2] and "00000000feedbeef" not in notices.seen[0][2]
    assert any("matches no pending call (call_id 00000000feedbeef" in line for line in logged), logged
    assert "00000000feedbeef" in [r.call_id for r in notices.ctx.dropped]
    # a module that honours the cancel answers `cancelled` at once: the expected answer, no news
    t = tree(RETRIED)
    t.mocks["navigation.go_to"].script(succeed(delay=8, room="kitchen"), succeed(delay=1, room="kitchen"))
    notices = Notices()
    run = t.run(observers=[notices])
    assert run.succeeded and [c.status for c in run.calls()] == ["timeout", "succeeded"]
    assert notices.seen == [] and run.calls()[0].late_status is None
