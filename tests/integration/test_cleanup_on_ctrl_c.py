"""Ctrl-C on ``bmtree run`` of a tree with ``cleanup:``: root is halted, the cleanup's calls reach the
real modules (processes of a private graph), the run log says so, the exit code is an interrupted run's."""
from __future__ import annotations

import os
import signal
import subprocess
import time

from coordinator.runlog import read_log
from tests.integration.conftest import bmtree_cmd, processes_running

TREE = """format: 1
name: go_and_clean
root:
  call: navigation.go_to
  inputs: {place: kitchen}
cleanup:
  sequence:
    - call: speech.say
      inputs: {text: "Sorry, I was {ended}."}
    - call: navigation.where_am_i
      outputs: {room: room}
cleanup_timeout: 20
"""


def test_ctrl_c_runs_the_cleanup_on_the_real_modules(tmp_path, slow_world):
    tree = tmp_path / "go_and_clean.yaml"
    tree.write_text(TREE)
    log_path = tmp_path / "run.jsonl"
    proc = subprocess.Popen(bmtree_cmd("run", "--sim", "--world", slow_world, "--record", str(log_path), str(tree)),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    seen = ""
    while "RUNNING   navigation.go_to" not in seen and time.monotonic() < deadline and proc.poll() is None:
        seen += proc.stdout.readline()
    time.sleep(0.5)   # driving (about 4 s to the kitchen in the slow world)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    out = seen + out
    assert proc.returncode == 3, out + err
    assert "interrupted: running calls were cancelled, then the cleanup ran" in err, err
    assert "reason: interrupted while 'navigation.go_to' was running" in out, out
    assert "NOTICE    interrupted while 'navigation.go_to' was running: running the cleanup" in out, out
    assert "cleanup (root stopped): succeeded in" in out, out
    assert "navigation.go_to           interrupted" in out, out
    log = read_log(str(log_path))
    assert log.end["status"] == "INVALID" and log.end["cleanup"]["status"] == "SUCCESS"
    assert log.end["cleanup"]["ended"] == "stopped"
    ends = {r["target"]: r for r in log.of_type("call_end")}
    assert ends["navigation.go_to"]["status"] == "halted"
    # answered by the module processes: the cleanup's calls reached them after the stop
    assert ends["speech.say"]["status"] == "succeeded" and ends["speech.say"]["answer"] == "succeeded"
    assert ends["navigation.where_am_i"]["answer"] == "succeeded"
    assert ends["navigation.where_am_i"]["outputs"]["room"]   # where the halted drive left the robot
    starts = {r["target"]: r for r in log.of_type("call_start")}
    assert starts["speech.say"]["inputs"] == {"text": "Sorry, I was stopped."}
    assert starts["speech.say"]["t"] >= ends["navigation.go_to"]["t"]
    assert processes_running(slow_world) == []
    assert os.path.exists(str(log_path))
