"""``bmtree replay RUN --scenario`` of a run that ``bmtree control stop`` stopped: the scenario stops root
when the run did (``max_duration``), and the cleanup reads the scenario's stop as ``ended_reason``."""
from __future__ import annotations

import io

import pytest
import yaml

from coordinator.runlog import RunLogWriter, read_log
from coordinator.runstream import RunStream
from coordinator.scenariogen import write_scenario
from coordinator.testing.scenario import run_scenario_file
from tests.unit.test_control_stop import Timed, _run, _stop, go, go_cleanup  # noqa: F401 - fixtures


@pytest.mark.parametrize("fixture", ["go", "go_cleanup"])
def test_a_run_stopped_by_control_replays_as_a_scenario_that_stops_then(fixture, request, monkeypatch, tmp_path,
                                                                        sim_defs):
    t = request.getfixturevalue(fixture)
    t.mocks["navigation.go_to"].succeed(room="kitchen", delay=3.0)
    log = str(tmp_path / "run.jsonl")
    run = _run(t, Timed([_stop(1.0)]), monkeypatch, observers=[RunStream([RunLogWriter(log, fsync=False)])])
    assert run.failed and run.reason.startswith("stopped by control (/smach_supervisor)")
    monkeypatch.undo()   # the scenario runs on the kit as it is
    out_path = str(tmp_path / "again.yaml")
    write_scenario(read_log(log), out_path)
    text = open(out_path).read()
    scenario = yaml.safe_load(text)["scenarios"][0]
    assert scenario["max_duration"] == pytest.approx(1.0) and scenario["expect"]["status"] == "failure"
    assert "# The run was stopped by control (stopped by control (/smach_supervisor) while 'navigation.go_to' " \
           "was running) at 1s" in text
    if fixture == "go_cleanup":
        said = [c["speech.say"]["text"] for c in scenario["expect"]["calls"] if "speech.say" in c]
        assert said == ["stopped: stopped after 1 s while 'navigation.go_to' was running"]
        assert scenario["expect"]["cleanup"] == "success"
    out = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, out) == [True], out.getvalue()
