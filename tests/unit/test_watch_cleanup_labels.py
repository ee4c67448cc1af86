"""What a viewer sees of a tree's cleanup and of includes, without ROS: the run's own summary, the
watch's state, views and line printer, ``replay``'s report; and halts in the kit's statuses."""
from __future__ import annotations

import io

import pytest
from rich.console import Console

from coordinator.replay import Replay
from coordinator.replay import _report as replay_report
from coordinator.runevents import Display, IncludeArgs, include_label, status_word
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runner import summary_lines
from coordinator.runstream import RunStream
from coordinator.testing.kit import TreeTest
from coordinator.testing.mocks import hang, succeed
from coordinator.watchstate import WatchState
from coordinator.watchtext import result_text
from coordinator.watchtext import summary_lines as watch_summary
from coordinator.watchview import LinePrinter, render
from tests.stopkit import GO_CLEANUP, GO_ROOT, CtrlC, Kept

TREE = GO_ROOT + GO_CLEANUP


def _interrupted_run(tmp_path, sim_defs, where_am_i):
    path = tmp_path / "go.yaml"
    path.write_text(TREE)
    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].hang()
    t.mocks["navigation.where_am_i"].script(where_am_i)
    log_path = str(tmp_path / "run.jsonl")
    kept = Kept()
    with pytest.raises(KeyboardInterrupt):
        t.run(observers=[CtrlC(3.0), kept, RunStream([RunLogWriter(log_path, fsync=False)])])
    return kept.result, read_log(log_path)


def _watched(log):
    state, out = WatchState(), io.StringIO()
    printer = LinePrinter(out)
    for rec in [log.tree] + log.records[1:]:
        state.apply(rec)
        printer.record(rec, state)
    return state, out.getvalue()


def _screen(state, width=110, height=40):
    console = Console(width=width, record=True, force_terminal=False)
    console.print(render(state, width, height))
    return console.export_text()


def test_an_interrupted_run_with_a_cleanup_as_the_summary_watch_and_replay_show_it(tmp_path, sim_defs):
    result, log = _interrupted_run(tmp_path, sim_defs, succeed(2.0))
    lines = summary_lines(result, "go")
    assert lines[1].startswith("go: INTERRUPTED in 5.00 s (")
    assert "cleanup (root stopped): succeeded in 2.00 s" in lines
    assert log.end["status"] == "INVALID"   # the record keeps py_trees' word
    state, printed = _watched(log)
    assert "[  3.000s] cleanup   interrupted while 'navigation.go_to' was running: running the cleanup" in printed
    assert ("end       INTERRUPTED: interrupted while 'navigation.go_to' was running; cleanup (root stopped): "
            "succeeded in 2.00 s") in printed
    shown = _screen(state)
    assert "bmtree watch go  t=5.0s" in shown and "INTERRUPTED" in shown.splitlines()[0]
    assert "go [with_cleanup]" in shown and "+ cleanup [sequence]  SUCCESS" in shown
    assert result_text(log.end).startswith("result: INTERRUPTED in 5.00s")
    assert result_text(log.end).endswith("cleanup (root stopped): succeeded in 2.00 s")
    assert watch_summary(state)[-1] == "cleanup (root stopped): succeeded in 2.00 s"
    view = state.view()
    assert view["cleanup"] == "cleanup (root stopped): succeeded in 2.00 s"
    replay = Replay(log)
    while replay.next(None) is not None:
        pass
    report = io.StringIO()
    replay_report(replay, report)
    text = report.getvalue()
    assert "go: INTERRUPTED in 5.00 s" in text
    assert "the ROS graph:" not in text
    assert "the cleanup:\n  +  3.000s  interrupted while 'navigation.go_to' was running: running the cleanup" in text


def test_the_pending_calls_during_the_cleanup_are_the_cleanups(tmp_path, sim_defs):
    _result, log = _interrupted_run(tmp_path, sim_defs, succeed(2.0))
    state = WatchState()
    for rec in [log.tree] + log.records[1:]:
        state.apply(rec)
        if rec.get("type") == "call_start" and rec.get("target") == "navigation.where_am_i":
            break
    assert state.pending_title() == "pending calls of the cleanup (root stopped)"
    assert "pending calls of the cleanup (root stopped)" in _screen(state)
    assert state.view()["pending_title"] == "pending calls of the cleanup (root stopped)"
    assert WatchState().pending_title() == "pending calls"


