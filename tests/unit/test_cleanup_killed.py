"""``replay --scenario`` of a run killed (no end record) while its cleanup ran: the scenario ends root
where the run did (stopped, or by itself), then the cleanup runs as far as the run saw it."""
from __future__ import annotations

import io
import json

import pytest
import yaml

from coordinator.errors import TreeErrors
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runstream import RunStream
from coordinator.scenariogen import write_scenario
from coordinator.testing.mocks import fail, succeed
from coordinator.testing.scenario import run_scenario_file
from tests.unit.test_cleanup_audit import WAITS, _interrupted, _tree


def _killed_at(log, t):
    """The log as a SIGKILL at ``t`` (seconds of the run) leaves it: no record after, no end record."""
    with open(log) as fh:
        records = [json.loads(line) for line in fh]
    kept = [r for r in records if r.get("type") != "end" and float(r.get("t") or 0.0) <= t]
    with open(log, "w") as fh:
        fh.write("".join(json.dumps(r) + "\n" for r in kept))


def _scenario(tmp_path, log):
    out_path = str(tmp_path / "again.yaml")
    write_scenario(read_log(log), out_path)
    return out_path, yaml.safe_load(open(out_path))["scenarios"][0]


def test_a_run_killed_in_the_cleanup_after_a_stop_stops_root_when_the_run_did(tmp_path, sim_defs):
    t = _tree(tmp_path, WAITS, sim_defs)
    log = str(tmp_path / "run.jsonl")
    _interrupted(t, 4.3, log=log)      # root stopped at 4.5 s; the cleanup's wait ran to 7.5 s, then it spoke
    _killed_at(log, 6.0)
    out_path, scenario = _scenario(tmp_path, log)
    assert scenario["max_duration"] == pytest.approx(4.5) and scenario["killed_at"] == pytest.approx(4.5)
    assert scenario["expect"] == {"status": "failure", "reason": "stopped after 4.5 s while 'wait 2s' was running",
                                  "calls": [{"speech.say": {"text": "a"}}, {"speech.say": {"text": "b"}}]}
    text = open(out_path).read()
    assert "# The run was stopped (interrupted while 'wait 2s' was running) at 4.5s, then its cleanup ran" in text
    assert "# It was killed at 4.5s while the cleanup ran (its log ends there): killed_at ends" in text
    out = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, out) == [True], out.getvalue()


FAILS = """format: 1
name: go
root:
  sequence:
    - call: speech.say
      inputs: {text: a}
      timeout: 5
cleanup:
  sequence:
    - call: speech.say
      inputs: {text: "bye {ended}"}
    - wait: 3
    - call: speech.say
      inputs: {text: "done"}
"""


def test_a_run_killed_in_the_cleanup_after_root_failed_lets_root_fail_by_itself(tmp_path, sim_defs):
    t = _tree(tmp_path, FAILS, sim_defs)
    t.mocks["speech.say"].script(fail("muted", delay=1.0), succeed(delay=0.5), succeed())
    log = str(tmp_path / "run.jsonl")
    result = t.run(observers=[RunStream([RunLogWriter(log, fsync=False)])])
    assert result.failed and result.duration == pytest.approx(4.5)
    assert [c.inputs["text"] for c in result.calls()] == ["a", "bye failed", "done"]
    _killed_at(log, 3.0)                # in the cleanup's wait
    out_path, scenario = _scenario(tmp_path, log)
    assert scenario["killed_at"] == pytest.approx(1.5) and "max_duration" not in scenario
    assert scenario["expect"] == {"status": "failure", "reason": "speech.say failed: muted",
                                  "calls": [{"speech.say": {"text": "a"}}, {"speech.say": {"text": "bye failed"}}]}
    assert "# Root ended by itself (failure), then its cleanup ran." in open(out_path).read()
    out = io.StringIO()
    assert run_scenario_file(out_path, sim_defs, out) == [True], out.getvalue()


def test_killed_at_ends_a_scenario_where_the_kill_was(tmp_path, sim_defs):
    """Written by hand: a kill in root halts it and no cleanup runs; one in the cleanup cuts it there."""
    tree = tmp_path / "go.yaml"
    tree.write_text(FAILS)
    scenarios = tmp_path / "s.yaml"
    scenarios.write_text("""tree: go.yaml
scenarios:
  - name: killed in root
    mocks: {speech.say: {succeed: {}, delay: 2.0}}
    killed_at: 1.0
    expect: {status: failure, reason: "killed after 1 s while 'speech.say' was running", calls: [speech.say]}
  - name: killed in the cleanup
    mocks: {speech.say: [{fail: muted}, {succeed: {}}, {succeed: {}}]}
    killed_at: 2.5
    expect: {status: failure, reason: muted, calls: [speech.say, speech.say], cleanup: failure}
  - name: killed after the end
    mocks: {speech.say: [{fail: muted}, {succeed: {}}, {succeed: {}}]}
    killed_at: 20
    expect: {status: failure, calls: [speech.say, speech.say, speech.say], cleanup: success}
  - name: bad
    killed_at: soon
""")
    out = io.StringIO()
    with pytest.raises(TreeErrors) as err:
        run_scenario_file(str(scenarios), sim_defs, out)
    assert str(err.value).endswith("s.yaml:16:16: killed_at must be a number of seconds >= 0, got 'soon'")
    scenarios.write_text(scenarios.read_text().rsplit("  - name: bad", 1)[0])
    out = io.StringIO()
    assert run_scenario_file(str(scenarios), sim_defs, out) == [True, False, True], out.getvalue()
    assert "killed in the cleanup (2 calls" in out.getvalue() and (
        "    cleanup cut short, expected FAILURE (killed after 2.5 s while 'wait 3s' was running)\n" in out.getvalue())
