"""Run observers, run logs, replay and scenarios from runs, failure reasons (no ROS master)."""
from __future__ import annotations

import io
import json
import os
import shutil
import types

import py_trees
import pytest
import yaml
from py_trees.common import Status

from coordinator import cli
from coordinator.replay import Replay, cmd_replay, find_run
from coordinator.replay import _report as replay_summary
from coordinator.runevents import RunObserver, StatusWatcher
from coordinator.runlog import RunLogError, RunLogWriter, list_runs, plan_run_files, prune, read_log
from coordinator.runstream import RunStream, Sink
from coordinator.scenariogen import write_scenario
from coordinator.testing.kit import TreeTest
from coordinator.testing.mocks import fail, succeed
from coordinator.testing.scenario import run_scenario_file
from tests.conftest import DATA, ROOT, TREES
from tests.stopkit import CtrlC

GO = os.path.join(DATA, "record", "go_kitchen.yaml")
GO_RETRY = os.path.join(DATA, "record", "go_kitchen_retry.yaml")


class Lines(Sink):
    def __init__(self):
        self.records = []
        self.flushes = 0
        self.closed = False

    def write(self, channel, text):
        self.records.append((channel, json.loads(text)))

    def flush(self):
        self.flushes += 1

    def close(self):
        self.closed = True


def recorded(path, sim_defs, tmp_path, script, inputs=None, **run):
    """Run ``path`` on mocks scripted by ``script(mocks)`` with a run log; the log's path and the run."""
    t = TreeTest(path, definitions=sim_defs, inputs=inputs)
    script(t.mocks)
    log = str(tmp_path / "run.jsonl")
    stream = RunStream([RunLogWriter(log, fsync=False)], {"inputs": inputs or {}})
    return log, t.run(observers=[stream], **run)


def blocked_once(m):
    m["navigation.go_to"].script(fail("blocked"), succeed(room="kitchen"))


# observers ---------------------------------------------------------------------------------------------
def test_status_watcher_sees_a_retried_failure_and_a_halt():
    leaf = py_trees.behaviours.Failure(name="leaf")
    w = StatusWatcher()
    leaf.status = Status.FAILURE
    assert w.changes([(leaf, Status.FAILURE)]) == [(leaf, Status.INVALID, Status.FAILURE)]
    leaf.stop(Status.INVALID)  # reset by a parent, never visited
    assert w.changes([]) == [(leaf, Status.FAILURE, Status.INVALID)]
    assert w.changes([]) == []


def test_observers_see_start_ticks_calls_writes_and_end(sim_defs):
    seen = []

    class Spy(RunObserver):
        def on_start(self, tree, root, ctx):
            seen.append(("start", tree.name))

        def on_call_start(self, rec):
            seen.append(("call", rec.target, rec.owner.name))

        def on_call_end(self, rec):
            seen.append(("end_call", rec.target, rec.status))

        def on_blackboard_write(self, key, value, now):
            seen.append(("write", key))

        def on_end(self, result):
            seen.append(("end", result.status.value))

    t = TreeTest(os.path.join(TREES, "find_apple.yaml"), definitions=sim_defs)
    t.mocks["vision.find_object"].succeed(success=True, room="kitchen")
    t.run(observers=[Spy()])
    assert seen[0] == ("start", "find_apple")
    assert ("call", "speech.say", "announce the search") in seen
    assert ("end_call", "vision.find_object", "succeeded") in seen
    assert ("write", "object_room") in seen
    assert seen[-1] == ("end", "SUCCESS")


def test_a_failing_observer_is_detached_and_the_run_goes_on(sim_defs):
    class Broken(RunObserver):
        def on_tick(self, root, changes, now):
            raise RuntimeError("boom")

    run = TreeTest(GO, definitions=sim_defs).run(observers=[Broken()])
    assert run.succeeded


# failure reasons ---------------------------------------------------------------------------------------
def test_reason_names_the_leaf_its_call_and_the_attempts(sim_defs):
    t = TreeTest(GO_RETRY, definitions=sim_defs)
    t.mocks["navigation.go_to"].fail("blocked")
    run = t.run()
    assert run.failed
    assert run.reason == "go to the kitchen: navigation.go_to failed: blocked (3 of 3 attempts)"


def test_reason_is_the_cause_not_force_failure(sim_defs):
    t = TreeTest(os.path.join(TREES, "find_apple.yaml"), definitions=sim_defs)
    t.mocks["vision.find_object"].succeed(success=False)
    run = t.run()
    assert run.failed
    assert run.reason == "look for the object: vision.find_object answered success: false"
    assert "success is failure" not in run.reason


def test_a_recovered_failure_is_not_the_reason(sim_defs):
    t = TreeTest(os.path.join(TREES, "find_apple.yaml"), definitions=sim_defs)
    t.mocks["navigation.go_to"].script(fail("blocked"), succeed())
    t.mocks["vision.find_object"].succeed(success=True)
    t.mocks["navigation.approach"].fail("arm folded")
    run = t.run()
    assert run.reason == "approach the apple: navigation.approach failed: arm folded"


def test_retry_says_how_far_it_got(sim_defs):
    t = TreeTest(GO_RETRY, definitions=sim_defs)
    t.mocks["navigation.go_to"].script(fail("blocked"))
    run = t.run()
    assert run.statuses("go to the kitchen")[-1] == "FAILURE"
    retry = [b for b in run.result.history if b.name == "go to the kitchen"][0]
    assert retry.feedback_message == "failed in attempt 3 of 3"


