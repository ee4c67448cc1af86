"""A tree's ``cleanup:`` when it runs: the runner, the test kit, scenarios, the run log and replay (no ROS)."""
from __future__ import annotations

import io

import pytest
from py_trees.common import Status

from coordinator import runner as runner_module
from coordinator.nodes.task import WithCleanup
from coordinator.replay import Replay, _jump_to_failure
from coordinator.replay import _report as replay_report
from coordinator.runevents import RunObserver
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runner import Display, summary_lines
from coordinator.runstream import RunStream
from coordinator.testing.kit import Coverage, TreeTest
from coordinator.testing.scenario import run_scenario_file
from tests.stopkit import GO_ROOT, CtrlC, Kept

TREE = GO_ROOT + """cleanup:
  sequence:
    - call: speech.say
      inputs: {text: "{ended}: {ended_reason}"}
    - call: navigation.where_am_i
cleanup_timeout: 10
"""


@pytest.fixture
def go(tmp_path, sim_defs):
    path = tmp_path / "go.yaml"
    path.write_text(TREE)
    return TreeTest(str(path), definitions=sim_defs)


def _cleanup_said(run):
    return [c.inputs["text"] for c in run.cleanup_calls("speech.say")]


def test_cleanup_runs_after_a_success(go):
    go.mocks["navigation.go_to"].succeed(delay=1.0, room="kitchen")
    run = go.run()
    assert run.succeeded and run.reason == "" and run.ended == "succeeded" and run.cleanup_status == "SUCCESS"
    assert run.targets == ["navigation.go_to", "speech.say", "speech.say", "navigation.where_am_i"]
    assert _cleanup_said(run) == ["succeeded: "] and run.said() == ["arrived", "succeeded: "]
    assert run.statuses("cleanup") == ["RUNNING", "SUCCESS"] and run.statuses("go") == ["RUNNING", "SUCCESS"]
    assert run.blackboard["ended"] == "succeeded" and run.blackboard["ended_reason"] == ""


def test_cleanup_runs_after_a_failure_and_the_reason_stays_roots(go):
    go.mocks["navigation.go_to"].fail("blocked", delay=1.0)
    go.mocks["navigation.where_am_i"].fail("lost")
    run = go.run()
    assert run.failed and run.reason == "navigation.go_to failed: blocked"
    assert run.result.failed_call is run.calls("navigation.go_to")[0]
    assert run.ended == "failed" and _cleanup_said(run) == ["failed: navigation.go_to failed: blocked"]
    assert run.cleanup_status == "FAILURE" and run.cleanup_reason == "cleanup: navigation.where_am_i failed: lost"


def test_a_failing_cleanup_does_not_change_a_success(go):
    go.mocks["navigation.go_to"].succeed(room="kitchen")
    go.mocks["navigation.where_am_i"].fail("lost")
    run = go.run()
    assert run.succeeded and run.reason == "" and run.cleanup_status == "FAILURE"
    lines = summary_lines(run.result, "go")
    assert "cleanup (root succeeded): FAILED in 0.00 s: cleanup: navigation.where_am_i failed: lost" in lines
    at = lines.index("cleanup (root succeeded): FAILED in 0.00 s: cleanup: navigation.where_am_i failed: lost") + 1
    assert lines[at].startswith("  at: ") and at == len(lines) - 3   # where its failure is; its calls under it


def test_cleanup_runs_after_a_stop_by_max_duration(go):
    go.mocks["navigation.go_to"].hang()
    run = go.run(max_duration=5.0)
    assert run.failed and run.reason == "stopped after 5 s while 'navigation.go_to' was running"
    assert run.ended == "stopped" and run.cleanup_status == "SUCCESS"
    go_to = run.calls("navigation.go_to")[0]
    assert go_to.status == "halted" and go_to.ended == pytest.approx(5.0)
    said = run.cleanup_calls("speech.say")[0]
    assert said.started >= go_to.ended and said.inputs["text"] == "stopped: " + run.reason
    assert run.result.stopped_at == pytest.approx(5.0) and run.duration == pytest.approx(5.0)


def test_cleanup_runs_after_a_stop_by_stop_when(go):
    go.mocks["navigation.go_to"].hang()
    ticks = []

    class Count(RunObserver):
        def on_tick(self, root, changes, now):
            ticks.append(now)

    run = go.run(observers=[Count()], stop_when=lambda: "enough ticks" if len(ticks) >= 3 else "")
    assert run.reason == "enough ticks while 'navigation.go_to' was running" and run.ended == "stopped"
    assert _cleanup_said(run) == ["stopped: enough ticks while 'navigation.go_to' was running"]


