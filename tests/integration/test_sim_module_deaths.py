"""A module process that ``bmtree run --sim`` started ends or hangs: the run says why, from what bmtree
knows of its own child (exit code, signal, an injected ``die``) and from the end of its log, not only
``its process is gone`` or ``modules did not announce themselves``."""
from __future__ import annotations

import json
import os
import subprocess

from tests.integration.conftest import bmtree_cmd

DEFINITION = {"Basic Module": "gripper", "Brief Description": "", "Hardware Required": [], "Functions": [
    {"Name": "grasp", "Exec-condition": "", "Description": "",
     "Input-params": [{"Name": "object", "Data-type": "std_msgs/String", "Description": ""}],
     "Output-params": [{"Name": "force", "Data-type": "std_msgs/Float64", "Description": ""}]}]}

MODULE = '''import os
import time

from modules import BasicModule


class Gripper(BasicModule):
    def setup(self, node):
        how = os.environ.get("GRIPPER_SETUP")
        if how == "raise":  # once its node answers: not caught by a wait for the node to register
            time.sleep(1.0)
            raise RuntimeError("no /dev/ttyUSB0")
        if how == "block":
            print("connecting to gripper...")
            while True:
                time.sleep(0.2)

    def grasp(self, object):
        if object.data == "crash":
            os._exit(7)
        return {"force": 12.5}
'''

TREE = "format: 1\ninputs: {object: {default: cup}}\nroot: {call: gripper.grasp, inputs: {object: $object}}\n"


def _run(tmp_path, *args, setup="", timeout=120):
    (tmp_path / "gripper.json").write_text(json.dumps(DEFINITION))
    (tmp_path / "gripper.py").write_text(MODULE)
    (tmp_path / "t.yaml").write_text(TREE)
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"), GRIPPER_SETUP=setup)
    module = "%s=%s:Gripper" % (tmp_path / "gripper.json", tmp_path / "gripper.py")
    return subprocess.run(bmtree_cmd("run", "--sim", "-q", "--no-record", "--module", module, *args,
                                     str(tmp_path / "t.yaml")),
                          capture_output=True, text=True, timeout=timeout, env=env, stdin=subprocess.DEVNULL)


def test_a_module_killed_by_an_injected_die_says_the_injected_reason(tmp_path):
    (tmp_path / "world.yaml").write_text("faults:\n  gripper.grasp: {die: motor driver fault}\n")
    out = _run(tmp_path, "--world", str(tmp_path / "world.yaml"))
    assert out.returncode == 1, out.stdout + out.stderr
    assert "reason: gripper.grasp module_lost: module gripper lost: node /bm_gripper stopped (its process exited: " \
           "motor driver fault (injected fault))" in out.stdout, out.stdout


def test_a_module_that_exits_mid_call_says_its_exit_code(tmp_path):
    out = _run(tmp_path, "--set", "object=crash")
    assert out.returncode == 1, out.stdout + out.stderr
    assert "module gripper lost: node /bm_gripper stopped (its process exited with code 7)" in out.stdout, out.stdout


def test_a_setup_that_never_returns_is_given_up_after_wait_saying_where_it_is(tmp_path):
    out = _run(tmp_path, "--wait", "3", setup="block")
    assert out.returncode == 3, out.stdout + out.stderr
    assert "error: your module gripper did not announce itself within" in out.stderr, out.stderr
    assert "its process is still running: its setup() has not returned after" in out.stderr, out.stderr
    assert "(it is at gripper.py:16 in setup)" in out.stderr, out.stderr
    assert out.stderr.rstrip().endswith("bm_gripper.out ends:\n  connecting to gripper..."), out.stderr


def test_a_setup_that_raises_is_said_at_once_with_the_exit_code(tmp_path):
    # --wait far beyond the test's own timeout: only an exit noticed at once ends the run in time
    out = _run(tmp_path, "--wait", "600", setup="raise", timeout=90)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "error: your module gripper exited with code 2 during start-up; its log " in out.stderr, out.stderr
    assert "  error: Gripper.setup raised RuntimeError: no /dev/ttyUSB0 (gripper.py:12 in setup)" in out.stderr, \
        out.stderr
