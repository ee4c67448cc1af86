"""A tree's ``cleanup:`` as real runs showed it: scenarios of interrupted runs, the labels of a cut
cleanup's calls on a clock that moves, ``replay --failure`` of a success whose cleanup failed, the
last line of an interrupted run, the kit's ``cleanup_calls`` and ``bmtree runs`` of a live run."""
from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import time

import pytest
import yaml

from coordinator import cli
from coordinator import runner as runner_module
from coordinator.clock import SimClock
from coordinator.replay import Replay, _jump_to_failure
from coordinator.replay import _report as replay_report
from coordinator.runcmd import interrupted_line
from coordinator.runlog import RunLogWriter, list_runs, read_log
from coordinator.runner import summary_lines
from coordinator.runstream import RunStream
from coordinator.scenariogen import write_scenario
from coordinator.testing import kit
from coordinator.testing.kit import TreeTest
from coordinator.testing.scenario import run_scenario_file
from tests.stopkit import GO_CLEANUP, GO_ROOT, CtrlC, Kept

WAITS = """format: 1
name: go
root:
  sequence:
    - wait: 2
    - call: speech.say
      inputs: {text: a}
    - wait: 2
    - call: speech.say
      inputs: {text: b}
    - wait: 2
cleanup:
  sequence:
    - wait: 3
    - call: speech.say
      inputs: {text: "bye {ended}: {ended_reason}"}
"""

GO = GO_ROOT + GO_CLEANUP


def _tree(tmp_path, text, sim_defs):
    path = tmp_path / "go.yaml"
    path.write_text(text)
    return TreeTest(str(path), definitions=sim_defs)


def _interrupted(t, *at, log=None):
    keep = Kept()
    observers = [CtrlC(*at), keep] + ([RunStream([RunLogWriter(log, fsync=False)])] if log else [])
    with pytest.raises(KeyboardInterrupt):
        t.run(observers=observers)
    return keep.result


# 1. replay --scenario of an interrupted run with a cleanup -----------------------------------------------
def test_an_interrupted_run_with_a_cleanup_becomes_a_scenario_that_stops_root_when_the_run_did(tmp_path, sim_defs):
    t = _tree(tmp_path, WAITS, sim_defs)
    log = str(tmp_path / "run.jsonl")
    result = _interrupted(t, 4.3, log=log)
    assert result.stopped_at == pytest.approx(4.5) and result.duration == pytest.approx(7.5)   # the cleanup ran 3 s
    said = [c.inputs["text"] for c in result.calls]
    assert said == ["a", "b", "bye stopped: interrupted while 'wait 2s' was running"]
    out_path = str(tmp_path / "again.yaml")
    write_scenario(read_log(log), out_path)
    text = open(out_path).read()
    scenario = yaml.safe_load(text)["scenarios"][0]
    assert scenario["max_duration"] == pytest.approx(4.5)   # when root was stopped, not the end of the cleanup
    assert scenario["expect"]["status"] == "failure" and scenario["expect"]["cleanup"] == "success"
    assert scenario["expect"]["calls"][-1] == {"speech.say": {"text": "bye stopped: stopped after 4.5 s while 'wait 2s' "
                                                                      "was running"}}
    assert "interrupted (interrupted while 'wait 2s' was running) at 4.5s, then its cleanup ran" in text
    out = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, out) == [True], out.getvalue()


def test_a_scenario_of_a_run_with_a_cleanup_expects_how_the_cleanup_ended(tmp_path, sim_defs):
    t = _tree(tmp_path, GO, sim_defs)
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    t.mocks["navigation.where_am_i"].fail("lost")
    log = str(tmp_path / "run.jsonl")
    t.run(observers=[RunStream([RunLogWriter(log, fsync=False)])])
    out_path = str(tmp_path / "again.yaml")
    write_scenario(read_log(log), out_path)
    assert yaml.safe_load(open(out_path))["scenarios"][0]["expect"]["cleanup"] == "failure"
    out = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, out) == [True], out.getvalue()


# 2. the calls a cut cleanup halted, on a clock that moves between the halt and the stamp ------------------
class Creeping(SimClock):
    """A simulated clock that, as a real one, has moved on each time it is read."""

    def now(self):
        self._now += 1e-4
        return self._now


