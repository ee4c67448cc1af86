"""Finding out why a run failed: the live reason, the end-of-run summary and ``replay --failure`` agree
on the failure, show what the failing call was asked, say when a run was stopped or last seen alive,
and draw the tree as it was after the failure's tick (no ROS master)."""
from __future__ import annotations

import io
import json
import os

import pytest
from py_trees.common import Status

from coordinator.replay import Replay, cmd_replay
from coordinator.replay import _report as replay_summary
from coordinator.runlog import RunLogWriter, list_runs, read_log
from coordinator.runner import summary_lines
from coordinator.runstream import RunStream
from coordinator.testing.kit import TreeTest
from coordinator.testing.mocks import fail, succeed
from tests.conftest import TREES
from tests.unit.test_recording import GO, GO_RETRY, CtrlC, _args, recorded

FIND_APPLE = os.path.join(TREES, "find_apple.yaml")


def _failure(log_path: str, capsys) -> str:
    assert cmd_replay(_args(run=log_path, failure=True)) == 0
    return capsys.readouterr().out


def _summary(log_path: str) -> str:
    shown = io.StringIO()
    replay = Replay(read_log(log_path))
    while replay.next(None) is not None:
        pass
    replay_summary(replay, shown)
    return shown.getvalue()


def _camera_down(sim_defs, tmp_path):
    return recorded(FIND_APPLE, sim_defs, tmp_path,
                    lambda m: m["vision.find_object"].fail("camera driver not responding"))


def test_replay_failure_names_the_node_the_reason_names_not_force_failure(sim_defs, tmp_path, capsys):
    """The shipped demo: every room's look fails, the fallback says so under a force_failure. The reason
    named the vision call, --failure named the force_failure."""
    log_path, run = _camera_down(sim_defs, tmp_path)
    assert run.reason == "look for the object: vision.find_object failed: camera driver not responding"
    out = _failure(log_path, capsys)
    head = out.splitlines()[1]
    assert head.startswith("the failure that ended the run, at 0.000s: 'look for the object' (trees/search_room.yaml:19)"), out
    assert "force_failure" not in head and "camera driver not responding" in head, out


def test_the_live_reason_and_replay_choose_the_failure_by_one_rule(sim_defs, tmp_path):
    log_path, run = _camera_down(sim_defs, tmp_path)
    replay = Replay(read_log(log_path))
    ended, _others = replay.failures()
    assert replay.nodes[ended.node]["name"] == "look for the object"
    assert ended.message == "vision.find_object failed: camera driver not responding"


def test_failures_a_for_each_went_on_past_are_listed_with_the_arguments_they_had(sim_defs, tmp_path, capsys):
    log_path, _run = _camera_down(sim_defs, tmp_path)
    out = _failure(log_path, capsys)
    assert "before it, the tree recovered from or went on past 3 failures:" in out, out
    earlier = out.split("went on past 3 failures:\n")[1].splitlines()[:3]
    for line, room in zip(earlier, ["living_room", "kitchen", "dining_room"]):
        assert "'look for the object' (trees/search_room.yaml:19) in search_room(room=\"%s\", object=\"apple\")" % room \
            in line, out
        assert line.endswith("(moved past: 'visit rooms until the apple is seen' [for_each] went on)"), out
    # the include in the tree, with the values its arguments had, not "$room"
    assert "search_room(room=\"bedroom\", object=\"apple\") [✕]" in out and "$room" not in out, out


def test_the_failing_calls_inputs_show_in_the_failure_view_and_both_summaries(sim_defs, tmp_path, capsys):
    log_path, run = _camera_down(sim_defs, tmp_path)
    out = _failure(log_path, capsys)
    assert "the failing call:\n  +  0.000s  vision.find_object         failed        0.000s  camera driver not " \
           "responding  inputs {\"object\":\"apple\"}" in out, out
    live = summary_lines(run.result, "find_apple")
    with_inputs = [line for line in live if "inputs" in line]
    assert len(with_inputs) == 1 and with_inputs[0].endswith('camera driver not responding  inputs {"object":"apple"}')
    assert with_inputs[0].startswith("  +  0.000s  vision.find_object")
    replayed = [line for line in _summary(log_path).splitlines() if line.startswith("  +")]
    assert replayed == [line for line in live if line.startswith("  +")]