def test_max_duration_ends_in_failure_with_its_reason(sim_defs):
    t = TreeTest(GO, definitions=sim_defs)
    t.mocks["navigation.go_to"].hang()
    run = t.run(max_duration=5.0)
    assert run.status == Status.FAILURE
    assert run.reason == "stopped after 5 s while 'go to the kitchen' was running"
    assert run.calls("navigation.go_to")[0].status == "halted"


def test_a_run_stopped_while_a_retry_waits_its_delay_says_what_it_waits_after(sim_defs, tmp_path):
    """No leaf runs then: the retry itself is what was running, with the failure it waits after."""
    tree = tmp_path / "delayed.yaml"
    tree.write_text("format: 1\nroot:\n  retry: 5\n  delay: 10\n  child:\n    call: navigation.go_to\n"
                    "    inputs: {place: kitchen}\n")
    t = TreeTest(str(tree), definitions=sim_defs)
    t.mocks["navigation.go_to"].fail("blocked")
    run = t.run(max_duration=5.0)
    assert run.reason == "stopped after 5 s while 'retry x5' was running (waiting 10 s between attempts: attempt 1 " \
                         "of 5 failed: navigation.go_to failed: blocked)", run.reason


def test_a_timeout_that_fires_while_a_retry_waits_its_delay_says_what_it_waits_after(sim_defs, tmp_path):
    tree = tmp_path / "bounded.yaml"
    tree.write_text("format: 1\nroot:\n  timeout: 3\n  name: in time\n  child:\n    retry: 5\n    delay: 2\n"
                    "    child:\n      call: navigation.go_to\n      inputs: {place: kitchen}\n")
    t = TreeTest(str(tree), definitions=sim_defs)
    t.mocks["navigation.go_to"].fail("blocked")
    run = t.run()
    assert run.reason == "in time: timed out after 3s while 'retry x5' was running (waiting 2 s between attempts: " \
                         "attempt 2 of 5 failed: navigation.go_to failed: blocked)", run.reason


def test_max_duration_stops_at_the_limit_not_at_the_next_period(sim_defs):
    t = TreeTest(GO, definitions=sim_defs)
    t.mocks["navigation.go_to"].hang()
    run = t.run(max_duration=0.1)  # the period is 0.25 s: the run used to stop at 0.25 s
    assert run.reason == "stopped after 0.1 s while 'go to the kitchen' was running"
    assert abs(run.result.duration - 0.1) < 1e-9


def test_the_run_summary_times_calls_from_the_runs_start_as_replay_does(sim_defs, tmp_path, capsys):
    from coordinator.runcmd import _report

    tree = tmp_path / "later.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n    - wait: 2\n    - call: speech.say\n"
                    "      inputs: {text: hi}\n")
    log_path, run = recorded(str(tree), sim_defs, tmp_path, lambda m: None)
    _report(run.result, "later")
    live = [line for line in capsys.readouterr().out.splitlines() if line.startswith("  +")]
    shown = io.StringIO()
    replay = Replay(read_log(log_path))
    while replay.next(None) is not None:
        pass
    replay_summary(replay, shown)
    replayed = [line for line in shown.getvalue().splitlines() if line.startswith("  +")]
    assert live[0].startswith("  +  2.000s  speech.say") and replayed[0].startswith("  +  2.000s  speech.say")


def test_max_duration_halts_show_in_the_log(sim_defs, tmp_path):
    from coordinator.runner import Display

    log_path, run = recorded(GO, sim_defs, tmp_path, lambda m: m["navigation.go_to"].hang(), max_duration=5.0)
    log = read_log(log_path)
    assert log.end["status"] == "FAILURE" and log.end["reason"] == "stopped after 5 s while 'go to the kitchen' was running"
    ids = {n["name"]: n["id"] for n in log.tree["nodes"]}
    last = log.of_type("tick")[-1]
    assert [ids["go to the kitchen"], "INVALID"] in last["changes"] and last["t"] >= 5.0
    replay = Replay(log)
    shown = io.StringIO()
    display = Display(shown, tty=False)
    while replay.next(display) is not None:
        pass
    assert "HALTED    go to the kitchen" in shown.getvalue()


# run log -----------------------------------------------------------------------------------------------
def test_the_log_has_every_kind_of_record(sim_defs, tmp_path):
    log_path, run = recorded(GO, sim_defs, tmp_path, blocked_once)
    log = read_log(log_path)
    tree = log.tree
    assert tree["v"] == 1 and tree["name"] == "go_kitchen" and tree["path"] == os.path.abspath(GO)
    kinds = {n["name"]: n for n in tree["nodes"]}
    assert kinds["go to the kitchen"]["kind"] == "call" and kinds["go to the kitchen"]["line"] == 12
    assert kinds["go to the kitchen"]["target"] == "navigation.go_to"
    assert tree["nodes"][0]["parent"] is None and tree["nodes"][0]["kind"] == "sequence"
    starts = log.of_type("call_start")
    assert [s["target"] for s in starts] == ["speech.say", "navigation.go_to"]
    assert starts[1]["inputs"] == {"place": "kitchen"}
    assert starts[1]["node"] == kinds["go to the kitchen"]["id"]
    ends = log.of_type("call_end")
    assert ends[1]["status"] == "failed" and ends[1]["error"] == "blocked" and ends[1]["answer"] == "failed"
    ticks = log.of_type("tick")
    assert all(t["changes"] for t in ticks)  # only ticks that changed something
    failed = [c for t in ticks for c in t["changes"] if c[1] == "FAILURE"]
    assert failed[0] == [kinds["go to the kitchen"]["id"], "FAILURE", "navigation.go_to failed: blocked"]
    assert log.end["status"] == "FAILURE"
    assert log.end["reason"] == "go to the kitchen: navigation.go_to failed: blocked"
    assert run.reason == log.end["reason"]


