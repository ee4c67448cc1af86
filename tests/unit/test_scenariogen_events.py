"""Scenarios from runs keep each event's place among the calls: tied to the call it last followed
(``after``/``nth``/``at``), not at its clock time, which simulated time cannot keep."""
from __future__ import annotations

import io
import json

import pytest
import yaml

from coordinator.runevents import RunObserver
from coordinator.runlog import RunLog, RunLogWriter, read_log
from coordinator.runstream import RunStream
from coordinator.scenariogen import scenario_from_log, write_scenario
from coordinator.testing import TreeTest
from coordinator.testing.mocknode import script_of
from coordinator.testing.mocks import MockError, Mocks
from coordinator.testing.scenario import run_scenario_file
from modules.search import default_definitions

MY = {
    "Basic Module": "my", "Brief Description": "emits an event, then answers", "Hardware Required": [],
    "Functions": [{"Name": "fire", "Exec-condition": "", "Description": "emit done, then answer",
                   "Input-params": [], "Output-params": []},
                  {"Name": "noop", "Exec-condition": "", "Description": "nothing",
                   "Input-params": [], "Output-params": []}],
    "Events": [{"Name": "done", "Description": "fired", "Event-params": []}],
}


def tree_text(noops=20, wait=True):
    lines = ["format: 1", "name: drift", "root:", "  sequence:"]
    lines += ["    - call: my.noop"] * noops + ["    - call: my.fire"]
    if wait:
        lines += ["    - timeout: 1", "      child:", "        wait_event: my.done"]
    return "\n".join(lines) + "\n"


@pytest.fixture
def my(tmp_path):
    path = tmp_path / "my.json"
    path.write_text(json.dumps(MY))
    return str(path)


class Overhead(RunObserver):
    """The tree spends ``cost`` seconds of the run's clock after taking an answer, before it makes
    its next call, as on a robot (a simulated clock alone spends nothing there)."""

    def __init__(self, cost):
        self.cost = cost

    def on_start(self, tree, root, ctx):
        self.clock = ctx.clock

    def on_call_end(self, record):
        self.clock._now += self.cost


def field_run(tmp_path, my, tree, script, cost=0.0002):
    """A run "on the robot" (the tree takes time between calls), recorded to a log."""
    path = tmp_path / "tree.yaml"
    path.write_text(tree)
    t = TreeTest(str(path), definitions=default_definitions([my]))
    script(t.mocks)
    log = str(tmp_path / "run.jsonl")
    run = t.run(observers=[RunStream([RunLogWriter(log, fsync=False)], {"inputs": {}, "modules": [my]}),
                           Overhead(cost)])
    return log, run


def emits_then_answers(mocks):
    """my.fire emits done, then answers 0.2 ms later (a module function that emits, then returns)."""
    mocks["my.noop"].succeed(delay=0.0003)
    mocks["my.fire"].succeed(delay=0.0005)
    mocks.event_after("my.fire", 0.0003, "my.done")


def test_an_event_before_the_answer_of_a_call_stays_before_the_wait_that_follows_the_call(tmp_path, my):
    log, run = field_run(tmp_path, my, tree_text(), emits_then_answers)
    assert run.failed and "timed out after 1s" in run.reason  # the wait_event started after the event
    out_path = str(tmp_path / "replayed.yaml")
    write_scenario(read_log(log), out_path)
    out = io.StringIO()
    assert run_scenario_file(out_path, default_definitions([my]), out) == [True], out.getvalue()
    scenario = yaml.safe_load(open(out_path))["scenarios"][0]
    assert scenario["expect"]["status"] == "failure"
    assert scenario["events"] == [{"event": "my.done", "after": "my.fire", "at": 0.0003}]


def test_at_the_recorded_time_the_event_would_land_after_the_wait_started(tmp_path, my):
    """What the scenario did before: the event at its clock time, 20 calls' overhead too late."""
    log, _ = field_run(tmp_path, my, tree_text(), emits_then_answers)
    out_path = str(tmp_path / "replayed.yaml")
    write_scenario(read_log(log), out_path)
    data = yaml.safe_load(open(out_path))
    event = next(r for r in read_log(log).records if r["type"] == "event")
    data["scenarios"][0]["events"] = [{"at": event["t"], "event": "my.done"}]
    with open(out_path, "w") as fh:
        yaml.safe_dump(data, fh)
    out = io.StringIO()
    assert run_scenario_file(out_path, default_definitions([my]), out) == [False]
    assert "status SUCCESS, expected FAILURE" in out.getvalue()


@pytest.mark.parametrize("at, status", [(0.2, "FAILURE"), (0.5, "FAILURE"), (0.5001, "SUCCESS")])
def test_an_event_after_a_call_comes_before_with_or_after_its_answer(tmp_path, my, at, status):
    tree = tmp_path / "t.yaml"
    tree.write_text(tree_text(noops=1))
    t = TreeTest(str(tree), definitions=default_definitions([my]))
    t.mocks["my.noop"].succeed(delay=1.0)
    t.mocks["my.fire"].succeed(delay=0.5)
    t.mocks.event_after("my.fire", at, "my.done")
    run = t.run()
    assert run.status.value == status, run.reason
    if status == "SUCCESS":
        assert run.duration == pytest.approx(1.5001)