def test_long_inputs_are_cut_on_the_failing_calls_line(sim_defs, tmp_path):
    tree = tmp_path / "long.yaml"
    tree.write_text("format: 1\nroot:\n  call: speech.say\n  inputs: {text: %s}\n" % ("x" * 300))
    log_path, run = recorded(str(tree), sim_defs, tmp_path, lambda m: m["speech.say"].fail("muted"))
    [line] = [line for line in summary_lines(run.result, "long") if line.startswith("  +") and "inputs" in line]
    assert line.endswith("…") and len(line.split("inputs ", 1)[1]) == 60


def test_a_timeout_is_drawn_after_its_tick_the_halted_call_halted_not_running(sim_defs, tmp_path, capsys):
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n    name: errand\n    children:\n      - timeout: 5\n"
                    "        name: reach the kitchen in time\n        child:\n          call: navigation.go_to\n"
                    "          name: drive\n          inputs: {place: kitchen}\n")
    log_path, run = recorded(str(tree), sim_defs, tmp_path, lambda m: m["navigation.go_to"].hang())
    assert run.reason == "reach the kitchen in time: timed out after 5s while 'drive' was running"
    out = _failure(log_path, capsys)
    assert "the failure that ended the run, at 5.000s: 'reach the kitchen in time'" in out, out
    assert "drive [-] -- halted" in out and "drive [*]" not in out, out
    assert "errand [✕]" in out and "calls in flight: none" in out, out
    assert "navigation.go_to           halted" in out and 'inputs {"place":"kitchen"}' in out, out


def test_a_parallel_branch_halted_by_the_others_failure_is_drawn_halted(sim_defs, tmp_path, capsys):
    tree = tmp_path / "p.yaml"
    tree.write_text("format: 1\nroot:\n  parallel:\n    name: both\n    children:\n      - call: speech.say\n"
                    "        name: talk\n        inputs: {text: hi}\n      - call: navigation.go_to\n"
                    "        name: drive\n        inputs: {place: kitchen}\n")

    def script(m):
        m["speech.say"].hang()
        m["navigation.go_to"].script(fail("blocked", delay=1.0))

    log_path, run = recorded(str(tree), sim_defs, tmp_path, script)
    assert run.status == Status.FAILURE
    out = _failure(log_path, capsys)
    assert "'drive'" in out.splitlines()[1] and "talk [-] -- halted" in out and "both [✕]" in out, out
    assert "calls in flight: none" in out and "[*]" not in out, out


def test_a_run_stopped_by_its_time_limit_names_no_earlier_failure_as_its_end(sim_defs, tmp_path, capsys):
    """The first attempt failed, the second still ran at the limit: the limit ended the run."""
    def script(m):
        m["navigation.go_to"].script(fail("blocked"), succeed(delay=60.0))

    log_path, run = recorded(GO_RETRY, sim_defs, tmp_path, script, max_duration=5.0)
    assert run.reason == "stopped after 5 s while 'navigation.go_to' was running"
    out = _failure(log_path, capsys)
    assert "the failure that ended the run" not in out, out
    assert "no leaf's failure ended this run: stopped after 5 s while 'navigation.go_to' was running (at 5.000s)" in out
    assert "calls in flight (stopped at 5.000s):" in out, out
    summary = _summary(log_path)
    assert "navigation.go_to           halted        5.000s  stopped after 5 s" in summary, summary


def test_ctrl_c_says_when_and_labels_its_calls_interrupted(sim_defs, tmp_path, capsys):
    t = TreeTest(GO, definitions=sim_defs)
    t.mocks["navigation.go_to"].script(succeed(room="kitchen", delay=4.0))
    log = str(tmp_path / "run.jsonl")
    with pytest.raises(KeyboardInterrupt):
        t.run(observers=[RunStream([RunLogWriter(log, fsync=False)]), CtrlC(2.0)])
    out = _failure(log, capsys)
    assert "no leaf's failure ended this run: interrupted while 'go to the kitchen' was running (at 2." in out, out
    assert "the state at its last tick before it was stopped, at 0.000s:" in out, out
    summary = _summary(log)
    assert "navigation.go_to           interrupted" in summary and "halted by the tree" not in summary, summary