def test_stream_flushes_every_tick_and_closes_at_the_end(sim_defs):
    sink = Lines()
    t = TreeTest(os.path.join(TREES, "find_apple.yaml"), definitions=sim_defs)
    t.mocks["vision.find_object"].succeed(success=True, room="kitchen")
    run = t.run(observers=[RunStream([sink])])
    assert sink.flushes >= run.result.ticks and sink.closed
    channels = {c for c, _ in sink.records}
    assert channels == {"tree", "status", "calls", "blackboard", "end"}
    writes = [r for c, r in sink.records if c == "blackboard"]
    assert {"key": "object_room", "value": "kitchen"}.items() <= writes[-1].items()


def test_a_cut_last_line_is_dropped_and_a_bad_line_is_skipped_with_a_warning(sim_defs, tmp_path):
    log_path, _ = recorded(GO, sim_defs, tmp_path, lambda m: None)
    with open(log_path) as fh:
        lines = fh.read().splitlines()
    cut = tmp_path / "cut.jsonl"
    cut.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][: len(lines[-1]) // 2])
    log = read_log(str(cut))
    assert log.truncated and log.end is None and len(log.records) == len(lines) - 1
    bad = tmp_path / "bad.jsonl"
    bad.write_text(lines[0] + "\n{oops\n" + lines[1] + "\n")
    log = read_log(str(bad))
    assert len(log.records) == 2 and log.skipped == 1
    assert log.warning_lines()[0].startswith("warning: %s:2: not a JSON record" % bad)
    other = tmp_path / "other.jsonl"
    other.write_text('{"type": "tick"}\n')
    with pytest.raises(RunLogError, match="not a bmtree run log"):
        read_log(str(other))


def test_retention_keeps_the_newest_runs(tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_HOME", str(tmp_path))
    runs = tmp_path / "bmtree" / "runs"
    runs.mkdir(parents=True)
    for i in range(5):
        (runs / ("2026010%d-120000-abcdef-t.jsonl" % i)).write_text("{}\n")
        (runs / ("2026010%d-120000-abcdef-t.sim" % i)).mkdir()
    (runs / "notes.txt").write_text("mine")
    files = plan_run_files("trees/x.yaml", None, False, 3)
    left = sorted(os.listdir(runs))
    assert left == ["20260103-120000-abcdef-t.jsonl", "20260103-120000-abcdef-t.sim",
                    "20260104-120000-abcdef-t.jsonl", "20260104-120000-abcdef-t.sim", "notes.txt"]
    assert files.log_path.startswith(str(runs)) and files.sim_dir == files.log_path[:-len(".jsonl")] + ".sim"
    assert plan_run_files("x.yaml", str(tmp_path / "mine.jsonl"), False, 3).log_path == str(tmp_path / "mine.jsonl")
    assert plan_run_files("x.yaml", None, True, 3).log_path is None
    with pytest.raises(RunLogError, match="at least 1"):
        plan_run_files("x.yaml", None, False, 0)
    assert prune(str(runs), 1)  # the newest stays
    assert sorted(os.listdir(runs)) == ["20260104-120000-abcdef-t.jsonl", "20260104-120000-abcdef-t.sim", "notes.txt"]


def test_record_and_scenario_never_write_into_a_users_file(sim_defs, tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_HOME", str(tmp_path))
    tree = tmp_path / "mine.yaml"
    shutil.copy(GO, str(tree))
    before = tree.read_text()
    with pytest.raises(RunLogError, match="the file exists and is not a bmtree run log; bmtree does not write"):
        plan_run_files(str(tree), str(tree), False, 3)
    log_path, _run = recorded(GO, sim_defs, tmp_path, lambda m: None)
    again = plan_run_files(str(tree), log_path, False, 3)  # an earlier run's log is replaced
    assert again.log_path == log_path and not os.path.exists(log_path)
    log_path, _run = recorded(GO, sim_defs, tmp_path, lambda m: None)
    with pytest.raises(RunLogError, match="was not written by 'bmtree replay --scenario'; bmtree does not overwrite"):
        write_scenario(read_log(log_path), str(tree))
    assert tree.read_text() == before
    out = tmp_path / "again.scenarios.yaml"
    write_scenario(read_log(log_path), str(out))
    write_scenario(read_log(log_path), str(out))  # its own earlier scenario is rewritten
    assert out.read_text().startswith("# Written by 'bmtree replay")
    empty = tmp_path / "from-mktemp.yaml"  # a file made empty beforehand (mktemp) is the user's choice of name
    empty.write_text("")
    write_scenario(read_log(log_path), str(empty))
    assert empty.read_text().startswith("# Written by 'bmtree replay")
    empty_log = tmp_path / "from-mktemp.jsonl"
    empty_log.write_text("")
    assert plan_run_files(str(tree), str(empty_log), False, 3).log_path == str(empty_log)


def test_a_damaged_run_log_is_an_error_that_says_where_and_runs_lists_the_others(sim_defs, tmp_path, capsys):
    """A log whose tree record is unusable is refused (exit 2), saying where and why; a bad later line
    is skipped with a warning naming it, and the rest is shown."""
    log_path, _run = recorded(GO, sim_defs, tmp_path, lambda m: None)
    lines = open(log_path).read().splitlines()
    runs = tmp_path / "runs"
    runs.mkdir()
    shutil.copy(log_path, str(runs / "20260101-120000-aaaaaa-good.jsonl"))
    bad = {"b-deep": ["[" * 100000 + "]" * 100000] + lines[1:],
           "c-started": [json.dumps(dict(json.loads(lines[0]), started="abc"))] + lines[1:],
           "d-board": [json.dumps(dict(json.loads(lines[0]), blackboard=[1]))] + lines[1:],
           "e-end": lines[:-1] + [json.dumps(dict(json.loads(lines[-1]), duration="x"))]}
    for n, (name, content) in enumerate(sorted(bad.items())):
        (runs / ("2026010%d-120000-bbbbbb-%s.jsonl" % (n + 2, name))).write_text("\n".join(content) + "\n")
    assert [(r.name, r.status) for r in list_runs(str(runs))] == [("go_kitchen", "SUCCESS"),
                                                                   ("go_kitchen", "UNFINISHED")]
    says = {"b-deep": ":1: a record nested deeper than 100 levels, too deep to be bmtree's",
            "c-started": ":1: 'started' of the tree record must be a Unix time, got 'abc'",
            "d-board": ":1: 'blackboard' of the tree record must be a mapping, got [1]"}
    for n, (name, message) in enumerate(sorted(says.items())):
        path = str(runs / ("2026010%d-120000-bbbbbb-%s.jsonl" % (n + 2, name)))
        for extra in ([], ["--at", "0.1"], ["--scenario", str(tmp_path / "out.yaml")]):
            assert cli.main(["replay", path] + extra) == 2
            assert capsys.readouterr().err == "error: %s%s\n" % (path, message)
    path = str(runs / "20260105-120000-bbbbbb-e-end.jsonl")
    assert cli.main(["replay", path]) == 0
    out, err = capsys.readouterr()
    assert err == "warning: %s:%d: 'duration' of the end record must be a number of seconds, got 'x' (line skipped)\n" % (
        path, len(lines))
    assert "go_kitchen: UNFINISHED" in out


def test_retention_keeps_or_drops_a_runs_log_and_sim_folder_together(tmp_path):
    """A run without --sim has no .sim folder, a run with --no-record no log: the newest N runs
    keep both of their files, whatever the others have."""
    runs = tmp_path / "runs"
    runs.mkdir()
    (runs / "20260101-120000-aaaaaa-go.jsonl").write_text("{}\n")
    (runs / "20260101-120000-aaaaaa-go.sim").mkdir()
    (runs / "20260102-120000-bbbbbb-go.jsonl").write_text("{}\n")  # no --sim
    (runs / "20260103-120000-cccccc-go.sim").mkdir()  # --sim --no-record
    (runs / "20260104-120000-dddddd-go.jsonl").write_text("{}\n")
    (runs / "20260104-120000-dddddd-go.sim").mkdir()
    gone = prune(str(runs), 2)
    assert sorted(os.path.basename(p) for p in gone) == [
        "20260101-120000-aaaaaa-go.jsonl", "20260101-120000-aaaaaa-go.sim", "20260102-120000-bbbbbb-go.jsonl"]
    assert sorted(os.listdir(runs)) == ["20260103-120000-cccccc-go.sim", "20260104-120000-dddddd-go.jsonl",
                                        "20260104-120000-dddddd-go.sim"]


# replay ------------------------------------------------------------------------------------------------
def _args(**kw):
    base = dict(run="", dir=None, at=None, step=False, failure=False, scenario=None, speed=None)
    base.update(kw)
    return types.SimpleNamespace(**base)


def shown_live_and_replayed(path, sim_defs, tmp_path):
    """Run ``path`` (navigation blocked once) with the live display and a log; (what the display
    showed, what the replay of the log shows, the log's path)."""
    from coordinator.runner import Display

    live = io.StringIO()
    t = TreeTest(path, definitions=sim_defs)
    blocked_once(t.mocks)
    log = str(tmp_path / "run.jsonl")
    t.run(observers=[RunStream([RunLogWriter(log, fsync=False)]), Display(live, tty=False)])
    replay = Replay(read_log(log))
    shown = io.StringIO()
    display = Display(shown, tty=False)
    while replay.next(display) is not None:
        pass
    return live.getvalue(), shown.getvalue(), log


def test_replay_of_a_retried_failure_prints_its_reason_as_the_live_display_did(sim_defs, tmp_path):
    live, shown, _log = shown_live_and_replayed(GO_RETRY, sim_defs, tmp_path)
    assert "FAILURE   navigation.go_to (navigation.go_to failed: blocked)" in live
    assert shown == live


def test_replay_prints_what_the_live_display_printed(sim_defs, tmp_path, capsys):
    live, shown, log = shown_live_and_replayed(GO, sim_defs, tmp_path)
    assert "FAILURE   go to the kitchen (navigation.go_to failed: blocked)" in shown
    assert shown == live  # the same view as while it ran
    log_path = log
    assert cmd_replay(_args(run=log_path)) == 0
    out = capsys.readouterr().out
    assert "go_kitchen: FAILURE" in out and "reason: go to the kitchen: navigation.go_to failed: blocked" in out
    assert cmd_replay(_args(run=log_path, speed=1000.0)) == 0  # paced: the same lines
    assert capsys.readouterr().out == out


def test_replay_at_a_moment_and_at_the_failure(sim_defs, tmp_path, capsys):
    log_path, _ = recorded(GO, sim_defs, tmp_path, lambda m: m["navigation.go_to"].script(fail("blocked", delay=4.0)))
    assert cmd_replay(_args(run=log_path, at=2.0)) == 0
    out = capsys.readouterr().out
    assert "at 2.000s" in out and "navigation.go_to" in out and "since" in out and '{"place": "kitchen"}' in out
    assert "go to the kitchen [" in out
    assert cmd_replay(_args(run=log_path, failure=True)) == 0
    out = capsys.readouterr().out
    assert "the failure that ended the run, at 4.0" in out and "'go to the kitchen' (" in out
    assert "go_kitchen.yaml:12" in out and "calls in flight: none" in out
    assert cmd_replay(_args(run=log_path, step=True)) == 0
    assert "--- tick 1 at" in capsys.readouterr().out


def test_replay_failure_goes_to_the_failure_that_ended_the_run_not_one_the_tree_recovered_from(sim_defs, tmp_path,
                                                                                                  capsys):
    def blocked_twice_then_mute(m):
        m["navigation.go_to"].script(fail("blocked"), succeed(room="kitchen", delay=1.0))
        m["speech.say"].script(succeed(), fail("speaker unplugged"))

    log_path, run = recorded(GO_RETRY, sim_defs, tmp_path, blocked_twice_then_mute)
    assert run.status == Status.FAILURE
    assert cmd_replay(_args(run=log_path, failure=True)) == 0
    out = capsys.readouterr().out
    assert "the failure that ended the run, at 1.0" in out and "'arrived' (" in out and "speaker unplugged" in out, out
    assert "before it, the tree recovered from or went on past 1 failure:\n  +  0.000s  'navigation.go_to' (" in out, out
    assert "blocked (recovered: 'go to the kitchen' [retry] succeeded after it)" in out, out
    assert "arrived [✕]" in out and "take a message to the kitchen [✕]" in out, out  # the state after that tick

    (tmp_path / "ok").mkdir()
    log_path, run = recorded(GO_RETRY, sim_defs, tmp_path / "ok", blocked_once)
    assert run.status == Status.SUCCESS
    assert cmd_replay(_args(run=log_path, failure=True)) == 0
    out = capsys.readouterr().out
    assert "the run succeeded; the tree recovered from 1 failure, the first at 0.000s: 'navigation.go_to'" in out
    # drawn as it was at that failure, not after the retry restarted it in the same tick
    assert "navigation.go_to [✕]" in out, out


def test_replay_failure_of_an_interrupted_run_shows_what_ran_when_it_was_stopped(sim_defs, tmp_path, capsys):
    t = TreeTest(GO, definitions=sim_defs)
    t.mocks["navigation.go_to"].script(succeed(room="kitchen", delay=4.0))
    log = str(tmp_path / "run.jsonl")
    with pytest.raises(KeyboardInterrupt):
        t.run(observers=[RunStream([RunLogWriter(log, fsync=False)]), CtrlC(2.0)])
    assert cmd_replay(_args(run=log, failure=True)) == 0
    out = capsys.readouterr().out
    assert "no leaf's failure ended this run: interrupted while 'go to the kitchen' was running (at 2." in out, out
    assert "the state at its last tick before it was stopped, at 0.000s:" in out, out
    assert "go to the kitchen [*]" in out and "navigation.go_to" in out.split("calls in flight (interrupted at 2.")[1], out
    runs = tmp_path / "runs"
    runs.mkdir()
    shutil.copy(log, str(runs / "20260101-120000-aaaaaa-go_kitchen.jsonl"))
    assert cli.main(["runs", "--dir", str(runs)]) == 0
    listed = capsys.readouterr().out.splitlines()[-1]
    assert " INTERRUPTED " in listed and "INVALID" not in listed, listed  # py_trees' word stays in the log


def test_find_run_by_number_name_and_last(sim_defs, tmp_path):
    runs = tmp_path / "runs"
    runs.mkdir()
    log_path, _ = recorded(GO, sim_defs, tmp_path, lambda m: None)
    for name in ("20260101-100000-aaaaaa-go.jsonl", "20260102-100000-bbbbbb-go.jsonl"):
        shutil.copy(log_path, str(runs / name))
    assert find_run("last", str(runs)).endswith("bbbbbb-go.jsonl")
    assert find_run("2", str(runs)).endswith("aaaaaa-go.jsonl")
    assert find_run("20260101", str(runs)).endswith("aaaaaa-go.jsonl")
    with pytest.raises(RunLogError, match="2 recorded runs"):
        find_run("3", str(runs))
    assert [r.status for r in list_runs(str(runs))] == ["SUCCESS", "SUCCESS"]


def test_cli_replay_of_a_bad_file_exits_2(tmp_path, capsys):
    bad = tmp_path / "x.jsonl"
    bad.write_text("not json\n{}\n")
    assert cli.main(["replay", str(bad)]) == 2
    assert "x.jsonl:1: not a JSON record" in capsys.readouterr().err
    assert cli.main(["runs", "--dir", str(tmp_path)]) == 0   # a folder with no run logs
    assert "no recorded runs" in capsys.readouterr().out


def test_replay_into_a_pipe_its_reader_closed_ends_quietly(sim_defs, tmp_path):
    """`bmtree replay last | head -1`: a closed output is not bmtree's error (exit 0, no message)."""
    import subprocess
    import sys

    log_path, _ = recorded(GO, sim_defs, tmp_path, lambda m: None)
    p = subprocess.Popen([sys.executable, "-m", "coordinator", "replay", log_path, "--speed", "4"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    p.stdout.readline()
    p.stdout.close()  # as `head -1` does, long before the replay's last line
    err = p.stderr.read().decode()
    assert p.wait(timeout=60) == 0 and err == "", err


# scenarios from runs -----------------------------------------------------------------------------------
def test_scenario_from_a_run_passes_and_a_changed_tree_shows_the_changed_calls(sim_defs, tmp_path):
    tree = tmp_path / "go_kitchen.yaml"
    shutil.copy(GO, str(tree))
    def script(m):
        m["navigation.go_to"].script(fail("blocked", delay=1.5), succeed(room="kitchen"))
        m.event(0.5, "navigation.arrived", place="hall")

    log_path, run = recorded(str(tree), sim_defs, tmp_path, script)
    out_path = str(tmp_path / "replayed.yaml")
    write_scenario(read_log(log_path), out_path)
    text = open(out_path).read()
    assert "fail: blocked" in text and "delay: 1.5" in text and "navigation.arrived" in text
    out = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, out) == [True], out.getvalue()
    shutil.copy(GO_RETRY, str(tree))  # the fix: retry the navigation
    out = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, out) == [False]
    report = out.getvalue()
    assert "expected 2 calls, got 4" in report and "calls changed" in report
    diff = [line.strip() for line in report.splitlines() if line.strip()[:2] in ("= ", "+ ", "- ")]
    assert diff == ['= speech.say {"text": "I am going to the kitchen."}', '= navigation.go_to {"place": "kitchen"}',
                    '+ navigation.go_to {"place": "kitchen"}', '+ navigation.go_to {"place": "kitchen"}']


RECALLS = """format: 1
name: where was it
root:
  sequence:
    - recall: {last_room: vision/find_object/room}
    - call: navigation.go_to
      inputs: {place: $last_room}
    - recall: {arrived: navigation/go_to/room}
    - call: speech.say
      inputs: {text: "I am in the {arrived}"}
"""


def test_a_scenario_from_a_run_gives_the_values_recalled_from_earlier_runs_and_only_those(sim_defs, tmp_path):
    """A recall of a value an earlier run stored could not succeed in the run's scenario: the log
    keeps where each recalled value came from, and the scenario stores those no call of the run made."""
    tree = tmp_path / "recalls.yaml"
    tree.write_text(RECALLS)

    def script(m):
        m.stored({"vision/find_object/room": "kitchen"})
        m["navigation.go_to"].succeed(room="kitchen")

    log_path, run = recorded(str(tree), sim_defs, tmp_path, script)
    assert run.succeeded, run.reason
    recalls = read_log(log_path).of_type("recall")
    assert [v["name"] for r in recalls for v in r["values"]] == ["vision/find_object/room", "navigation/go_to/room"]
    first, second = recalls[0]["values"][0], recalls[1]["values"][0]
    assert first["value"] == "kitchen" and first["call_id"] not in {c.call_id for c in run.calls()}
    assert second["call_id"] == run.calls("navigation.go_to")[0].call_id
    out_path = str(tmp_path / "replayed.yaml")
    write_scenario(read_log(log_path), out_path)
    scenario = yaml.safe_load(open(out_path))["scenarios"][0]
    assert scenario["stored"] == {"vision/find_object/room": "kitchen"}  # not the run's own result
    out = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, out) == [True], out.getvalue()


def test_a_killed_run_becomes_a_scenario_of_what_the_tree_saw_until_its_last_tick(sim_defs, tmp_path):
    def slow_navigation(m):
        m["navigation.go_to"].script(succeed(room="kitchen", delay=4.0))

    log_path, _ = recorded(GO, sim_defs, tmp_path, slow_navigation)
    records = [json.loads(line) for line in open(log_path).read().splitlines()]
    nav = next(i for i, r in enumerate(records) if r["type"] == "call_start" and r["target"] == "navigation.go_to")
    tick = next(i for i in range(nav, len(records)) if records[i]["type"] == "tick")
    # killed two seconds into the navigation: the log ends with the records of a later tick,
    # and an answer that came after it, which the tree never ticked on
    later = dict(records[tick], t=records[tick]["t"] + 2.0, n=records[tick]["n"] + 1, changes=[])
    answer = next(r for r in records if r["type"] == "call_end" and r["target"] == "navigation.go_to")
    cut = tmp_path / "killed.jsonl"
    cut.write_text("\n".join(json.dumps(r) for r in records[:tick + 1] + [later, answer]) + "\n")
    out_path = str(tmp_path / "killed.yaml")
    write_scenario(read_log(str(cut)), out_path)
    text = open(out_path).read()
    assert "it was killed" in text and "hang: true" in text, text
    scenario = yaml.safe_load(text)["scenarios"][0]
    assert scenario["max_duration"] == pytest.approx(later["t"], abs=1e-6)
    assert scenario["expect"]["status"] == "failure"
    assert [list(c) for c in scenario["expect"]["calls"]] == [["speech.say"], ["navigation.go_to"]]
    out = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, out) == [True], out.getvalue()

    before_any_tick = tmp_path / "early.jsonl"
    before_any_tick.write_text(json.dumps(records[0]) + "\n")
    with pytest.raises(RunLogError, match="no end record and no tick"):
        write_scenario(read_log(str(before_any_tick)), str(tmp_path / "s.yaml"))


def test_an_interrupted_run_becomes_a_scenario_that_passes_and_replay_says_how_to_test_it(sim_defs, tmp_path,
                                                                                          capsys):
    t = TreeTest(GO, definitions=sim_defs)
    t.mocks["navigation.go_to"].script(succeed(room="kitchen", delay=4.0))
    log = str(tmp_path / "run.jsonl")
    defs_dir = tmp_path / "defs"
    defs_dir.mkdir()
    stream = RunStream([RunLogWriter(log, fsync=False)], {"inputs": {}, "modules": [str(defs_dir)]})
    with pytest.raises(KeyboardInterrupt):
        t.run(observers=[stream, CtrlC(2.0)])
    assert read_log(log).end["status"] == "INVALID"
    out_path = str(tmp_path / "interrupted.yaml")
    assert cmd_replay(_args(run=log, scenario=out_path)) == 0
    said = capsys.readouterr().out
    assert "(run it with: bmtree test %s)" % out_path in said, said   # its modules: are in the file
    text = open(out_path).read()
    assert "was interrupted (interrupted while 'go to the kitchen' was running)" in text and "hang: true" in text, text
    scenario = yaml.safe_load(text)["scenarios"][0]
    assert scenario["expect"]["status"] == "failure" and scenario["max_duration"] >= 2.0
    out = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, out) == [True], out.getvalue()