def test_an_event_tied_to_the_nth_call_and_to_a_call_never_made(tmp_path, my):
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n    - call: my.noop\n    - call: my.noop\n"
                    "    - wait_event: my.done\n      timeout: 5\n")
    t = TreeTest(str(tree), definitions=default_definitions([my]))
    t.mocks["my.noop"].succeed(delay=1.0)
    t.mocks.event_after("my.noop", 3.0, "my.done", nth=2)
    run = t.run()
    assert run.succeeded and run.duration == pytest.approx(4.0)
    t.mocks.call_events[:] = []
    t.mocks.event_after("my.fire", 0.0, "my.done")  # the tree never calls it: the event never comes
    run = t.run()
    assert run.failed and "no my.done within 5s" in run.reason
    with pytest.raises(MockError, match=r"tied to a call \(event_after: my.done\) run in process only"):
        script_of(t.mocks, "my")  # a mock node's events count from when the coordinator connected
    with pytest.raises(MockError, match="nth is a whole number >= 1, got 0"):
        t.mocks.event_after("my.noop", 0.0, "my.done", nth=0)
    with pytest.raises(MockError, match=r"no event 'my.dne' in the definitions \(did you mean 'my.done'\?\)"):
        t.mocks.event_after("my.noop", 0.0, "my.dne")
    with pytest.raises(MockError, match="has no function 'fier'"):
        Mocks(t.definitions).event_after("my.fier", 0.0, "my.done")


# where each event is tied, from the records -------------------------------------------------------------
def _log(tmp_path, records, end=True):
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n  wait: 1\n")
    head = {"v": 1, "type": "tree", "run": "r", "t": 0.0, "path": str(tree), "nodes": [], "blackboard": {}}
    tail = [{"v": 1, "type": "tick", "t": 9.0, "n": 9, "changes": []},
            {"v": 1, "type": "end", "t": 9.0, "status": "SUCCESS", "reason": ""}] if end else []
    return RunLog(str(tmp_path / "run.jsonl"), [head] + records + tail)


def start(cid, target, t):
    return {"type": "call_start", "t": t, "call_id": cid, "target": target, "inputs": {}}


def end(cid, target, t, duration, answer="succeeded", status="succeeded"):
    return {"type": "call_end", "t": t, "call_id": cid, "target": target, "status": status, "error": "",
            "outputs": {}, "answer": answer, "duration": duration}


def event(t, name="done"):
    return {"type": "event", "t": t, "module": "my", "event": name, "params": {}}


def events_of(tmp_path, records, end=True):
    return scenario_from_log(_log(tmp_path, records, end), str(tmp_path / "s.yaml"))["scenarios"][0]["events"]


def test_each_event_is_tied_to_the_call_start_or_answer_it_last_followed(tmp_path):
    records = [
        event(0.1),                                      # before any call: its time in the run
        start("a", "my.noop", 1.0),
        event(1.2),                                      # while a runs: before its answer (at 1.5)
        event(1.55),                                     # a's answer came (1.5), the tree had not taken it
        end("a", "my.noop", 1.6, 0.5),
        event(1.7),                                      # after the tick that took a's answer
        start("b", "my.noop", 2.0),                      # my.noop's second call
        start("c", "my.fire", 2.1),                      # in parallel
        event(2.2),                                      # c started last
        end("b", "my.noop", 2.8, 0.7),                   # b answered at 2.7
        event(2.9),                                      # after b's answer, c still running
        end("c", "my.fire", 4.0, 1.0, answer=None, status="timeout"),  # c never answered: it hangs
        event(4.5),                                      # b's answer is still the last start or answer
        start("d", "my.fire", 5.0),                      # never answered
        event(7.5),
    ]
    assert events_of(tmp_path, records) == [
        {"event": "my.done", "at": 0.1},
        {"event": "my.done", "after": "my.noop", "at": 0.2},
        {"event": "my.done", "after": "my.noop", "at": 0.5},       # with the answer, not after it
        {"event": "my.done", "after": "my.noop", "at": 0.7},
        {"event": "my.done", "after": "my.fire", "at": 0.1},
        {"event": "my.done", "after": "my.noop", "nth": 2, "at": 0.9},
        {"event": "my.done", "after": "my.noop", "nth": 2, "at": 2.5},
        {"event": "my.done", "after": "my.fire", "nth": 2, "at": 2.5},  # a hanging call: from its start
    ]


def test_an_event_just_after_the_tick_that_took_the_answer_stays_after_it(tmp_path):
    # clock readings rounded to the microsecond: the event is recorded at the answer's time, after
    # the tick that took it (its call_end): it must stay after that tick
    records = [start("a", "my.noop", 1.0), end("a", "my.noop", 1.5, 0.5), event(1.5)]
    assert events_of(tmp_path, records) == [{"event": "my.done", "after": "my.noop", "at": 0.500001}]


def test_a_killed_runs_events_are_tied_too(tmp_path):
    records = [start("a", "my.noop", 1.0), event(1.2), {"type": "tick", "t": 1.3, "n": 2, "changes": []}]
    assert events_of(tmp_path, records, end=False) == [{"event": "my.done", "after": "my.noop", "at": 0.2}]


def test_a_scenario_from_a_run_given_definitions_names_them_and_runs_alone(tmp_path, my):
    """``--modules``/``--module`` of the run become the scenario file's ``modules:``, relative to it: the
    scenario runs by itself (before, it failed with ``no module 'my' to mock``)."""
    log, run = field_run(tmp_path, my, tree_text(noops=2, wait=False), emits_then_answers)
    assert run.succeeded
    (tmp_path / "tests").mkdir()
    out_path = str(tmp_path / "tests" / "replayed.yaml")
    write_scenario(read_log(log), out_path)
    data = yaml.safe_load(open(out_path))
    assert list(data) == ["tree", "modules", "scenarios"]
    assert data["tree"] == "../tree.yaml" and data["modules"] == ["../my.json"]
    out = io.StringIO()
    assert run_scenario_file(out_path, out=out) == [True], out.getvalue()
