"""Mocks of modules that cannot be interrupted (an original module behind bmtree-bridge)."""
from __future__ import annotations

import io

import pytest

from coordinator.testing import MockError, TreeTest, succeed
from coordinator.testing.scenario import run_scenario_file
from modules.outcome import outcome_from_dict, outcome_to_dict

TREE = """format: 1
root:
  sequence:
    - force_success:
        timeout: 5
        child: {call: navigation.go_to, inputs: {place: kitchen}}
    - call: navigation.go_to
      inputs: {place: hall}
"""


def test_a_mock_that_ignores_cancels_stays_busy_as_the_bridge_does(tmp_path):
    """A timeout halts the call; a mock ended its delay at once and took the next call, so the
    clean-up path passed in tests and failed on the robot, where the bridge stays busy."""
    path = tmp_path / "t.yaml"
    path.write_text(TREE)
    t = TreeTest(str(path))
    t.mocks["navigation.go_to"].succeed(delay=8, room="kitchen")
    run = t.run()
    assert run.succeeded and [c.status for c in run.calls()] == ["halted", "succeeded"]
    t = TreeTest(str(path))
    t.mocks["navigation.go_to"].succeed(delay=8, room="kitchen")
    t.mocks.ignoring_cancels("navigation")
    run = t.run()
    assert run.failed and [c.status for c in run.calls()] == ["halted", "rejected"]
    assert "busy with call" in run.calls()[1].error and run.duration == pytest.approx(6.0)
    with pytest.raises(MockError, match="no module 'navigaton' to mock.*did you mean 'navigation'"):
        t.mocks.ignoring_cancels("navigaton")


def test_after_its_delay_the_module_is_free_again(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text(TREE.replace("    - call: navigation.go_to\n      inputs: {place: hall}\n",
                                 "    - wait: 4\n    - call: navigation.go_to\n      inputs: {place: hall}\n"))
    t = TreeTest(str(path))
    t.mocks["navigation.go_to"].ignoring_cancels().script(succeed(delay=8, room="kitchen"),
                                                          succeed(delay=1, room="hall"))
    run = t.run()
    assert run.succeeded, run.reason
    assert [c.status for c in run.calls()] == ["halted", "succeeded"] and run.duration == pytest.approx(10.0)


def test_the_written_form_and_a_scenario(tmp_path):
    o = outcome_from_dict({"succeed": {"room": "x"}, "delay": 8, "ignores_cancel": True})
    assert o.ignores_cancel and outcome_to_dict(o) == {"succeed": {"room": "x"}, "delay": 8.0, "ignores_cancel": True}
    with pytest.raises(ValueError, match="ignores_cancel is true or false"):
        outcome_from_dict({"hang": True, "ignores_cancel": "yes"})
    (tmp_path / "t.yaml").write_text(TREE)
    scen = tmp_path / "t.scenarios.yaml"
    scen.write_text("""tree: t.yaml
scenarios:
  - name: the bridge stays busy
    mocks:
      navigation.go_to: [{succeed: {room: kitchen}, delay: 8, ignores_cancel: true}]
    expect:
      status: failure
      calls: [navigation.go_to, navigation.go_to]
""")
    out = io.StringIO()
    assert run_scenario_file(str(scen), None, out) == [True], out.getvalue()


def test_the_mocks_warnings_show_under_a_failed_scenario_not_between_the_lines(tmp_path, capfd):
    """``bmtree test`` printed the mocked runtime's warnings (busy, a cancelled call's code still running)
    on stderr among the PASS/FAIL lines; a failed scenario now shows them under its problems."""
    (tmp_path / "t.yaml").write_text(TREE)
    scen = tmp_path / "t.scenarios.yaml"
    scenario = """  - name: %s
    mocks:
      navigation.go_to: [{succeed: {room: kitchen}, delay: 8, ignores_cancel: true}]
    expect:
      status: %s
"""
    scen.write_text("tree: t.yaml\nscenarios:\n" + scenario % ("expected", "failure") + scenario % ("wrong", "success"))
    out = io.StringIO()
    assert run_scenario_file(str(scen), None, out) == [True, False], out.getvalue()
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("PASS ") and lines[1].startswith("FAIL ") and lines[2].startswith("    status FAILURE")
    logged = [line for line in lines if line.startswith("    module log: ")]
    assert logged and any("busy" in line for line in logged), lines
    assert all(line.startswith("    ") for line in lines[2:])
    assert capfd.readouterr().err == ""