def test_replay_says_which_modules_a_scenario_needs_that_the_run_had_from_the_live_graph(sim_defs, tmp_path, capsys):
    log_path, _ = recorded(GO, sim_defs, tmp_path, lambda m: None)
    records = [json.loads(line) for line in open(log_path)]
    for n in records[0]["nodes"]:
        if n.get("target") == "navigation.go_to":
            n["target"] = "wheels.go_to"
    changed = tmp_path / "live.jsonl"
    changed.write_text("".join(json.dumps(r) + "\n" for r in records))
    assert cmd_replay(_args(run=str(changed), scenario=str(tmp_path / "s.yaml"))) == 0
    assert "adding --modules with the definition of wheels (the run had it from the live graph)" in \
        capsys.readouterr().out


def test_a_malformed_record_is_a_clear_error(sim_defs, tmp_path, capsys):
    log_path, _ = recorded(GO, sim_defs, tmp_path, lambda m: None)
    lines = open(log_path).read().splitlines()
    bad = tmp_path / "bad.jsonl"
    bad.write_text("\n".join([lines[0], '{"v":1,"type":"tick","t":0.1,"changes":[[[1],"BOGUS"]]}'] + lines[1:]) + "\n")
    assert cli.main(["replay", str(bad)]) == 0   # the line is skipped, the rest shown
    out, err = capsys.readouterr()
    assert "bad.jsonl:2: a change of the tick record is not [node id, status, why?] of a node of the tree" in err
    assert "go_kitchen: SUCCESS" in out


