"""After a run, ``bmtree run`` waits a moment for the answers to the cancels of the calls the tree stopped,
and says the ones that may still run on their module: before, Ctrl-C printed "running calls were
cancelled" while a function that ignores its cancel went on moving the arm."""
from __future__ import annotations

from typing import Any, List

import pytest

from coordinator.runner import summary_lines
from coordinator.runstop import interrupted_line
from coordinator.testing import kit
from coordinator.testing.kit import TreeTest

TREE = """format: 1
name: grab
root:
  call: navigation.go_to
  inputs: {place: kitchen}
  timeout: 2
"""


@pytest.fixture
def grab(tmp_path, sim_defs, monkeypatch):
    path = tmp_path / "grab.yaml"
    path.write_text(TREE)
    runners: List[Any] = []
    real = kit.TreeRunner

    def keep(*a: Any, **k: Any) -> Any:
        runners.append(real(*a, **k))
        return runners[-1]

    monkeypatch.setattr(kit, "TreeRunner", keep)
    t = TreeTest(str(path), definitions=sim_defs)
    t.runners = runners
    return t


def test_a_call_whose_code_ignores_its_cancel_is_said_to_be_maybe_running(grab):
    grab.mocks["navigation.go_to"].respond(lambda place: {"success": True, "room": place}, delay=60.0)
    grab.mocks.ignoring_cancels("navigation.go_to")
    run = grab.run()
    assert run.failed and run.reason == "navigation.go_to: no answer within 2s"
    running = grab.runners[-1].confirm_cancels()
    call = run.calls("navigation.go_to")[0]
    assert running == [call]
    assert call.maybe_running == "its module says its code has not returned after 1s: it goes on running"
    lines = summary_lines(run.result, "grab")
    row = lines.index([line for line in lines if line.startswith("  +")][0])
    assert lines[row + 1] == " " * 14 + "may still be running: " + call.maybe_running, lines
    assert interrupted_line(run.result, True, running=running) == (
        "interrupted: running calls were cancelled (but navigation.go_to may still be running: its module says its "
        "code has not returned after 1s: it goes on running)")   # as its summary row says (it said "did not confirm")


def test_a_call_that_honours_its_cancel_is_not(grab):
    grab.mocks["navigation.go_to"].hang()
    run = grab.run()
    assert run.failed and grab.runners[-1].confirm_cancels() == []
    assert run.calls("navigation.go_to")[0].cancel_answer == "cancelled by the coordinator"
    assert not [line for line in summary_lines(run.result, "grab") if "may still be running" in line]
    assert interrupted_line(run.result, True) == "interrupted: running calls were cancelled"


def test_a_module_that_never_answers_the_cancel_is_said_so(grab, monkeypatch):
    # the cancel never reaches the module (an original module, a module cut off): no answer comes
    monkeypatch.setattr(kit.InProcessTransport, "send_cancel", lambda self, cancel: self.sent.append(cancel))
    grab.mocks["navigation.go_to"].hang()
    run = grab.run()
    call = run.calls("navigation.go_to")[0]
    runner = grab.runners[-1]
    start = runner.ctx.clock.now()
    assert runner.confirm_cancels(0.5) == [call] and runner.ctx.clock.now() - start == pytest.approx(0.5)
    assert call.maybe_running == "its module did not answer the cancel"
    assert interrupted_line(run.result, True, running=[call]) == (
        "interrupted: running calls were cancelled (but navigation.go_to may still be running: its module did not "
        "answer the cancel)")


def test_the_answers_to_its_cancels_go_into_the_run_log_after_its_end(grab, tmp_path, capsys, monkeypatch):
    """The late answer that proves the module did run the call came after the end record, and the log was
    closed at the end: the terminal said it, the log (and so replay) did not."""
    from coordinator.replay import cmd_replay
    from coordinator.runlog import RunLogWriter, list_runs, read_log
    from coordinator.runstream import RunStream

    grab.mocks["navigation.go_to"].respond(lambda place: {"success": True, "room": place}, delay=2.5)
    # the cancel is lost (a link down, an original module): the module runs the call to its end
    monkeypatch.setattr(kit.InProcessTransport, "send_cancel", lambda self, cancel: self.sent.append(cancel))
    path = str(tmp_path / "runs" / "20261126-091737-17983e-grab.jsonl")
    (tmp_path / "runs").mkdir()
    stream = RunStream([RunLogWriter(path, fsync=False)], linger=True)
    run = grab.run(observers=[stream])
    assert run.failed
    grab.runners[-1].confirm_cancels()   # as bmtree run does after the run: the answer comes at 2.5 s
    stream.close()
    log = read_log(path)
    assert log.end is not None and log.end["status"] == "FAILURE"
    late = [r for r in log.records if r.get("type") == "notice" and r.get("what") == "late_answer"]
    assert len(late) == 1 and log.records.index(late[0]) > log.records.index(log.end), log.records[-3:]
    assert "answered succeeded at 2.50s: the module did run it" in late[0]["text"], late
    listed = list_runs(str(tmp_path / "runs"))
    assert [(r.status, r.reason) for r in listed] == [("FAILURE", "navigation.go_to: no answer within 2s")]
    import argparse

    cmd_replay(argparse.Namespace(run=path, dir=None, at=None, step=False, failure=False, scenario=None, web=False,
                                  speed=None, bind=None, port=None))
    out = capsys.readouterr().out
    assert "late answer: navigation.go_to" in out and "the module did run it" in out, out


def test_a_cancel_answered_with_what_may_not_have_stopped_is_maybe_running_and_a_notice(grab):
    """A function that returned after its cancel but says what it drives may go on (an action server that
    ignores the cancel: ``Failure(..., not_stopped=...)``): said as for code that has not returned, and as a
    ``still_running`` notice, which the run log, the watch and replay show."""
    from comm.messages import CallStatus, FunctionResult
    from coordinator.context import STILL_RUNNING

    grab.mocks["navigation.go_to"].hang()
    run = grab.run()
    ctx = grab.runners[-1].ctx
    call = run.calls("navigation.go_to")[0]
    call.cancel_answer = ""  # as if the module's answer to the cancel came now, saying so
    ctx._late(call, FunctionResult(call_id=call.call_id, basic_mod="navigation", function="go_to",
                                   status=CallStatus.CANCELLED,
                                   error="cancelled by the coordinator, but /move_base did not end the goal within "
                                         "0.8s of its cancel: it may not have stopped"))
    assert call.maybe_running == ("its module says /move_base did not end the goal within 0.8s of its cancel: it may "
                                  "not have stopped")
    notice = [n for n in ctx.notices if n.what == STILL_RUNNING]
    assert [n.call_id for n in notice] == [call.call_id]
    assert notice[0].text == "navigation.go_to (call %s, timed out at 2.00s) may still be running: %s" % (
        call.call_id, call.maybe_running)
    assert "may still be running: " + call.maybe_running in "\n".join(summary_lines(run.result, "grab"))
