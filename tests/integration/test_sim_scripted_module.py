"""``bmtree run --sim --module arm.json=arm.yaml``: a module not written yet, played by a scripted stand-in
(the real module runtime serving the script) beside the simulated robot, the world's faults included."""
from __future__ import annotations

import json
import os
import subprocess

from modules.sim import DEFAULT_WORLD
from tests.integration.conftest import bmtree_cmd

ARM = {"Basic Module": "arm", "Brief Description": "", "Hardware Required": [], "Functions": [
    {"Name": "grasp", "Exec-condition": "", "Description": "",
     "Input-params": [{"Name": "object", "Data-type": "std_msgs/String", "Description": ""}],
     "Output-params": [{"Name": "holding", "Data-type": "std_msgs/Bool", "Description": ""}]}]}
SCRIPT = "module: arm\nfunctions:\n  grasp:\n    - fail: slipped\n    - succeed: {holding: true}\n      delay: 0.2\n"
TREE = """format: 1
root:
  sequence:
    - call: navigation.go_to
      inputs: {place: kitchen}
    - retry: 3
      child:
        call: arm.grasp
        inputs: {object: apple}
        outputs: {holding: held}
    - check: held
"""


def test_a_scripted_stand_in_answers_as_its_script_says_and_takes_the_worlds_faults(tmp_path):
    (tmp_path / "arm.json").write_text(json.dumps(ARM))
    (tmp_path / "arm.yaml").write_text(SCRIPT)
    (tmp_path / "t.yaml").write_text(TREE)
    house = open(DEFAULT_WORLD).read().replace("\nfaults: {}\n", "\n")
    (tmp_path / "world.yaml").write_text(house + "\nfaults:\n  arm.grasp: {fail: jammed, times: 1}\n")
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    out = subprocess.run(bmtree_cmd("run", "--sim", "-q", "--module", "arm.json=arm.yaml", "--world", "world.yaml",
                                    "t.yaml"), capture_output=True, text=True, timeout=120, env=env,
                         stdin=subprocess.DEVNULL, cwd=str(tmp_path))
    assert out.returncode == 0, out.stdout + out.stderr
    assert "arm (yours)" in out.stderr
    calls = [line.split(None, 4) for line in out.stdout.split("calls:")[1].splitlines() if "arm.grasp" in line]
    assert [(c[3], c[4].split(None, 1)[1] if c[3] == "failed" else "") for c in calls] == [
        ("failed", "jammed (injected fault)"), ("failed", "slipped"), ("succeeded", "")], out.stdout
