"""A scenario from a run names the definitions the run used that are not the simulated robot's (a team's
package export, ``$BMTREE_MODULE_PATH``, ``--modules``) in its ``modules:``, relative to itself, so that
``bmtree test`` runs it where the workspace is not sourced (no ROS master)."""
from __future__ import annotations

import json
import os
import shutil

import yaml

from coordinator import cli
from coordinator.replay import _test_command
from coordinator.runlog import RunFiles, RunLogWriter, definition_files, read_log
from coordinator.runstream import RunStream
from coordinator.scenariogen import write_scenario
from coordinator.testing.kit import TreeTest
from coordinator.testing.mocks import fail, succeed
from modules.definition import load_definitions, parse_definition
from modules.search import SIM_DIR
from tests.conftest import DATA

GRIPPER = os.path.join(DATA, "gripper")
PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>robot_bm</name><version>0.0.1</version><description>d</description>
  <maintainer email="t@example.org">t</maintainer><license>MIT</license>
  <buildtool_depend>catkin</buildtool_depend>
  <export><bmtree definitions="definitions"/></export>
</package>
"""


def _workspace(tmp_path, monkeypatch):
    """A catkin-style package exporting the gripper's definition, found through ROS_PACKAGE_PATH (the
    workspace sourced); its tree uses the gripper beside the simulated navigation and speech."""
    pkg = tmp_path / "ws" / "src" / "robot_bm"
    for d in ("definitions", "trees", "tests"):
        (pkg / d).mkdir(parents=True)
    (pkg / "package.xml").write_text(PACKAGE_XML)
    shutil.copy(os.path.join(GRIPPER, "gripper.json"), str(pkg / "definitions"))
    shutil.copy(os.path.join(GRIPPER, "grasp.yaml"), str(pkg / "trees"))
    monkeypatch.delenv("BMTREE_MODULE_PATH", raising=False)
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ws" / "src"))
    return pkg


def _run(pkg, observer):
    t = TreeTest(str(pkg / "trees" / "grasp.yaml"))   # the default definitions: the package's gripper found
    t.mocks["gripper.open"].script(fail("stuck"), succeed(success=True))
    t.mocks["gripper.close"].script(succeed(success=True, holding=True))
    return t.run(observers=[observer])


def _recorded_by_bmtree_run(pkg, tmp_path):
    """The log as `bmtree run` writes it (its RunFiles' recorder)."""
    files = RunFiles("20261126-170241-23e7e6", str(tmp_path / "run1.jsonl"), str(tmp_path / "run1.sim"))
    recorder = files.recorder([], {}, None, None)
    _run(pkg, recorder)
    recorder.close()
    return read_log(files.log_path)


def _bmtree_test(path, capsys):
    code = cli.main(["test", str(path)])
    out = capsys.readouterr()
    return code, out.out + out.err


def test_the_run_log_names_the_definition_files_of_the_modules_not_the_simulated_robots(tmp_path, monkeypatch):
    pkg = _workspace(tmp_path, monkeypatch)
    log = _recorded_by_bmtree_run(pkg, tmp_path)
    assert log.tree["definitions"] == {"gripper": str(pkg / "definitions" / "gripper.json")}
    sim = load_definitions([SIM_DIR])
    live = parse_definition(dict(json.load(open(os.path.join(GRIPPER, "gripper.json"))), **{"Basic Module": "arm"}),
                            "live:/bm_arm")   # announced by a running module: in no file
    assert definition_files(dict(sim, arm=live)) == {}


def test_a_scenario_from_a_run_on_a_teams_modules_runs_where_the_workspace_is_not_sourced(tmp_path, monkeypatch,
                                                                                          capsys):
    pkg = _workspace(tmp_path, monkeypatch)
    log = _recorded_by_bmtree_run(pkg, tmp_path)
    monkeypatch.delenv("ROS_PACKAGE_PATH")     # elsewhere: CI, a laptop, a shell without devel/setup.bash
    out = pkg / "tests" / "run1.scenario.yaml"
    write_scenario(log, str(out))
    data = yaml.safe_load(out.read_text())
    assert data["tree"] == "../trees/grasp.yaml" and data["modules"] == ["../definitions/gripper.json"], data
    assert "as found here now" not in out.read_text()
    code, said = _bmtree_test(out, capsys)
    assert code == 0 and "1 passed, 0 failed" in said, said
    assert _test_command(log, str(out)) == "bmtree test %s" % out
    moved = tmp_path / "elsewhere" / "run1.scenario.yaml"   # written in another folder: relative to it
    moved.parent.mkdir()
    write_scenario(log, str(moved))
    assert yaml.safe_load(moved.read_text())["modules"] == ["../ws/src/robot_bm/definitions/gripper.json"]
    code, said = _bmtree_test(moved, capsys)
    assert code == 0, said


def test_a_log_that_does_not_name_its_definitions_takes_the_ones_found_here_and_says_so(tmp_path, monkeypatch,
                                                                                        capsys):
    """A log of an earlier bmtree (the audit's run1.jsonl) has no ``definitions``: the scenario names the
    files the same search finds now, for the modules the run used that are not the simulated robot's."""
    pkg = _workspace(tmp_path, monkeypatch)
    path = str(tmp_path / "old.jsonl")
    _run(pkg, RunStream([RunLogWriter(path, fsync=False)], {"inputs": {}}))
    log = read_log(path)
    assert "definitions" not in log.tree
    out = pkg / "tests" / "run1.scenario.yaml"
    write_scenario(log, str(out))
    text = out.read_text()
    assert yaml.safe_load(text)["modules"] == ["../definitions/gripper.json"], text
    assert "# modules: gripper as found here now (ROS packages, $BMTREE_MODULE_PATH): the run log does not" in text
    monkeypatch.delenv("ROS_PACKAGE_PATH")
    code, said = _bmtree_test(out, capsys)
    assert code == 0 and "1 passed, 0 failed" in said, said


def test_a_definition_file_the_run_used_that_is_gone_is_said(tmp_path, monkeypatch):
    pkg = _workspace(tmp_path, monkeypatch)
    log = _recorded_by_bmtree_run(pkg, tmp_path)
    monkeypatch.delenv("ROS_PACKAGE_PATH")
    os.remove(str(pkg / "definitions" / "gripper.json"))
    out = tmp_path / "s.yaml"
    write_scenario(log, str(out))
    text = out.read_text()
    assert "modules" not in yaml.safe_load(text)
    gone = str(pkg / "definitions" / "gripper.json")
    assert "modules: the definition files of gripper the run used are not here (%s)" % gone in text.replace(
        "\n# ", " "), text
    assert _test_command(log, str(out)).endswith(
        "adding --modules with the definition of gripper (the run's, %s, is not here)" % gone)