def test_a_timeout_says_what_was_still_running(sim_defs, tmp_path):
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n  timeout: 5\n  name: reach the kitchen in time\n"
                    "  child:\n    call: navigation.go_to\n    name: drive\n    inputs: {place: kitchen}\n")
    t = TreeTest(str(tree), definitions=sim_defs)
    t.mocks["navigation.go_to"].hang()
    run = t.run()
    assert run.reason == "reach the kitchen in time: timed out after 5s while 'drive' was running"


def test_a_scenario_is_refused_for_a_run_whose_outcome_a_person_forced(sim_defs, tmp_path):
    log_path, _run = recorded(GO, sim_defs, tmp_path, lambda m: None)
    lines = open(log_path).read().splitlines()
    run_id = json.loads(lines[0])["run"]

    def control(command, args):
        return json.dumps({"v": 1, "type": "control", "run": run_id, "t": 0.5, "command": command, "args": args,
                           "ok": True, "answer": "ok"})

    paused = tmp_path / "paused.jsonl"
    paused.write_text("\n".join(lines[:-1] + [control("pause", {}), lines[-1]]) + "\n")
    write_scenario(read_log(str(paused)), str(tmp_path / "paused.yaml"))  # pausing changes no outcome
    forced = tmp_path / "forced.jsonl"
    forced.write_text("\n".join(lines[:-1] + [control("force", {"node": "go to the kitchen", "outcome": "FAILURE"}),
                                              lines[-1]]) + "\n")
    with pytest.raises(RunLogError, match=r"the run was steered \(1 forced outcome or blackboard write, the first at "
                                          r"0.500s: force go to the kitchen FAILURE\); a scenario replays"):
        write_scenario(read_log(str(forced)), str(tmp_path / "forced.yaml"))
    assert not (tmp_path / "forced.yaml").exists()


