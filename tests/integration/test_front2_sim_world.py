"""`bmtree run --sim --world jam.yaml --module …` with a world of `faults:` alone: the default house
with those faults (the README's faults-only world files), the fault meeting the user's own module."""
from __future__ import annotations

import os
import subprocess

from tests.conftest import DATA
from tests.integration.conftest import bmtree_cmd

GRIPPER = os.path.join(DATA, "gripper")

TREE = """format: 1
root:
  sequence:
    children:
      - call: navigation.go_to
        inputs: {place: kitchen}
      - call: gripper.open
        inputs: {width: 0.08}
      - retry: 2
        child: {call: gripper.close, outputs: {holding: holding}}
"""


def test_a_world_of_faults_alone_runs_in_the_default_house(tmp_path):
    jam = tmp_path / "jam.yaml"
    jam.write_text("faults: {gripper.close: {fail: jammed, times: 1}}\n")
    tree = tmp_path / "grasp.yaml"
    tree.write_text(TREE)
    module = "%s=%s:Gripper" % (os.path.join(GRIPPER, "gripper.json"), os.path.join(GRIPPER, "gripper.py"))
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    out = subprocess.run(bmtree_cmd("run", "--sim", "--world", str(jam), "--module", module, "-q", str(tree)),
                         capture_output=True, text=True, timeout=120, env=env, stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stdout + out.stderr
    calls = [line.split() for line in out.stdout.split("calls:")[1].splitlines() if ".go_to" in line or
             "gripper.close" in line]
    assert [(c[2], c[3]) for c in calls] == [("navigation.go_to", "succeeded"), ("gripper.close", "failed"),
                                             ("gripper.close", "succeeded")], out.stdout
    assert "jammed" in calls[1], out.stdout


def test_a_die_fault_kills_the_module_process_mid_call_and_the_run_finds_it_lost(tmp_path):
    """``die``: the node's process is killed while the call runs (SIGKILL, as a crash: it stays registered);
    the run's watchdog finds it gone and ends the call module_lost long before its timeout."""
    world = tmp_path / "power.yaml"
    world.write_text("faults: {navigation.go_to: {die: power cut, delay: 0.3}}\n")
    tree = tmp_path / "go.yaml"
    tree.write_text("format: 1\nroot:\n  call: navigation.go_to\n  inputs: {place: kitchen}\n  timeout: 60\n")
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    out = subprocess.run(bmtree_cmd("run", "--sim", "--world", str(world), "-q", str(tree)),
                         capture_output=True, text=True, timeout=120, env=env, stdin=subprocess.DEVNULL)
    assert out.returncode == 1, out.stdout + out.stderr
    [call] = [line.split() for line in out.stdout.split("calls:")[1].splitlines() if ".go_to" in line]
    assert call[2:4] == ["navigation.go_to", "module_lost"] and float(call[4].rstrip("s")) < 30, out.stdout
    assert "reason: navigation.go_to module_lost: module navigation lost: " in out.stdout, out.stdout
    logs = [os.path.join(d, f) for d, _, fs in os.walk(str(tmp_path / "home")) for f in fs if "navigation" in f]
    assert any("the node dies (an injected fault) with 1 call(s) in flight: power cut" in open(p).read()
               for p in logs), logs
