"""``bmtree run --sim --set x=abc``: a value that the call input it is passed to could never take is
refused before anything starts (exit 2, the call input named), not mid-run after the calls before it
moved the robot."""
from __future__ import annotations

import os
import subprocess

from tests.integration.conftest import bmtree_cmd

TREE = """format: 1
inputs:
  x: {default: 1.5}
root:
  sequence:
    - call: navigation.go_to
      inputs: {place: kitchen}
    - call: navigation.approach
      inputs: {target: {x: $x, y: 0.0}}
"""


def test_a_set_value_the_call_cannot_take_is_refused_before_any_call(tmp_path):
    tree = tmp_path / "t.yaml"
    tree.write_text(TREE)
    record = tmp_path / "run.jsonl"
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    out = subprocess.run(bmtree_cmd("run", "--sim", "-q", "--record", str(record), "--set", "x=abc", str(tree)),
                         capture_output=True, text=True, timeout=60, env=env, stdin=subprocess.DEVNULL)
    assert out.returncode == 2, out.stdout + out.stderr
    assert out.stderr.strip() == ("error: --set x: 'abc' is text, but navigation.approach's target.x at %s:9:28 "
                                  "takes a number (float64)" % tree), out.stderr
    assert "starting the simulated robot" not in out.stdout + out.stderr and "navigation.go_to" not in out.stdout, out.stdout
    assert not record.exists() and not (tmp_path / "home").exists()   # no run: nothing recorded, no robot
