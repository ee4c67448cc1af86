"""What a module's failures say in a real `bmtree run --sim`: the tree's reasons and the modules' own
logs, for an exception in the author's code and for the world's injected faults (reaching the
simulated modules from their world and the user's own module through its ``~faults``)."""
from __future__ import annotations

import json
import os
import subprocess

from tests.integration.conftest import bmtree_cmd

DEFINITION = {"Basic Module": "arm", "Brief Description": "", "Hardware Required": [], "Functions": [
    {"Name": "pick", "Exec-condition": "", "Description": "",
     "Input-params": [{"Name": "object", "Data-type": "std_msgs/String", "Description": ""}],
     "Output-params": [{"Name": "weight", "Data-type": "std_msgs/Float64", "Description": ""}]}]}

MODULE = '''from modules import BasicModule


class Arm(BasicModule):
    def pick(self, object):
        weights = {"apple": 0.2}
        return {"weight": weights[object.data]}
'''

WORLD = """faults:
  arm.pick: {fail: gripper jammed, times: 1}
  navigation.go_to: {crash: true, times: 1}
"""

TREE = """format: 1
root:
  sequence:
    - force_success: {call: navigation.go_to, inputs: {place: kitchen}}
    - force_success: {call: arm.pick, inputs: {object: apple}}
    - call: arm.pick
      inputs: {object: banana}
"""


def test_failures_say_where_they_come_from_in_the_run_and_in_the_module_logs(tmp_path):
    (tmp_path / "arm.json").write_text(json.dumps(DEFINITION))
    (tmp_path / "arm.py").write_text(MODULE)
    (tmp_path / "world.yaml").write_text(WORLD)
    (tmp_path / "t.yaml").write_text(TREE)
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    module = "%s=%s:Arm" % (tmp_path / "arm.json", tmp_path / "arm.py")
    out = subprocess.run(bmtree_cmd("run", "--sim", "--module", module, "--world", str(tmp_path / "world.yaml"),
                                    str(tmp_path / "t.yaml")),
                         capture_output=True, text=True, timeout=120, env=env, stdin=subprocess.DEVNULL)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "RuntimeError: injected crash (injected fault)" in out.stdout, out.stdout
    assert "gripper jammed (injected fault)" in out.stdout, out.stdout
    assert "arm.pick failed: KeyError: 'banana' (arm.py:7 in pick)" in out.stdout, out.stdout
    sim_dir = next(line.split(": ", 1)[1] for line in out.stdout.splitlines()
                   if line.startswith("simulated robot's Blackboard store and module logs: "))
    with open(os.path.join(sim_dir, "bm_arm.out")) as fh:
        arm_log = fh.read()
    assert "faults injected: arm.pick: fail 'gripper jammed' ×1" in arm_log, arm_log
    assert "an injected fault answers (fail 'gripper jammed')" in arm_log, arm_log
    assert "arm.pick raised (call " in arm_log and 'arm.py", line 7, in pick' in arm_log, arm_log
    with open(os.path.join(sim_dir, "bm_navigation.out")) as fh:
        nav_log = fh.read()
    assert "faults injected: navigation.go_to: crash ×1" in nav_log, nav_log
    assert "Traceback" not in nav_log, nav_log  # an injected crash is no bug to look for
