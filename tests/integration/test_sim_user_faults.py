"""A world's faults reach the user's own module too (`bmtree run --sim --module … --world …`): a
tree's failure handling is tried against the module under development, not only the simulated one."""
from __future__ import annotations

import json
import os
import subprocess

from modules.sim import DEFAULT_WORLD
from tests.integration.conftest import bmtree_cmd

DEFINITION = {"Basic Module": "gripper2", "Brief Description": "", "Hardware Required": [], "Functions": [
    {"Name": "close", "Exec-condition": "", "Description": "", "Input-params": [],
     "Output-params": [{"Name": "holding", "Data-type": "std_msgs/Bool", "Description": ""}]}]}

MODULE = '''from modules import BasicModule


class Gripper2(BasicModule):
    def close(self):
        return {"holding": True}
'''


def test_a_worlds_fault_on_the_users_own_module_fails_its_first_call(tmp_path):
    (tmp_path / "g.json").write_text(json.dumps(DEFINITION))
    (tmp_path / "g.py").write_text(MODULE)
    world = tmp_path / "world.yaml"
    house = open(DEFAULT_WORLD).read().replace("\nfaults: {}\n", "\n")   # a key written twice is an error
    world.write_text(house + "\nfaults:\n  gripper2.close: {fail: jammed, times: 1}\n")
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n  retry: 2\n  child: {call: gripper2.close, outputs: {holding: held}}\n")
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    module = "%s=%s:Gripper2" % (tmp_path / "g.json", tmp_path / "g.py")
    out = subprocess.run(bmtree_cmd("run", "--sim", "--module", module, "--world", str(world), "-q", str(tree)),
                         capture_output=True, text=True, timeout=120, env=env, stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stdout + out.stderr
    calls = [line.split() for line in out.stdout.split("calls:")[1].splitlines() if "gripper2.close" in line]
    assert [c[3] for c in calls] == ["failed", "succeeded"] and "jammed" in calls[0], out.stdout
    # a fault naming a function that neither the simulated robot nor your module has
    world.write_text(house + "\nfaults:\n  gripper2.clsoe: {fail: jammed}\n")
    out = subprocess.run(bmtree_cmd("run", "--sim", "--module", module, "--world", str(world), "-q", str(tree)),
                         capture_output=True, text=True, timeout=120, env=env, stdin=subprocess.DEVNULL)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "faults.gripper2.clsoe: not a function of the simulated robot or of your --module (did you mean " \
           "'gripper2.close'?)" in out.stderr, out.stderr