@pytest.mark.parametrize("second", [False, True])
def test_a_cut_cleanups_calls_say_why_on_a_clock_that_moves(tmp_path, sim_defs, monkeypatch, second):
    monkeypatch.setattr(kit, "SimClock", Creeping)
    monkeypatch.setattr(runner_module, "BURST", 0.0)   # a second Ctrl-C is not the first one's burst
    t = _tree(tmp_path, GO, sim_defs)
    t.mocks["navigation.go_to"].hang()
    t.mocks["navigation.where_am_i"].hang()
    log = str(tmp_path / "run.jsonl")
    result = _interrupted(t, *((3.0, 4.0) if second else (3.0,)), log=log)
    where = result.cleanup_calls[1]
    assert where.target == "navigation.where_am_i" and where.error == "halted by the tree"   # its record
    want = ("interrupted", "") if second else ("halted", "did not end within 4 s (cleanup_timeout)")
    assert runner_module.shown_status(result, where) == want
    line = next(x for x in summary_lines(result, "go") if x.startswith("  +") and "navigation.where_am_i" in x)
    assert "halted by the tree" not in line and line.split()[3] == want[0] and want[1] in line
    replay = Replay(read_log(log))
    while replay.next(None) is not None:
        pass
    report = io.StringIO()
    replay_report(replay, report)
    replayed = next(x for x in report.getvalue().splitlines() if x.startswith("  +") and "navigation.where_am_i" in x)
    assert replayed.split()[3] == want[0] and want[1] in replayed


def test_the_kit_labels_a_call_of_a_cleanup_its_time_limit_halted(tmp_path, sim_defs):
    t = _tree(tmp_path, GO, sim_defs)
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    t.mocks["navigation.where_am_i"].hang()
    run = t.run()
    [where] = run.cleanup_calls("navigation.where_am_i")
    assert run.label(where) == ("halted", "did not end within 4 s (cleanup_timeout)")
    assert run.label(run.calls("navigation.go_to")[0]) == ("succeeded", "")


# 3. replay --failure of a success whose cleanup failed -----------------------------------------------------
def test_replay_failure_of_a_success_whose_cleanup_failed_says_both(tmp_path, sim_defs):
    t = _tree(tmp_path, GO, sim_defs)
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    t.mocks["navigation.where_am_i"].fail("lost")
    log = str(tmp_path / "run.jsonl")
    t.run(observers=[RunStream([RunLogWriter(log, fsync=False)])])
    out = io.StringIO()
    _jump_to_failure(Replay(read_log(log)), out)
    lines = out.getvalue().splitlines()
    assert lines[0] == "the run succeeded: no leaf of root failed"
    assert lines[1] == ("the cleanup (root succeeded) failed: cleanup: navigation.where_am_i failed: lost; the run's "
                        "result stays root's")
    assert lines[2] == "its call that did not succeed:" and lines[3].split()[2:4] == ["navigation.where_am_i", "failed"]
    assert "the failure that ended the run" not in out.getvalue()


def test_replay_failure_of_a_failure_also_says_the_cleanup_failed(tmp_path, sim_defs):
    t = _tree(tmp_path, GO, sim_defs)
    t.mocks["navigation.go_to"].fail("blocked")
    t.mocks["navigation.where_am_i"].fail("lost")
    log = str(tmp_path / "run.jsonl")
    t.run(observers=[RunStream([RunLogWriter(log, fsync=False)])])
    out = io.StringIO()
    _jump_to_failure(Replay(read_log(log)), out)
    text = out.getvalue()
    assert text.splitlines()[0].startswith("the failure that ended the run") and "navigation.go_to failed" in text
    assert "the cleanup (root failed) failed: cleanup: navigation.where_am_i failed: lost" in text