def test_the_live_summary_says_interrupted_for_calls_ctrl_c_halted(sim_defs):
    from coordinator.builder import build_tree
    from coordinator.clock import SimClock
    from coordinator.context import RunContext
    from coordinator.language import load_tree
    from coordinator.runner import TreeRunner
    from coordinator.testing.inprocess import InProcessTransport
    from coordinator.testing.mocks import Mocks

    mocks = Mocks(sim_defs)
    mocks["navigation.go_to"].script(succeed(room="kitchen", delay=4.0))
    clock = SimClock()
    ctx = RunContext(InProcessTransport(mocks, clock), clock, sim_defs)
    tree = load_tree(GO, sim_defs)
    runner = TreeRunner(build_tree(tree, ctx, {}), ctx, observers=[CtrlC(2.0)], tree=tree)
    with pytest.raises(KeyboardInterrupt):
        runner.run(60.0)
    lines = summary_lines(runner.result, "go_kitchen")
    go = [line for line in lines if "navigation.go_to" in line]
    assert go and "interrupted" in go[0] and "halted by the tree" not in go[0], lines


def test_a_killed_run_says_when_it_was_last_seen_alive_as_runs_does(sim_defs, tmp_path, capsys):
    log_path, _run = recorded(GO, sim_defs, tmp_path, lambda m: m["navigation.go_to"].hang(), max_duration=1.0)
    records = [json.loads(line) for line in open(log_path)]
    last_tick = max(i for i, r in enumerate(records) if r["type"] == "tick" and r["t"] < 1.0)
    runs = tmp_path / "runs"
    runs.mkdir()
    killed = runs / "20260101-120000-abcdef-go_kitchen.jsonl"
    killed.write_text("".join(json.dumps(r) + "\n" for r in records[:last_tick + 1]))
    started = records[0]["started"]
    os.utime(str(killed), (started + 3.0, started + 3.0))  # the heartbeat touched it until 3 s in
    [listed] = list_runs(str(runs))
    assert listed.status == "UNFINISHED" and abs(listed.duration - 3.0) < 0.01
    summary = _summary(str(killed))
    assert "go_kitchen: UNFINISHED: last seen alive at 3.00s" in summary, summary
    assert "the log ends at" not in summary
    out = _failure(str(killed), capsys)
    assert "the process was killed (or lost power) at about 3.00s, when it was last seen alive" in out, out
    assert "the state at its last tick, at 0.000s:" in out, out


def test_the_run_that_succeeded_shows_its_first_recovered_failure_with_its_call(sim_defs, tmp_path, capsys):
    log_path, run = recorded(GO_RETRY, sim_defs, tmp_path,
                             lambda m: m["navigation.go_to"].script(fail("blocked"), succeed(room="kitchen")))
    assert run.succeeded
    out = _failure(log_path, capsys)
    assert "the run succeeded; the tree recovered from 1 failure, the first at 0.000s: 'navigation.go_to'" in out
    assert 'navigation.go_to           failed        0.000s  blocked  inputs {"place":"kitchen"}' in out, out
    assert "navigation.go_to [✕]" in out, out


UNNAMED = """format: 1
name: unnamed_steps
root:
  sequence:
    name: take a message to the kitchen
    children:
      - sequence:
          - call: speech.say
            inputs: {text: "going"}
          - call: navigation.go_to
            inputs: {place: kitchen}
"""


@pytest.mark.parametrize("named", [True, False])
def test_the_reason_names_the_nearest_named_node_not_a_bare_kind(sim_defs, tmp_path, named):
    """An unnamed call sits in an unnamed sequence: the reason said 'sequence: navigation.go_to failed',
    which tells nothing; it names the nearest node with a name of its own, or none."""
    text = UNNAMED if named else UNNAMED.replace("    name: take a message to the kitchen\n", "")
    path = tmp_path / "unnamed.yaml"
    path.write_text(text)
    t = TreeTest(str(path), sim_defs)
    t.mocks["navigation.go_to"].fail("blocked")
    run = t.run()
    assert run.status == Status.FAILURE
    said = "navigation.go_to failed: blocked"
    assert run.reason == ("take a message to the kitchen: " + said if named else said)


