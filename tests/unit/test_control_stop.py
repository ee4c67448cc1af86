"""``bmtree control stop`` (another node preempts the task): the runner stops root as ``--max-duration``
does, its cleanup runs with ``ended`` = stopped, also when the run was paused (no ROS, a simulated clock)."""
from __future__ import annotations

from typing import Any, Dict, List, Tuple

import pytest

from coordinator.control import COMMANDS, Controller, parse_command
from coordinator.runevents import RunObserver
from coordinator.runner import shown_status
from coordinator.testing import kit
from coordinator.testing.kit import TreeTest
from tests.stopkit import GO_ROOT, Kept
from tests.unit.test_cleanup_runs import TREE


class Timed(Controller):
    """A Controller given commands at run times (seconds since the start), as a node would send them:
    also while paused, when nothing is ticked; ``signal_at``: a Ctrl-C lands then."""

    def __init__(self, script: List[Tuple[float, Dict[str, Any]]], signal_at: float = -1.0):
        self.replies: List[Dict[str, Any]] = []
        super().__init__(True, reply=self.replies.append)
        self.script, self.signal_at = list(script), signal_at
        self.records: List[Dict[str, Any]] = []

    def may_tick(self) -> bool:
        now = self.ctx.clock.now() - self.ctx.started
        while self.script and self.script[0][0] <= now:
            self.submit(dict(self.script.pop(0)[1]))
        if 0 <= self.signal_at <= now:
            self.signal_at = -1.0
            raise KeyboardInterrupt
        return super().may_tick()

    def answers(self) -> List[Tuple[str, bool, str]]:
        return [(str(r["id"]), r["ok"], r["answer"]) for r in self.replies]


class Controls(RunObserver):
    """The run's ``control`` records (as the run stream and the run log get them)."""

    def __init__(self) -> None:
        self.records: List[Dict[str, Any]] = []

    def on_control(self, record: Dict[str, Any], now: float) -> None:
        self.records.append(dict(record, t=now))


def _stop(t: float, by: str = "/smach_supervisor", cid: str = "stop") -> Tuple[float, Dict[str, Any]]:
    return t, {"id": cid, "command": "stop", "by": by}


def _run(test: TreeTest, control: Timed, monkeypatch: Any, **kwargs: Any) -> Any:
    """The kit's run with ``control`` as the runner's gate and an observer, as ``bmtree run --control`` has it."""
    real = kit.TreeRunner
    monkeypatch.setattr(kit, "TreeRunner", lambda *a, **k: real(*a, gate=control, **k))
    records = Controls()
    run = test.run(observers=[control, records, *kwargs.pop("observers", [])], **kwargs)
    run.control_records = records.records
    return run


@pytest.fixture
def go(tmp_path, sim_defs):
    path = tmp_path / "go.yaml"
    path.write_text(GO_ROOT)
    return TreeTest(str(path), definitions=sim_defs)


@pytest.fixture
def go_cleanup(tmp_path, sim_defs):
    path = tmp_path / "go_cleanup.yaml"
    path.write_text(TREE)
    return TreeTest(str(path), definitions=sim_defs)


def test_stop_is_a_command():
    assert "stop" in COMMANDS and parse_command(["stop"]) == {"command": "stop"}
    with pytest.raises(ValueError, match="usage: stop"):
        parse_command(["stop", "now"])


def test_a_stop_ends_the_run_as_a_time_limit_does_naming_who_stopped_it(go, monkeypatch):
    go.mocks["navigation.go_to"].hang()
    control = Timed([_stop(2.0)])
    run = _run(go, control, monkeypatch)
    assert control.answers() == [("stop", True, "stopping: the running nodes are halted and their calls cancelled")]
    assert run.failed and run.result.status.value == "FAILURE"   # as --max-duration: exit 1 from bmtree run
    assert run.reason == "stopped by control (/smach_supervisor) while 'navigation.go_to' was running"
    assert run.result.duration == pytest.approx(2.0) and run.result.stopped_at == pytest.approx(2.0)
    call = run.calls("navigation.go_to")[0]
    assert call.status == "halted"
    assert shown_status(run.result, call) == ("halted", "stopped by control (/smach_supervisor)")
    assert [(r["command"], r["ok"], r["by"]) for r in run.control_records] == [("stop", True, "/smach_supervisor")]
    assert run.targets == ["navigation.go_to"]   # nothing ticked after the stop: 'arrived' never said


