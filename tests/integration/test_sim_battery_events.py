"""`bmtree run --sim --world W tree.yaml` with real processes: a world's scheduled `vision.lostPerson`, and
the simulated battery falling low mid-drive, each halt a long drive (trees/README.md's "Reacting while an
action runs", tried on the simulated robot)."""
from __future__ import annotations

import json
import os
import subprocess

from tests.integration.conftest import bmtree_cmd

TREE = """format: 1
root:
  parallel:
    - call: navigation.go_to
      name: drive
      inputs: {place: kitchen}
      timeout: 120
    - sequence:
        - {wait_event: %s, outputs: {%s: what}}
        - fail: "%s {what}"
  policy: one
"""


def run(tmp_path, world: str, tree: str):
    (tmp_path / "w.yaml").write_text(world)
    (tmp_path / "t.yaml").write_text(tree)
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    out = subprocess.run(bmtree_cmd("run", "--sim", "--world", str(tmp_path / "w.yaml"), str(tmp_path / "t.yaml")),
                         capture_output=True, text=True, timeout=120, env=env, stdin=subprocess.DEVNULL)
    log = next(line.split(": ", 1)[1] for line in out.stdout.splitlines() if line.startswith("run log: "))
    with open(log) as fh:
        records = [json.loads(line) for line in fh]
    return out, records


def drive_line(out):
    return [line.split() for line in out.stdout.split("calls:")[1].splitlines() if "navigation.go_to" in line]


def test_a_scheduled_lost_person_halts_a_long_drive(tmp_path):
    # the kitchen is ~8.2 m away at 0.5 m/s: ~16 s; the world loses Ana after 1 s
    out, records = run(tmp_path, "speed: 0.5\nevents:\n  - {at: 1.0, event: vision.lostPerson, params: {person: Ana}}\n",
                       TREE % ("vision.lostPerson", "person", "lost"))
    assert out.returncode == 1, out.stdout + out.stderr
    assert "reason: fail: lost Ana" in out.stdout, out.stdout
    ((_, _, target, status, took, *_),) = drive_line(out)
    assert (target, status) == ("navigation.go_to", "halted") and float(took.rstrip("s")) < 5.0, out.stdout
    (event,) = [r for r in records if r["type"] == "event"]
    assert (event["module"], event["event"], event["params"]) == ("vision", "lostPerson", {"person": "Ana"})
    assert 0.3 < event["t"] < 5.0


def test_the_battery_falling_low_mid_drive_halts_it(tmp_path):
    # 1 % per metre from 22 %: low (20 %) after 2 m, 1 s at 2 m/s; the kitchen is ~4 s away
    out, records = run(tmp_path, "speed: 2.0\nbattery: {level: 22, drain_per_metre: 1.0, low: 20}\n",
                       TREE % ("battery.low", "percentage", "battery low:"))
    assert out.returncode == 1, out.stdout + out.stderr
    assert "reason: fail: battery low: " in out.stdout, out.stdout
    ((_, _, target, status, took, *_),) = drive_line(out)
    assert (target, status) == ("navigation.go_to", "halted") and float(took.rstrip("s")) < 3.0, out.stdout
    (event,) = [r for r in records if r["type"] == "event"]
    assert (event["module"], event["event"]) == ("battery", "low") and 19.0 < event["params"]["percentage"] <= 20.0