def test_a_paused_run_times_its_calls_by_their_answers_and_replay_shows_the_control(sim_defs, tmp_path, capsys):
    """Paused at 0.5 s while go_to runs (it answers at 2.5 s), resumed at 10 s: the call took 2 s, not 9.5 s;
    the live display, the run log, replay's summary and a replay at 5 s show who paused it."""
    from coordinator.builder import build_tree
    from coordinator.clock import SimClock
    from coordinator.context import RunContext
    from coordinator.control import Controller
    from coordinator.language import load_tree
    from coordinator.runner import Display, TreeRunner
    from coordinator.testing.inprocess import InProcessTransport
    from coordinator.testing.mocks import Mocks

    mocks = Mocks(sim_defs)
    mocks["navigation.go_to"].script(succeed(room="kitchen", delay=2.0))
    clock = SimClock()
    ctx = RunContext(InProcessTransport(mocks, clock), clock, sim_defs)
    tree = load_tree(GO, sim_defs)
    control = Controller(True)
    clock.call_later(0.5, lambda: control.submit({"command": "pause", "by": "/tester"}))
    # a refused command while paused: --at named it as what paused the run
    clock.call_later(2.0, lambda: control.submit({"command": "force", "by": "/other", "args": {"node": "nowhere",
                                                                                             "outcome": "SUCCESS"}}))
    clock.call_later(10.0, lambda: control.submit({"command": "resume", "by": "/tester"}))
    live = io.StringIO()
    log = str(tmp_path / "run.jsonl")
    result = TreeRunner(build_tree(tree, ctx, {}), ctx, observers=[RunStream([RunLogWriter(log, fsync=False)]), control,
                                                                    Display(live, tty=False)],
                        tree=tree, gate=control).run(60.0)
    assert result.status == Status.SUCCESS and result.duration >= 10.0
    go = [c for c in result.calls if c.target == "navigation.go_to"][0]
    assert go.duration == pytest.approx(2.0, abs=0.3) and go.ended >= 10.0
    assert "CONTROL   pause by /tester: paused: no node starts" in live.getvalue()
    assert "CONTROL   resume by /tester: resumed" in live.getvalue()
    ends = [r for r in read_log(log).records if r.get("type") == "call_end" and r["target"] == "navigation.go_to"]
    assert ends[0]["duration"] == pytest.approx(2.0, abs=0.3)
    assert cmd_replay(_args(run=log)) == 0
    out = capsys.readouterr().out
    assert "control:\n  +  0.500s  pause by /tester: paused" in out and "+ 10.000s  resume by /tester: resumed" in out
    assert "CONTROL   pause by /tester" in out   # the replayed display shows it where the live one did
    assert cmd_replay(_args(run=log, at=5.0)) == 0
    at = capsys.readouterr().out
    assert "paused by control (pause by /tester: paused" in at and "paused by control (force" not in at, at


