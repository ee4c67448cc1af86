"""Original modules' results (no call id) belong to the module whose node published them:
``bmtree run --legacy MODULE=/node``, the coordinator's correlation and the Blackboard's storage."""
from __future__ import annotations

import os
import subprocess
import sys

from tests.conftest import REFERENCE
from tests.integration.conftest import NODES, bmtree_cmd

LEGACY = REFERENCE


def run(*args):
    return subprocess.run(bmtree_cmd(*args), capture_output=True, text=True, timeout=120, env=dict(os.environ),
                          stdin=subprocess.DEVNULL)


TREE = """format: 1
root:
  sequence:
    - call: PYTHON_BM.graspObject
      inputs: {target_pos: {x: 0.3, y: 0.1, z: 0.9}, obj_radius: 0.3}
      outputs: {final_pos: held_at}
    - check: 'held_at.x == 0.3'
    - call: PYTHON_BM.goSafePos
    - recall: {stored: PYTHON_BM/graspObject/final_pos, safe: PYTHON_BM/goSafePos/final_pos}
    - check: 'stored.x == 0.3 and stored.z == 0.9 and safe.z == 0.5'
"""


def test_legacy_node_named_on_the_command_line_and_its_results_identified(ros_graph, tmp_path):
    ros_graph.start_node(["-m", "blackboard.node", "--db", str(tmp_path / "bb.sqlite")], "/blackboard")
    ros_graph.start_node([sys.executable, os.path.join(NODES, "legacy_python_bm.py"), "__name:=arm_driver"],
                         "/arm_driver")
    # answers every call at once with success: false, from a node that is no module of the run
    ros_graph.start_node([sys.executable, os.path.join(NODES, "stray_result_node.py"), "_subscribers:=2"], "/stray")
    tree = tmp_path / "arm.yaml"
    tree.write_text(TREE)

    out = run("run", str(tree), "--modules", LEGACY, "--wait", "1", "-q")
    assert out.returncode == 3, out.stdout + out.stderr
    assert "module 'PYTHON_BM' is not running" in out.stderr and "--legacy PYTHON_BM=/node" in out.stderr

    out = run("run", str(tree), "--modules", LEGACY, "--legacy", "PYTHON_BM=/arm_driver", "-q")
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.count("succeeded") == 2

    live = run("modules", "--live")
    assert "PYTHON_BM  (node /arm_driver, original module)" in live.stdout, live.stdout


def test_legacy_option_errors_exit_2(ros_master, tmp_path):
    tree = tmp_path / "arm.yaml"
    tree.write_text(TREE)
    out = run("run", str(tree), "--modules", LEGACY, "--legacy", "NOPE=/x", "-q")
    assert out.returncode == 2 and "--legacy names module 'NOPE', which has no definition" in out.stderr
    out = run("run", str(tree), "--modules", LEGACY, "--legacy", "PYTHON_BM", "-q")
    assert out.returncode == 2 and "--legacy takes MODULE=/node" in out.stderr