def test_a_cleanup_call_halted_by_the_cleanups_time_limit_says_so(tmp_path, sim_defs):
    result, log = _interrupted_run(tmp_path, sim_defs, hang())
    limit = "navigation.where_am_i      halted        4.000s  did not end within 4 s (cleanup_timeout)"
    assert any(line.endswith(limit) for line in summary_lines(result, "go")), summary_lines(result, "go")
    replay = Replay(log)
    while replay.next(None) is not None:
        pass
    report = io.StringIO()
    replay_report(replay, report)
    text = report.getvalue()
    assert limit in text and "halted by the tree" not in text
    assert "the cleanup:" in text and "the cleanup failed (root stopped): did not end within 4 s" in text
    state, printed = _watched(log)
    assert "[  7.000s] cleanup   the cleanup failed (root stopped)" in printed
    assert "cleanup (root stopped): FAILED in 4.00 s: did not end within 4 s (cleanup_timeout)" in _screen(state, 200)


def test_status_word():
    assert status_word("INVALID") == "INTERRUPTED" and status_word("FAILURE") == "FAILURE"


def test_include_label_says_the_values_bounded():
    assert include_label("fetch_item(item=$item)", {"item": "milk"}) == 'fetch_item(item="milk")'
    assert include_label("fetch_item(item=$item, n=2)", {"item": "x" * 100}) == 'fetch_item(item="%s…, n=2)' % (
        "x" * 38)
    assert include_label("fetch_item(item=$item)", None) == "fetch_item(item=$item)"
    many = include_label("f(%s)" % ", ".join("k%d=$v" % k for k in range(20)), {"k%d" % k: "y" * 30 for k in range(20)})
    assert len(many) <= 160 and many.endswith("…)")


def test_a_write_that_comes_after_its_tick_still_names_the_include():
    """Over ROS the blackboard and status topics are not ordered between them."""
    args = IncludeArgs({5: 4})
    args.tick([[5, "SUCCESS"]], 1.0)
    args.write("room", "kitchen", 0.5)   # the write of that tick, come late
    args.write("room", "bedroom", 1.5)   # a later one: not the include's
    assert args.name(4, "search_room(room=$room)") == 'search_room(room="kitchen")'


def test_includes_show_their_values_live_in_watch_and_in_replay(tmp_path, sim_defs):
    log_path = str(tmp_path / "run.jsonl")
    live = io.StringIO()
    t = TreeTest("trees/find_apple.yaml", definitions=sim_defs)
    t.mocks["vision.find_object"].fail_first(1, "not here")
    t.run(observers=[RunStream([RunLogWriter(log_path, fsync=False)]), Display(live, tty=False)])
    assert 'RUNNING   search_room(room="living_room", object="apple")' in live.getvalue()
    assert 'RUNNING   search_room(room="kitchen", object="apple")' in live.getvalue()
    assert "$room" not in live.getvalue()
    log = read_log(log_path)
    state, printed = _watched(log)
    assert 'search_room(room="kitchen", object="apple") [include]' in _screen(state)
    assert 'RUNNING   search_room(room="kitchen", object="apple")' in printed and "$room" not in printed  # --plain
    include = next(n["id"] for n in log.tree["nodes"] if n["kind"] == "include")
    assert state.view()["labels"] == {str(include): 'search_room(room="kitchen", object="apple")'}
    late = WatchState()   # a watch that attaches late loads the values from a snapshot
    late.apply(log.tree)
    late.apply(state.snapshot())
    assert late.name(include) == 'search_room(room="kitchen", object="apple")'
    replay, shown = Replay(log), io.StringIO()
    display = Display(shown, tty=False)
    while replay.next(display) is not None:
        pass
    assert shown.getvalue() == live.getvalue()


HALTS = """format: 1
name: halts
root:
  retry: 2
  child:
    timeout: 1
    child:
      call: navigation.go_to
      name: drive
      inputs: {place: kitchen}
"""


def test_statuses_show_a_halt_and_a_restart(tmp_path, sim_defs):
    path = tmp_path / "halts.yaml"
    path.write_text(HALTS)
    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].script(succeed(5.0), succeed(0.5))
    run = t.run()
    assert run.succeeded
    assert run.statuses("drive") == ["RUNNING", "INVALID", "RUNNING", "SUCCESS"]   # halted by the timeout
    stopped = TreeTest(str(path), definitions=sim_defs)
    stopped.mocks["navigation.go_to"].hang()
    run = stopped.run(max_duration=0.5)
    assert run.statuses("drive") == ["RUNNING", "INVALID"]   # halted by the stop from outside