def test_a_stop_halts_root_then_the_cleanup_runs_told_who_stopped_it(go_cleanup, monkeypatch):
    go_cleanup.mocks["navigation.go_to"].hang()
    go_cleanup.mocks["navigation.where_am_i"].succeed(delay=2.0)
    control = Timed([_stop(1.0), _stop(1.5, by="/other", cid="again")])
    run = _run(go_cleanup, control, monkeypatch)
    why = "stopped by control (/smach_supervisor) while 'navigation.go_to' was running"
    assert run.failed and run.reason == why and run.ended == "stopped"
    assert run.blackboard["ended_reason"] == why
    assert [c.inputs["text"] for c in run.cleanup_calls("speech.say")] == ["stopped: " + why]
    assert run.cleanup_status == "SUCCESS"   # the second stop did not cut it short
    assert control.answers() == [
        ("stop", True, "stopping: root is halted and its calls cancelled, then the cleanup runs (at most 10 s)"),
        ("again", False, "root was stopped already (stopped by control (/smach_supervisor)) and its cleanup is "
                         "running: a stop does not cut the cleanup short (it ends within 9.5 s, its cleanup_timeout; "
                         "Ctrl-C in the run's terminal ends it at once)")]
    assert [(r["command"], r["ok"], r["by"]) for r in run.control_records] == [
        ("stop", True, "/smach_supervisor"), ("stop", False, "/other")]


def test_a_stop_while_paused_ends_the_pause_so_that_the_cleanup_runs(go_cleanup, monkeypatch):
    go_cleanup.mocks["navigation.go_to"].succeed(room="kitchen", delay=5.0)
    go_cleanup.mocks["navigation.where_am_i"].succeed(delay=1.0)
    control = Timed([(0.5, {"id": "pause", "command": "pause"}), _stop(3.0)])
    run = _run(go_cleanup, control, monkeypatch)
    assert control.answers()[1] == ("stop", True, "stopping: root is halted and its calls cancelled, then the cleanup "
                                                  "runs (at most 10 s); the pause ends")
    assert run.ended == "stopped" and run.reason.startswith("stopped by control (/smach_supervisor)")
    assert run.cleanup_status == "SUCCESS" and run.result.duration == pytest.approx(4.0)   # not cut at 10 s
    assert not control.paused and run.control_records[-1]["paused"] is False   # the viewers stop showing PAUSED


def test_a_stop_once_root_ended_by_itself_is_refused(go_cleanup, monkeypatch):
    go_cleanup.mocks["navigation.go_to"].fail("blocked", delay=1.0)
    go_cleanup.mocks["navigation.where_am_i"].succeed(delay=3.0)
    control = Timed([_stop(2.0)])
    run = _run(go_cleanup, control, monkeypatch)
    assert control.answers() == [("stop", False, "root has ended (failed) and its cleanup is running: a stop does not "
                                                 "cut the cleanup short (it ends within 9 s, its cleanup_timeout; "
                                                 "Ctrl-C in the run's terminal ends it at once)")]
    assert run.reason == "navigation.go_to failed: blocked" and run.ended == "failed" and run.cleanup_status == "SUCCESS"


def test_two_stops_at_once_the_second_is_refused(go, monkeypatch):
    go.mocks["navigation.go_to"].hang()
    control = Timed([_stop(1.0), _stop(1.0, by="/other", cid="again")])
    run = _run(go, control, monkeypatch)
    assert control.answers()[1] == ("again", False, "the run is stopping already")
    assert run.reason.startswith("stopped by control (/smach_supervisor) while")


def test_a_stop_from_an_unknown_sender_still_reads_as_a_sentence(go, monkeypatch):
    go.mocks["navigation.go_to"].hang()
    run = _run(go, Timed([(1.0, {"id": "stop", "command": "stop"})]), monkeypatch)
    assert run.reason == "stopped by control while 'navigation.go_to' was running"


def test_a_stop_to_a_run_without_control_is_refused(go):
    control = Controller(False)
    control.root = object()
    assert control._apply({"command": "stop"}) == (
        False, "control is not enabled for this run (start it with 'bmtree run --control')")
    assert control.take_stop() == ""


def test_ctrl_c_while_paused_ends_the_pause_so_that_the_cleanup_runs(go_cleanup, monkeypatch):
    """As a stop does: else the cleanup would wait out its cleanup_timeout without a tick."""
    go_cleanup.mocks["navigation.go_to"].succeed(room="kitchen", delay=5.0)
    go_cleanup.mocks["navigation.where_am_i"].succeed(delay=1.0)
    control = Timed([(0.5, {"id": "pause", "command": "pause"})], signal_at=2.0)
    kept = Kept()
    with pytest.raises(KeyboardInterrupt):
        _run(go_cleanup, control, monkeypatch, observers=[kept])
    result = kept.result
    assert result.ended == "stopped" and result.reason.startswith("interrupted while")
    assert str(result.cleanup_status.value) == "SUCCESS" and result.duration == pytest.approx(3.0)
    assert not control.paused
