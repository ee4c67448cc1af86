"""``bmtree run --sim --module DEF=FILE:CLASS``: the user's module beside the simulated robot."""
from __future__ import annotations

import os
import shutil
import subprocess

from tests.conftest import DATA
from tests.integration.conftest import bmtree_cmd

GRIPPER = os.path.join(DATA, "gripper")


def _run(*args, cwd=None):
    return subprocess.run(bmtree_cmd("run", "--sim", "-q", *args), capture_output=True, text=True, timeout=180,
                          stdin=subprocess.DEVNULL, cwd=cwd)


def test_your_module_runs_beside_the_simulated_ones():
    out = _run("--module", "%s=%s:Gripper" % (os.path.join(GRIPPER, "gripper.json"),
                                              os.path.join(GRIPPER, "gripper.py")), os.path.join(GRIPPER, "grasp.yaml"))
    assert out.returncode == 0, out.stdout + out.stderr
    assert "gripper (yours)" in out.stderr and "grasp_apple: SUCCESS" in out.stdout
    calls = [line.split()[2:4] for line in out.stdout.splitlines() if line.startswith("  +")]
    assert calls == [["navigation.go_to", "succeeded"], ["gripper.open", "succeeded"],
                     ["gripper.close", "succeeded"], ["speech.say", "succeeded"]]


def test_your_module_with_a_parameter_that_is_not_an_input_is_exit_2():
    out = _run("--module", "%s=%s:Gripper" % (os.path.join(GRIPPER, "gripper.json"),
                                              os.path.join(GRIPPER, "wrong_params.py")),
               os.path.join(GRIPPER, "grasp.yaml"))
    assert out.returncode == 2, out.stdout + out.stderr
    assert "Traceback" not in out.stderr
    assert "your module gripper exited with code 2" in out.stderr
    assert "parameter 'size' is not an input; input 'width' has no parameter" in out.stderr


def test_a_teams_own_modules_folder_does_not_hide_bmtrees(tmp_path):
    """A team keeps its definitions and classes in ``modules/`` and runs from its repository: the nodes
    bmtree started with ``python -m`` had the working directory first on their path, so the team's
    folder hid bmtree's ``modules`` package (``cannot import name 'BasicModule' from 'modules'``)."""
    shutil.copytree(GRIPPER, str(tmp_path / "modules"))
    out = _run("--module", "modules/gripper.json=modules/gripper.py:Gripper", "modules/grasp.yaml", cwd=str(tmp_path))
    assert out.returncode == 0, out.stdout + out.stderr
    assert "grasp_apple: SUCCESS" in out.stdout
