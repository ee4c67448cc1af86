"""A run stopped from outside (Ctrl-C, ``--max-duration``) as the watch shows it, without ROS: the calls
the stop halted say so as ``bmtree run``'s summary and ``bmtree replay`` do (``interrupted``, not "halted
by the tree"), in the terminal's call log, the ``--plain`` lines and the page's JSON; and the top node of
a tree with ``cleanup:`` shows the run's status (INTERRUPTED), not HALTED."""
from __future__ import annotations

import io
import types

import pytest
from py_trees.common import Status
from rich.console import Console

from coordinator.replay import Replay
from coordinator.replay import _report as replay_report
from coordinator.runevents import Display, halted_word, stop_status
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runner import summary_lines
from coordinator.runstream import RunStream
from coordinator.testing.kit import TreeTest
from coordinator.testing.mocks import hang, succeed
from coordinator.watchstate import WatchState
from coordinator.watchview import LinePrinter, render
from tests.stopkit import GO_CLEANUP, GO_ROOT, CtrlC, Kept


def _run(tmp_path, sim_defs, cleanup, ctrl_c, where_am_i=None):
    """The tree (with its cleanup or not) stopped at 3 s by a Ctrl-C or by max_duration: its result,
    its run log and what the live display printed."""
    path = tmp_path / "go.yaml"
    path.write_text(GO_ROOT + (GO_CLEANUP if cleanup else ""))
    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].hang()
    t.mocks["navigation.where_am_i"].script(where_am_i or succeed(1.0))
    log_path, keep, shown = str(tmp_path / "run.jsonl"), Kept(), io.StringIO()
    observers = [keep, RunStream([RunLogWriter(log_path, fsync=False)]), Display(shown, tty=False)]
    if ctrl_c:
        with pytest.raises(KeyboardInterrupt):
            t.run(observers=[CtrlC(3.0)] + observers)
    else:
        t.run(max_duration=3.0, observers=observers)
    return keep.result, read_log(log_path), shown.getvalue()


def _watched(records):
    state, out = WatchState(), io.StringIO()
    printer = LinePrinter(out)
    for rec in records:
        state.apply(rec)
        printer.record(rec, state)
    printer.finish()
    return state, out.getvalue()


def _screen(state, width=120, height=40):
    console = Console(width=width, record=True, force_terminal=False)
    console.print(render(state, width, height))
    return console.export_text()


def _summary_call(result, target):
    return next(line for line in summary_lines(result, "go") if target in line and line.startswith("  +"))


@pytest.mark.parametrize("cleanup", [False, True])
@pytest.mark.parametrize("ctrl_c", [True, False])
def test_the_calls_a_stop_halted_are_labelled_as_the_summary_and_replay_do(tmp_path, sim_defs, cleanup, ctrl_c):
    result, log, _shown = _run(tmp_path, sim_defs, cleanup, ctrl_c)
    status, error = ("interrupted", "") if ctrl_c else ("halted", "stopped after 3 s")
    assert _summary_call(result, "navigation.go_to").split()[3] == status   # the run's own summary
    replay = Replay(log)
    while replay.next(None) is not None:
        pass
    report = io.StringIO()
    replay_report(replay, report)
    assert "halted by the tree" not in report.getvalue()
    state, printed = _watched([log.tree] + log.records[1:])
    go_to = [c for c in state.view()["calls"] if c["target"] == "navigation.go_to"]
    assert [(c["status"], c["error"]) for c in go_to] == [(status, error)]          # the page
    assert [c["status"] for c in state.calls if c["target"] == "navigation.go_to"] == ["halted"]  # the record's
    line = next(x for x in _screen(state).splitlines() if "navigation.go_to" in x and "place kitchen" in x)
    assert line.split()[2] == status and "halted by the tree" not in line          # the terminal
    assert ("[  3.000s] %-9s navigation.go_to %s" % (status, error)).rstrip() + "\n" in printed  # --plain
    assert "halted by the tree" not in printed
    late = WatchState()   # a watch that attaches after the stop loads it from the snapshot
    late.apply(log.tree)
    late.apply(state.snapshot())
    assert [(c["status"], c["error"]) for c in late.view()["calls"] if c["target"] == "navigation.go_to"] == [
        (status, error)]


