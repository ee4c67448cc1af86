"""``bmtree run --sim --module DEF.json=EXECUTABLE``: a C++ module (the example gripper, built with the real
compiler against Debian's roscpp: test_bridge_dead_node's build, reused) beside the simulated robot, with its
bridge; a world's fault on it; its node dying mid-run, or serving another module, or a node that exits
during start-up, each said with why."""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess

import yaml

from modules.sim import DEFAULT_WORLD
from tests.conftest import until
from tests.integration.conftest import bmtree_cmd, processes_running
from tests.integration.test_bridge_dead_node import gripper_node  # noqa: F401 - a fixture
from tests.integration.test_cpp_modules import GRIPPER_JSON, call_lines

TREE = """format: 1
name: cpp_grasp
root:
  sequence:
    - call: navigation.go_to
      inputs: {place: kitchen}
    - force_success:
        call: gripper.ping
        name: jammed ping
    - call: gripper.set_fingers
      inputs: {left: 0.02, right: 0.07}
      outputs: {opening: opening}
    - check: 'opening > 0.0499 and opening < 0.0501'
"""


def _user(tmp_path, exe):
    """The user's folder: the gripper's executable in build/, its definition, the tree."""
    (tmp_path / "build").mkdir()
    shutil.copy(exe, str(tmp_path / "build" / "gripper_node"))  # a path of this test's own: its processes
    shutil.copy(GRIPPER_JSON, str(tmp_path / "gripper.json"))
    (tmp_path / "grasp.yaml").write_text(TREE)
    return str(tmp_path / "build" / "gripper_node")


def _cmd(*args):
    return bmtree_cmd("run", "--sim", "-q", "--no-record", *args)


def _env(tmp_path):
    return dict(os.environ, ROS_HOME=str(tmp_path / "home"))


def _run(tmp_path, *args):
    return subprocess.run(_cmd(*args), capture_output=True, text=True, timeout=180, env=_env(tmp_path),
                          cwd=str(tmp_path), stdin=subprocess.DEVNULL)


def _sim_dir(stderr):
    return re.search(r"^its Blackboard store and module logs go to (.*)$", stderr, re.M).group(1)


def _log(folder, name):
    with open(os.path.join(folder, name + ".out"), errors="replace") as fh:
        return fh.read()


def test_a_cpp_module_runs_beside_the_simulated_robot_with_its_bridge(gripper_node, tmp_path):  # noqa: F811
    _user(tmp_path, gripper_node)
    (tmp_path / "world.yaml").write_text("faults:\n  gripper.ping: {fail: jammed, times: 1}\n")
    out = _run(tmp_path, "--world", "world.yaml", "--module", "gripper.json=./build/gripper_node", "grasp.yaml")
    assert out.returncode == 0, out.stdout + out.stderr
    assert "battery, gripper (yours))" in out.stderr and "cpp_grasp: SUCCESS" in out.stdout, out.stdout + out.stderr
    calls = [line.split()[2:4] for line in call_lines(out.stdout)]
    assert calls == [["navigation.go_to", "succeeded"], ["gripper.ping", "failed"],
                     ["gripper.set_fingers", "succeeded"]], out.stdout
    assert "jammed (injected fault)" in call_lines(out.stdout)[1]  # the world's fault, by the bridge
    folder = _sim_dir(out.stderr)  # served by the C++ node bmtree started, through its bridge
    assert "bmtree: C++ basic module gripper ready" in _log(folder, "gripper")
    bridge = _log(folder, "gripper_bridge")
    assert "bridge for 'gripper': C++ node /gripper connected (bmtree library" in bridge, bridge
    assert "faults injected: gripper.ping: fail 'jammed' ×1" in bridge, bridge
    assert processes_running(str(tmp_path)) == []  # the C++ node, its bridge, the Blackboard: all stopped