def test_the_cleanup_has_its_own_time_limit(go):
    go.mocks["navigation.go_to"].hang()
    go.mocks["navigation.where_am_i"].hang()
    run = go.run(max_duration=5.0)
    assert run.reason.startswith("stopped after 5 s") and run.failed   # root's, whatever the cleanup did
    assert run.cleanup_status == "FAILURE" and run.cleanup_reason == (
        "did not end within 10 s (cleanup_timeout) while 'navigation.where_am_i' was running")
    where = run.cleanup_calls("navigation.where_am_i")[0]
    assert where.status == "halted" and where.ended == pytest.approx(15.0)   # cancelled at the limit
    assert run.duration == pytest.approx(15.0) and run.result.cleanup_duration == pytest.approx(10.0)


def test_ctrl_c_halts_root_runs_the_cleanup_then_the_run_is_interrupted(go):
    go.mocks["navigation.go_to"].hang()
    go.mocks["navigation.where_am_i"].succeed(delay=2.0)
    kept = Kept()
    with pytest.raises(KeyboardInterrupt):
        go.run(observers=[CtrlC(3.0), kept])
    notice, result = kept.seen
    assert notice.what == "cleanup" and notice.text == (
        "interrupted while 'navigation.go_to' was running: running the cleanup (at most 10 s; Ctrl-C again ends it "
        "at once)")
    assert result.status == Status.INVALID and result.reason == "interrupted while 'navigation.go_to' was running"
    assert result.ended == "stopped" and result.cleanup_status == Status.SUCCESS
    assert [c.target for c in result.cleanup_calls] == ["speech.say", "navigation.where_am_i"]
    assert result.cleanup_calls[1].status == "succeeded" and result.duration >= 5.0


def test_a_second_ctrl_c_ends_the_cleanup_at_once(go, monkeypatch):
    monkeypatch.setattr(runner_module, "BURST", 0.0)   # the second one is not the same burst
    go.mocks["navigation.go_to"].hang()
    go.mocks["navigation.where_am_i"].hang()
    kept = Kept()
    with pytest.raises(KeyboardInterrupt):
        go.run(observers=[CtrlC(3.0, 4.0), kept])
    result = kept.result
    where = result.cleanup_calls[1]
    assert result.cleanup_status == Status.INVALID and where.status == "halted"
    assert result.cleanup_reason == "interrupted again while 'navigation.where_am_i' was running"
    assert where.ended < 5.0 and result.status == Status.INVALID


def test_a_signal_repeated_in_the_same_burst_does_not_end_the_cleanup(go, monkeypatch):
    monkeypatch.setattr(runner_module, "BURST", 3600.0)
    go.mocks["navigation.go_to"].hang()
    kept = Kept()
    with pytest.raises(KeyboardInterrupt):
        go.run(observers=[CtrlC(3.0, 3.0), kept])
    assert kept.result.cleanup_status == Status.SUCCESS


def test_ctrl_c_during_the_cleanup_after_root_ended_keeps_roots_result(go):
    go.mocks["navigation.go_to"].succeed(room="kitchen", delay=1.0)
    go.mocks["navigation.where_am_i"].hang()
    run = go.run(observers=[CtrlC(2.0)])
    assert run.succeeded and run.cleanup_status == "INVALID"
    assert run.cleanup_reason == "interrupted while 'navigation.where_am_i' was running"


def test_without_cleanup_the_root_is_the_trees_top(tmp_path, sim_defs):
    path = tmp_path / "plain.yaml"
    path.write_text(TREE.split("cleanup:")[0])
    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].hang()
    run = t.run(max_duration=2.0)
    assert run.ended == "" and run.cleanup_status is None and run.targets == ["navigation.go_to"]
    assert not any(isinstance(b, WithCleanup) for b in run.result.history)
    assert "cleanup" not in " ".join(summary_lines(run.result, "plain"))