def test_a_quiet_run_keeps_touching_its_log_and_a_killed_run_lists_how_long_it_lived(tmp_path, monkeypatch):
    """Only changes are logged: a run killed after a quiet minute used to list as 0.00s."""
    import os
    import time as _time

    from coordinator import runlog
    from tests.conftest import until

    monkeypatch.setattr(runlog, "HEARTBEAT", 0.05)
    path = str(tmp_path / "runs" / "20261125-120000-abc123-quiet.jsonl")
    writer = RunLogWriter(path, fsync=False)
    started = _time.time() - 30.0
    writer.write("tree", json.dumps({"v": 1, "type": "tree", "run": "abc123", "t": 0.0, "started": started,
                                     "name": "quiet", "nodes": []}))
    writer.write("status", json.dumps({"v": 1, "type": "tick", "run": "abc123", "t": 0.001, "n": 1, "changes": []}))
    writer.flush()
    until(lambda: os.path.exists(path) and os.path.getsize(path) > 0)
    written = os.path.getmtime(path)
    until(lambda: os.path.getmtime(path) > written + 0.1)  # touched while nothing is written
    writer.close()
    os.utime(path, (started + 12.0, started + 12.0))  # killed 12 s in
    [run] = list_runs(str(tmp_path / "runs"))
    assert run.status == "UNFINISHED" and abs(run.duration - 12.0) < 0.01