def test_the_summary_says_where_the_failure_is_written_and_which_include_it_was_in(sim_defs, tmp_path):
    """``reason:`` says what failed; ``at:`` says where it is written (an editor's FILE:LINE:COLUMN) and, in
    a subtree, with which arguments it was included: the fourth room's look failed, not the first's."""
    _log, run = _camera_down(sim_defs, tmp_path)
    lines = summary_lines(run.result, "find_apple")
    at = lines[lines.index("reason: " + run.reason) + 1]
    assert at.startswith("at: ") and at.endswith('search_room.yaml:19:9 in search_room(room="bedroom", object="apple")'), lines
    assert run.result.failed_at == at[len("at: "):]


def test_a_failed_cleanup_says_where_its_failure_is_written_and_a_success_says_nothing(sim_defs, tmp_path):
    from tests.unit.test_cleanup_runs import TREE

    path = tmp_path / "go.yaml"
    path.write_text(TREE)
    line = TREE.splitlines().index("    - call: navigation.where_am_i") + 1
    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].fail("blocked")
    t.mocks["navigation.where_am_i"].fail("lost")
    lines = summary_lines(t.run().result, "go")
    cleanup = next(i for i, x in enumerate(lines) if x.startswith("cleanup (root failed): FAILED"))
    assert lines[cleanup + 1] == "  at: %s:%d:7" % (path, line), lines
    go = [x for x in lines if x.startswith("at: ")]
    assert len(go) == 1 and go[0].startswith("at: %s:" % path), lines
    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    assert not [x for x in summary_lines(t.run().result, "go") if "at: " in x]


def test_replay_and_watch_say_where_the_failure_and_the_cleanups_are_written(sim_defs, tmp_path):
    """The run log's end record keeps ``at``: the replay's report and the watch's last lines say it as the
    run's summary did, for root's failure and for the cleanup's."""
    from coordinator.watchstate import WatchState
    from coordinator.watchtext import summary_lines as watch_lines
    from tests.unit.test_cleanup_runs import TREE

    def watched(log_path):
        state = WatchState()
        for rec in read_log(log_path).records:
            state.apply(rec)
        return watch_lines(state)

    log_path, run = _camera_down(sim_defs, tmp_path)
    at = "at: " + run.result.failed_at
    assert run.result.failed_at and at in _summary(log_path).splitlines() and at in watched(log_path)
    path = tmp_path / "go.yaml"
    path.write_text(TREE)
    (tmp_path / "go").mkdir()
    log_path, run = recorded(str(path), sim_defs, tmp_path / "go", lambda m: (m["navigation.go_to"].succeed(room="kitchen"),
                                                                       m["navigation.where_am_i"].fail("lost")))
    line = TREE.splitlines().index("    - call: navigation.where_am_i") + 1
    for lines in (_summary(log_path).splitlines(), watched(log_path)):
        cleanup = [i for i, x in enumerate(lines) if x.startswith("cleanup (root succeeded): FAILED")]
        assert len(cleanup) == 1, lines
        assert lines[cleanup[0] + 1] == "  at: %s:%d:7" % (path, line), lines
        assert not [x for x in lines if x.startswith("at: ")], lines  # root succeeded: nothing of its own


def test_a_named_include_says_its_name_and_the_values_it_was_included_with(sim_defs, tmp_path):
    """A name given to an include hid the values: ``at: go.yaml:6:3 in go to the door`` (which door?)."""
    (tmp_path / "go.yaml").write_text("format: 1\nname: go\ninputs:\n  place: {}\nroot:\n  call: navigation.go_to\n"
                                      "  inputs: {place: $place}\n")
    (tmp_path / "t.yaml").write_text("format: 1\nname: t\nroot:\n  include: go.yaml\n  name: go to the door\n"
                                     "  args: {place: garage}\n")
    t = TreeTest(str(tmp_path / "t.yaml"), sim_defs)
    t.mocks["navigation.go_to"].fail("blocked")
    run = t.run()
    assert run.result.failed_at == '%s:6:3 in go to the door (place="garage")' % (tmp_path / "go.yaml"), \
        run.result.failed_at