# 4. the last line of an interrupted run ---------------------------------------------------------------------
def test_the_interrupted_line_says_how_the_cleanup_went(tmp_path, sim_defs, monkeypatch):
    monkeypatch.setattr(runner_module, "BURST", 0.0)
    t = _tree(tmp_path, GO, sim_defs)
    t.mocks["navigation.go_to"].hang()
    assert interrupted_line(_interrupted(t, 3.0), True) == (
        "interrupted: running calls were cancelled, then the cleanup ran")
    t.mocks["navigation.where_am_i"].hang()
    assert interrupted_line(_interrupted(t, 3.0, 4.0), True) == (
        "interrupted: running calls were cancelled, then the cleanup was cut short by a second Ctrl-C while "
        "'navigation.where_am_i' was running")
    assert interrupted_line(_interrupted(t, 3.0), True) == (
        "interrupted: running calls were cancelled, then the cleanup was cut short: did not end within 4 s "
        "(cleanup_timeout) while 'navigation.where_am_i' was running")
    t.mocks["navigation.where_am_i"].fail("lost")
    assert interrupted_line(_interrupted(t, 3.0), True) == (
        "interrupted: running calls were cancelled, then the cleanup failed: cleanup: navigation.where_am_i failed: "
        "lost")
    assert interrupted_line(None, False) == "interrupted during start-up: nothing was called"
    assert interrupted_line(None, True) == "interrupted before any call was sent"


# 5. the kit's cleanup_calls of a misspelt function --------------------------------------------------------
def test_cleanup_calls_of_a_misspelt_function_names_cleanup_calls(tmp_path, sim_defs):
    t = _tree(tmp_path, GO, sim_defs)
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    run = t.run()
    with pytest.raises(KeyError) as exc:
        run.cleanup_calls("navigation.goto")
    assert "run.cleanup_calls('navigation.goto'): no function 'navigation.goto'" in str(exc.value)
    assert "run.calls(" not in str(exc.value)
    assert [c.target for c in run.cleanup_calls("speech.say")] == ["speech.say"]
    assert run.cleanup_calls("navigation.go_to") == []


# 6. bmtree runs of a run still going ---------------------------------------------------------------------
def _log_of(directory, name, pid, started):
    os.makedirs(directory, exist_ok=True)
    path = os.path.join(directory, "20261125-120000-%s-go.jsonl" % name)
    with open(path, "w") as fh:
        fh.write(json.dumps({"v": 1, "type": "tree", "run": name, "t": 0.0, "started": started, "name": "go",
                             "pid": pid, "nodes": [{"id": 0, "name": "go", "parent": None, "kind": "sequence"}]}) + "\n")
        fh.write(json.dumps({"v": 1, "type": "tick", "run": name, "t": 0.5, "n": 1, "changes": []}) + "\n")
    return path


def test_runs_lists_a_run_whose_writer_still_runs_as_running(tmp_path, capsys):
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)", "bmtree", "run"])
    try:
        time.sleep(0.1)
        runs = str(tmp_path / "runs")
        _log_of(runs, "aaaaaa", proc.pid, time.time())               # written by it
        _log_of(runs, "bbbbbb", proc.pid, time.time() - 3600.0)      # an older run's pid, taken by it since
        _log_of(runs, "cccccc", None, time.time())                    # no pid recorded
        _log_of(runs, "dddddd", os.getpid(), time.time())             # alive, not a bmtree process: pytest's
        by = {os.path.basename(r.path)[16:22]: r for r in list_runs(runs)}
        assert (by["aaaaaa"].status, by["aaaaaa"].reason) == ("RUNNING", "still running (pid %d)" % proc.pid)
        assert [by[k].status for k in ("bbbbbb", "cccccc")] == ["UNFINISHED"] * 2
        if b"bmtree" not in open("/proc/self/cmdline", "rb").read():
            assert by["dddddd"].status == "UNFINISHED"
        capsys.readouterr()
        assert cli.main(["replay", by["aaaaaa"].path]) == 0   # replay says so too
        assert "go: RUNNING: still running (pid %d)" % proc.pid in capsys.readouterr().out
    finally:
        proc.kill()
        proc.wait()
    assert list_runs(runs)[0].status == "UNFINISHED"   # its writer is gone
    assert cli.main(["replay", by["aaaaaa"].path]) == 0
    assert "go: UNFINISHED: last seen alive" in capsys.readouterr().out