def test_replay_draws_a_switch_with_its_cases(sim_defs, tmp_path, capsys):
    """A composite of none of py_trees' shapes was recorded as a leaf: replay and watch drew the
    switch without the case that ran under it."""
    tree = tmp_path / "choose.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n    - set: {answer: 'yes'}\n    - switch: $answer\n"
                    "      name: act on the answer\n      cases:\n        'yes': {call: speech.say, inputs: {text: great},"
                    " name: say great}\n      default: {call: speech.say, inputs: {text: sorry}, name: say sorry}\n")
    log_path, run = recorded(str(tree), sim_defs, tmp_path, lambda m: None)
    assert run.succeeded, run.reason
    assert [n["shape"] for n in read_log(log_path).tree["nodes"] if n["name"] == "act on the answer"] == ["composite"]
    assert cmd_replay(_args(run=log_path, at=99.0)) == 0
    out = capsys.readouterr().out
    drawn = out[out.index("act on the answer"):]
    assert "say great [✓]" in drawn and "say sorry [-]" in drawn, out


def test_find_run_by_the_start_bmtree_runs_shows(sim_defs, tmp_path, capsys):
    """The file name has the process's start, ``bmtree runs`` the first tick's (seconds later with --sim):
    the time shown finds the run, as the README says the start of its name does."""
    import datetime
    import json

    runs = tmp_path / "runs"
    runs.mkdir()
    log_path, _ = recorded(GO, sim_defs, tmp_path, lambda m: None)
    lines = open(log_path).read().splitlines()
    head = json.loads(lines[0])
    head["started"] = datetime.datetime(2026, 1, 1, 10, 0, 3).timestamp()   # 3 s after the name's time
    (runs / "20260101-100000-aaaaaa-go.jsonl").write_text("\n".join([json.dumps(head)] + lines[1:]) + "\n")
    assert cli.main(["runs", "--dir", str(runs)]) == 0
    assert "2026-01-01 10:00:03" in capsys.readouterr().out
    for ref in ("20260101-100003", "2026-01-01 10:00:03", "20260101-100000"):
        assert find_run(ref, str(runs)).endswith("aaaaaa-go.jsonl"), ref
    with pytest.raises(RunLogError, match="no runs"):
        find_run("20260101-100004", str(runs))