def test_the_run_log_replay_and_failure_show_the_cleanup(go, tmp_path):
    go.mocks["navigation.go_to"].fail("blocked", delay=1.0)
    go.mocks["navigation.where_am_i"].fail("lost")
    log_path = str(tmp_path / "run.jsonl")
    live = io.StringIO()
    go.run(observers=[RunStream([RunLogWriter(log_path, fsync=False)]), Display(live, tty=False)])
    log = read_log(log_path)
    assert log.end["reason"] == "navigation.go_to failed: blocked"
    assert log.end["cleanup"] == {"ended": "failed", "status": "FAILURE", "calls": 2, "duration": 0.0,
                                  "reason": "cleanup: navigation.where_am_i failed: lost",
                                  "at": "%s:%d:7" % (go.path, TREE.splitlines().index("    - call: navigation.where_am_i") + 1)}
    kinds = [(n["kind"], n["name"], n["parent"]) for n in log.tree["nodes"]]
    assert kinds[0] == ("with_cleanup", "go", None) and ("sequence", "cleanup", 0) in kinds
    notices = [r["text"] for r in log.of_type("notice")]
    assert notices == ["the cleanup failed (root failed): cleanup: navigation.where_am_i failed: lost; the run's "
                       "result stays root's"]
    assert "NOTICE    the cleanup failed (root failed)" in live.getvalue()
    replay = Replay(log)
    shown = io.StringIO()
    display = Display(shown, tty=False)
    while replay.next(display) is not None:
        pass
    assert shown.getvalue() == live.getvalue()
    report = io.StringIO()
    replay_report(replay, report)
    lines = report.getvalue().splitlines()
    at = lines.index("cleanup (root failed): FAILED in 0.00 s: cleanup: navigation.where_am_i failed: lost")
    assert lines[at - 1].split()[2:4] == ["navigation.go_to", "failed"]
    assert lines[at + 1] == "  at: %s" % log.end["cleanup"]["at"]
    assert lines[at + 3].split()[2:4] == ["navigation.where_am_i", "failed"]
    failure = io.StringIO()
    _jump_to_failure(Replay(read_log(log_path)), failure)
    assert failure.getvalue().splitlines()[0].endswith("navigation.go_to failed: blocked")   # root's, not the cleanup's


def test_replay_of_a_stopped_run_with_a_cleanup_says_when_it_was_stopped(go, tmp_path):
    go.mocks["navigation.go_to"].hang()
    log_path = str(tmp_path / "run.jsonl")
    go.run(max_duration=3.0, observers=[RunStream([RunLogWriter(log_path, fsync=False)])])
    replay = Replay(read_log(log_path))
    assert replay.stop_tick() is not None
    report = io.StringIO()
    while replay.next(None) is not None:
        pass
    replay_report(replay, report)
    text = report.getvalue()
    assert "navigation.go_to           halted        3.000s  stopped after 3 s" in text
    assert "cleanup (root stopped): succeeded in 0.00 s" in text
    failure = io.StringIO()
    _jump_to_failure(Replay(read_log(log_path)), failure)
    assert "stopped after 3 s while 'navigation.go_to' was running (at 3.000s)" in failure.getvalue()
    assert "navigation.go_to           since 0.000s" in failure.getvalue()


def test_coverage_counts_the_cleanup_nodes(tmp_path, sim_defs):
    path = tmp_path / "go.yaml"
    path.write_text(TREE)
    coverage = Coverage()
    t = TreeTest(str(path), definitions=sim_defs, coverage=coverage)
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    t.run()
    report = coverage.report()
    assert "6 of 6 nodes ran" in report and "with_cleanup" not in report
    assert "sequence 'cleanup' reached SUCCESS" in report


SCENARIOS = """tree: go.yaml
scenarios:
  - name: stopped while driving, the cleanup says so
    max_duration: 5
    mocks:
      navigation.go_to: {hang: true}
    expect:
      status: failure
      reason: stopped after 5 s
      cleanup: success
      calls:
        in_order:
          - navigation.go_to: {place: kitchen}
          - speech.say: {text: "stopped: stopped after 5 s while 'navigation.go_to' was running"}
          - navigation.where_am_i
  - name: a failing cleanup is expected
    mocks:
      navigation.where_am_i: {fail: lost}
    expect:
      cleanup: failure
      calls: [navigation.go_to, speech.say, speech.say, navigation.where_am_i]
  - name: wrong
    mocks:
      navigation.where_am_i: {fail: lost}
    expect: {cleanup: success}
"""


def test_scenarios_see_the_cleanups_calls_and_how_it_ended(tmp_path, sim_defs):
    (tmp_path / "go.yaml").write_text(TREE)
    path = tmp_path / "go.scenarios.yaml"
    path.write_text(SCENARIOS)
    out = io.StringIO()
    assert run_scenario_file(str(path), sim_defs, out=out) == [True, True, False]
    assert "    cleanup FAILURE, expected SUCCESS (cleanup: navigation.where_am_i failed: lost)" in out.getvalue()


def test_expect_cleanup_is_checked(tmp_path, sim_defs):
    from coordinator.errors import TreeErrors

    (tmp_path / "plain.yaml").write_text(TREE.split("cleanup:")[0])
    path = tmp_path / "s.yaml"
    path.write_text("tree: plain.yaml\nscenarios:\n  - expect: {cleanup: succes}\n  - expect: {cleanup: success}\n")
    with pytest.raises(TreeErrors) as exc:
        run_scenario_file(str(path), sim_defs, out=io.StringIO())
    assert [e.message for e in exc.value.errors] == [
        "cleanup is success or failure (how the tree's cleanup: ended), got 'succes' (did you mean 'success'?)",
        "expect: cleanup, but plain.yaml has no cleanup: (a top-level node run after root)"]
