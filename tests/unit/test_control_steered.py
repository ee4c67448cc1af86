"""A run that ``bmtree control`` steered (a forced outcome, a blackboard write) says so under its result, in
``bmtree run``'s summary, the run log's ``end`` record, ``replay``'s report and the watch's last lines: a
SUCCESS an operator forced is not the tree's own."""
from __future__ import annotations

import io

from coordinator.replay import _report
from coordinator.replaystate import Replay
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runner import summary_lines
from coordinator.runstream import RunStream
from coordinator.testing.kit import TreeTest
from coordinator.watchstate import WatchState
from coordinator.watchtext import result_text
from coordinator.watchtext import summary_lines as watch_lines
from tests.unit.test_control_stop import Timed, _run, go  # noqa: F401 - fixtures

TREE = """format: 1
name: fetch
inputs:
  room: {default: kitchen}
root:
  sequence:
    - call: navigation.go_to
      inputs: {place: "{room}"}
    - call: speech.say
      inputs: {text: "{room}"}
"""


def _force(t: float, node: str, outcome: str, by: str = "/operator") -> tuple:
    return t, {"id": "f", "command": "force", "node": node, "outcome": outcome, "by": by}


def test_a_forced_success_and_a_write_are_said_under_the_result_and_in_the_log(tmp_path, monkeypatch, sim_defs):
    path = tmp_path / "fetch.yaml"
    path.write_text(TREE)
    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].hang()
    log = str(tmp_path / "run.jsonl")
    control = Timed([(1.0, {"id": "s", "command": "set", "key": "room", "value": "hall", "by": "/operator"}),
                     _force(2.0, "navigation.go_to", "SUCCESS")])
    run = _run(t, control, monkeypatch, observers=[RunStream([RunLogWriter(log, fsync=False)])])
    assert run.succeeded
    steered = ["1.00s blackboard room = \"hall\" by /operator",
               "2.00s 'navigation.go_to' forced to SUCCESS by /operator"]
    assert run.result.steered == steered
    lines = summary_lines(run.result, "fetch")
    assert lines[1].startswith("fetch: SUCCESS in 2.00 s")
    assert lines[2:4] == ["steered: " + s for s in steered] and lines[4] == "calls:", lines
    end = read_log(log).end
    assert end is not None and end["steered"] == steered
    out = io.StringIO()
    _report(Replay(read_log(log)), out)
    assert "steered: 2.00s 'navigation.go_to' forced to SUCCESS by /operator\n" in out.getvalue(), out.getvalue()
    assert result_text(end).endswith("  steered: " + "; ".join(steered))   # the live views' result line
    state = WatchState()
    state.tree, state.nodes, state.end = {"name": "fetch"}, [{"id": 0}], end
    assert watch_lines(state)[1:3] == ["steered: " + s for s in steered], watch_lines(state)


def test_a_pause_is_said_with_its_length_and_who_paused(go, monkeypatch, tmp_path):  # noqa: F811 - the fixture
    """An operator's stray key froze a robot 18.7 s and the run's summary and replay --failure never said so:
    the calls' timeouts kept counting meanwhile."""
    from coordinator.replay import _jump_to_failure

    go.mocks["navigation.go_to"].succeed(room="kitchen", delay=1.0)
    log = str(tmp_path / "run.jsonl")
    run = _run(go, Timed([(0.5, {"id": "p", "command": "pause", "by": "/bmtree_watch_1"}),
                          (0.7, {"id": "r", "command": "resume"})]), monkeypatch,
               observers=[RunStream([RunLogWriter(log, fsync=False)])])
    assert run.succeeded and run.result.steered == ["0.50s paused 0.2 s by /bmtree_watch_1"], run.result.steered
    assert "steered: 0.50s paused 0.2 s by /bmtree_watch_1" in summary_lines(run.result, "go")
    out = io.StringIO()
    _jump_to_failure(Replay(read_log(log)), out)
    assert "steered: 0.50s paused 0.2 s by /bmtree_watch_1\n" in out.getvalue(), out.getvalue()


def test_a_run_nobody_steered_says_nothing_of_it(go, monkeypatch):  # noqa: F811 - the fixture
    go.mocks["navigation.go_to"].succeed(room="kitchen", delay=1.0)
    run = _run(go, Timed([]), monkeypatch)
    assert run.succeeded and run.result.steered == []
    assert not [line for line in summary_lines(run.result, "go") if line.startswith("steered")]