def test_a_cpp_node_that_dies_mid_run_is_said_with_its_signal(gripper_node, tmp_path):  # noqa: F811
    exe = _user(tmp_path, gripper_node)
    with open(DEFAULT_WORLD) as fh:
        world = yaml.safe_load(fh)
    world["speed"] = 2.0  # the way to the kitchen: some 4 s, while the C++ node is killed
    (tmp_path / "slow.yaml").write_text(yaml.safe_dump(world))
    (tmp_path / "grasp.yaml").write_text(TREE.replace("    - force_success:\n        call: gripper.ping\n"
                                                      "        name: jammed ping\n", ""))
    with open(str(tmp_path / "out.txt"), "w") as stdout:
        proc = subprocess.Popen(_cmd("--world", "slow.yaml", "--module", "gripper.json=" + exe, "grasp.yaml"),
                                stdout=stdout, stderr=subprocess.STDOUT, text=True, env=_env(tmp_path),
                                cwd=str(tmp_path), stdin=subprocess.DEVNULL)
        try:
            until(lambda: "\nrunning cpp_grasp" in (tmp_path / "out.txt").read_text() or proc.poll() is not None, 120)
            assert proc.poll() is None, (tmp_path / "out.txt").read_text()
            os.kill(processes_running(exe + " __name:=gripper")[0], signal.SIGSEGV)  # the C++ node, not bmtree
            assert proc.wait(120) == 1
        finally:
            if proc.poll() is None:
                proc.kill()
    out = (tmp_path / "out.txt").read_text()
    lost = "module gripper lost: node /gripper_bridge stopped (its C++ node /gripper stopped: its process was " \
           "killed by SIGSEGV)"
    assert "reason: gripper.set_fingers module_lost: " + lost in out, out
    assert processes_running(str(tmp_path)) == []


def test_a_cpp_node_that_serves_another_module_is_exit_2_naming_both(gripper_node, tmp_path):  # noqa: F811
    _user(tmp_path, gripper_node)
    with open(GRIPPER_JSON) as fh:
        definition = json.load(fh)
    definition["Basic Module"] = "arm"
    (tmp_path / "arm.json").write_text(json.dumps(definition))
    (tmp_path / "arm.yaml").write_text("format: 1\nroot: {call: arm.ping}\n")
    out = _run(tmp_path, "--module", "arm.json=build/gripper_node", "arm.yaml")
    assert out.returncode == 2, out.stdout + out.stderr
    assert "error: your module arm's bridge /arm_bridge exited with code 2 during start-up; its log " in out.stderr
    # the fix first: the start-up error quotes 200 characters of the bridge's last line
    assert "arm_bridge.out ends:\n  error: node /arm serves module 'gripper', but the definition is module 'arm': the " \
           "name given to BasicModule in the C++ code must be the definition's (BasicModule(nh, \"arm\"))" in out.stderr, \
        out.stderr
    assert "Traceback" not in out.stderr


def test_a_node_that_exits_during_start_up_is_said_at_once_with_its_exit_code(tmp_path):
    """Any executable: here a script standing for a node whose driver is missing."""
    (tmp_path / "gripper_node").write_text("#!/bin/sh\necho 'gripper: no /dev/ttyUSB0' >&2\nexit 3\n")
    (tmp_path / "gripper_node").chmod(0o755)
    shutil.copy(GRIPPER_JSON, str(tmp_path / "gripper.json"))
    (tmp_path / "t.yaml").write_text("format: 1\nroot: {call: gripper.ping}\n")
    # --wait far beyond the test's own timeout: only an exit noticed at once ends the run in time
    out = _run(tmp_path, "--wait", "600", "--module", "gripper.json=./gripper_node", "t.yaml")
    assert out.returncode == 3, out.stdout + out.stderr
    assert re.search(r"(^|\n)error: your module gripper's C\+\+ node /gripper exited with code 3 during start-up; its "
                     r"log \S+/gripper\.out ends:\n  gripper: no /dev/ttyUSB0\n$", out.stderr), out.stderr
