"""A module's node that dies mid-call, without a robot: the ``die`` outcome of mocks, scenarios and
world faults ends the call, and every other call that module has in flight, ``module_lost`` as the run's
watchdog does; and ``replay --scenario`` of a run whose module died writes a test that passes (it wrote
``hang``, and the fresh regression test failed on a timeout the run never had)."""
from __future__ import annotations

import io

import pytest
import yaml

from coordinator.cli import main as bmtree
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runstream import RunStream
from coordinator.scenariogen import write_scenario
from coordinator.testing import TreeTest, die, succeed
from coordinator.testing.scenario import run_scenario_file
from modules.outcome import OutcomeError, outcome_from_dict, outcome_to_dict
from modules.sim.world import Fault, WorldError

BOTH = """format: 1
root:
  sequence:
    children:
      - retry: 2
        child:
          parallel:
            policy: all
            children:
              - call: navigation.go_to
                inputs: {place: kitchen}
              - call: navigation.where_am_i
      - call: speech.say
        inputs: {text: "made it"}
"""


@pytest.fixture
def both(tmp_path, sim_defs):
    path = tmp_path / "both.yaml"
    path.write_text(BOTH)
    return str(path)


def test_a_dying_mock_ends_every_call_its_module_has_in_flight_and_the_next_attempt_is_answered(both, sim_defs):
    t = TreeTest(both, definitions=sim_defs)
    t.mocks["navigation.go_to"].script(die("node /bm_navigation stopped (its process is gone)", delay=2.0),
                                       succeed(room="kitchen"))
    t.mocks["navigation.where_am_i"].succeed(delay=5.0, room="hall")
    run = t.run()
    assert run.succeeded, run.reason
    first = [c for c in run.calls() if c.started == 0.0]
    assert [(c.target, c.status.value, c.error, c.ended) for c in first] == [
        (target, "module_lost", "module navigation lost: node /bm_navigation stopped (its process is gone)", 2.0)
        for target in ("navigation.go_to", "navigation.where_am_i")]
    assert [c.status.value for c in run.calls()][2:] == ["succeeded", "succeeded", "succeeded"]


def test_die_is_written_as_the_other_outcomes_and_a_bad_one_says_what_it_takes(tmp_path, sim_defs):
    assert outcome_to_dict(outcome_from_dict({"die": "power cut", "delay": 1.5})) == {"die": "power cut", "delay": 1.5}
    assert outcome_from_dict({"die": True}).reason == "its process died (mock)"
    with pytest.raises(OutcomeError, match="one of succeed, fail, reject, hang, die"):
        outcome_from_dict({"dye": True})
    assert Fault.parse("navigation.go_to", {"die": "power cut", "times": 1}).what == "die 'power cut'"  # why, in the line listing the faults
    with pytest.raises(WorldError, match="faults.navigation.go_to.die must be a text"):
        Fault.parse("navigation.go_to", {"die": [3]})
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n  call: navigation.go_to\n  inputs: {place: kitchen}\n")
    bad = tmp_path / "s.yaml"
    bad.write_text("tree: t.yaml\nscenarios:\n  - name: x\n    mocks:\n      navigation.go_to: {die: 3}\n")
    assert bmtree(["test", str(bad)]) == 2


def test_a_recorded_run_whose_module_died_becomes_a_scenario_that_passes(both, sim_defs, tmp_path):
    t = TreeTest(both, definitions=sim_defs)
    t.mocks["navigation.go_to"].script(die("node /bm_navigation stopped (its process is gone)", delay=1.6),
                                       succeed(room="kitchen"))
    log = str(tmp_path / "run.jsonl")
    t.run(observers=[RunStream([RunLogWriter(log, fsync=False)], {"inputs": {}})])
    out_path = str(tmp_path / "regression.yaml")
    write_scenario(read_log(log), out_path)
    scenario = yaml.safe_load(open(out_path))["scenarios"][0]
    assert scenario["mocks"]["navigation.go_to"][0] == {
        "die": "node /bm_navigation stopped (its process is gone)", "delay": 1.6}
    said = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, said) == [True], said.getvalue()
