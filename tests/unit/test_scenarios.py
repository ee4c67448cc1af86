"""``bmtree test``: declarative YAML scenarios."""
from __future__ import annotations

import os

from coordinator.cli import main as bmtree
from tests.conftest import ROOT, TREES

SCENARIOS = os.path.join(ROOT, "tests", "scenarios", "find_apple.scenarios.yaml")


def test_shipped_scenarios_pass(capsys):
    assert bmtree(["test", SCENARIOS]) == 0
    out = capsys.readouterr().out
    assert out.count("PASS") == 2 and out.rstrip().endswith("2 passed, 0 failed")


def test_failing_expectations_are_explained(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n  - name: wrong\n    mocks:\n      vision.find_object: {fail: blind}\n"
                 "    expect:\n      status: success\n      calls: [speech.say, navigation.go_to: {place: attic}]\n"
                 % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", str(f)]) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "status FAILURE, expected SUCCESS" in out
    assert "input place is 'living_room', expected 'attic'" in out and "0 passed, 1 failed" in out


def test_invalid_scenario_file(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n  - name: x\n    mokcs: {}\n" % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", str(f)]) == 2
    assert "s.yaml:4:5: unknown scenario key 'mokcs' (did you mean 'mocks'?)" in capsys.readouterr().err
    f.write_text("tree: %s\nscenarios:\n  - mocks:\n      speech.say: {succeed: {volume: 3}}\n"
                 % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", str(f)]) == 2
    assert "unknown output 'volume'" in capsys.readouterr().err