def test_a_stop_seen_before_its_halted_call_still_labels_it(tmp_path, sim_defs):
    """Over ROS the calls and the ticks come on different topics: the stop's tick may come first."""
    _result, log, _shown = _run(tmp_path, sim_defs, False, True)
    records = list(log.records[1:])
    k = next(i for i, r in enumerate(records) if r["type"] == "call_end" and r["status"] == "halted")
    records.insert(k + 1, records.pop(k))   # the tick after it first
    assert records[k]["type"] == "tick" and records[k + 1]["type"] == "call_end"
    state, printed = _watched([log.tree] + records)
    assert [(c["status"], c["error"]) for c in state.view()["calls"]] == [("interrupted", "")]
    assert "[  3.000s] interrupted navigation.go_to" in printed


def test_a_call_the_tree_halted_itself_stays_halted_by_the_tree(tmp_path, sim_defs):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nname: t\nroot:\n  selector:\n    - timeout: 1\n      child:\n"
                    "        call: navigation.go_to\n        inputs: {place: kitchen}\n"
                    "    - call: speech.say\n      inputs: {text: late}\n")
    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].hang()
    log_path = str(tmp_path / "run.jsonl")
    t.run(observers=[RunStream([RunLogWriter(log_path, fsync=False)])])
    log = read_log(log_path)
    state, printed = _watched([log.tree] + log.records[1:])
    assert ("halted", "halted by the tree") in [(c["status"], c["error"]) for c in state.view()["calls"]]
    assert "[  1.000s] halted    navigation.go_to halted by the tree" in printed


@pytest.mark.parametrize("ctrl_c", [True, False])
def test_the_top_node_of_a_stopped_tree_with_cleanup_shows_the_runs_status(tmp_path, sim_defs, ctrl_c):
    _result, log, shown = _run(tmp_path, sim_defs, True, ctrl_c)
    word = "INTERRUPTED" if ctrl_c else "FAILURE"
    top = next(n["id"] for n in log.tree["nodes"] if n["kind"] == "with_cleanup")
    root = next(n["id"] for n in log.tree["nodes"] if n.get("parent") == top)
    state, printed = _watched([log.tree] + log.records[1:])
    assert state.label(top) == word and state.label(root) == "HALTED"   # root was halted by the stop
    assert state.view()["words"][str(top)] == word                        # the page
    assert "go [with_cleanup]  %s" % word in _screen(state)               # the terminal
    assert "[  4.000s] %-9s go\n" % word in printed                       # --plain (after its cleanup)
    assert "HALTED    go\n" not in printed
    assert "[  4.000s] %-9s go\n" % word in shown                         # bmtree run's lines (and replay's)
    before = WatchState()   # its last tick, before the end: the reason its cleanup read says it
    for rec in [log.tree] + log.records[1:-1]:
        before.apply(rec)
    assert before.end is None and before.label(top) == word
    late = WatchState()
    late.apply(log.tree)
    late.apply(state.snapshot())
    assert late.label(top) == word


def test_a_cleanup_cut_short_labels_its_halted_call_with_why(tmp_path, sim_defs):
    result, log, _shown = _run(tmp_path, sim_defs, True, True, where_am_i=hang())
    limit = ("halted", "did not end within 4 s (cleanup_timeout)")
    assert _summary_call(result, "navigation.where_am_i").split()[3] == "halted"
    state, printed = _watched([log.tree] + log.records[1:])
    shown = {c["target"]: (c["status"], c["error"]) for c in state.view()["calls"]}
    assert shown == {"navigation.go_to": ("interrupted", ""), "speech.say": ("succeeded", ""),
                     "navigation.where_am_i": limit}
    assert "[  7.000s] halted    navigation.where_am_i did not end within 4 s (cleanup_timeout)" in printed
    assert "halted by the tree" not in printed + _screen(state)


def test_halted_word_and_stop_status():
    assert stop_status("interrupted while 'x' was running") == "INVALID"
    assert stop_status("stopped after 60 s while 'x' was running") == "FAILURE"
    # a replay's stand-in for the top node says how root ended as a WithCleanup does
    stand_in = types.SimpleNamespace(name="go", feedback_message="", ended="stopped", ended_reason="interrupted")
    assert halted_word(stand_in) == "INTERRUPTED"
    assert halted_word(types.SimpleNamespace(name="x", feedback_message="")) == "HALTED"
    assert halted_word(types.SimpleNamespace(name="go", ended="failed", ended_reason="boom")) == "HALTED"
    out = io.StringIO()
    display = Display(out, tty=False)
    display.on_tick(None, [(stand_in, Status.RUNNING, Status.INVALID)], 2.5)
    assert out.getvalue() == "[  2.500s] INTERRUPTED go\n"
