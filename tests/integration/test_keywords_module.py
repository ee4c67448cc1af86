"""The README's topic-and-service example (modules/example/keywords.*): a ROS topic of another node
becomes module events a ``wait_event`` takes, and a ROS service a module function a ``call`` makes,
with a real stand-in recognizer node and ``bmtree run``."""
from __future__ import annotations

import os
import subprocess
import sys

from tests.conftest import ROOT
from tests.integration.conftest import NODES, bmtree_cmd, wait_announced

EXAMPLE = os.path.join(ROOT, "modules", "example")
DEFINITION = os.path.join(EXAMPLE, "keywords.json")
TREE = """format: 1
root:
  sequence:
    - call: keywords.listen
      inputs: {enabled: true}
    - wait_event: keywords.heard
      where: 'text == "stop"'
      outputs: {text: said}
      timeout: 10
    - check: 'said == "stop"'
"""


def _start_module(ros_graph):
    ros_graph.start_node(["-m", "modules.node", "--definition", DEFINITION, "--class",
                          os.path.join(EXAMPLE, "keywords.py") + ":Keywords"], "/bm_keywords")
    wait_announced("keywords")


def _run(tmp_path):
    tree = tmp_path / "tree.yaml"
    tree.write_text(TREE)
    return subprocess.run(bmtree_cmd("run", "-q", "--modules", DEFINITION, str(tree)), capture_output=True,
                          text=True, timeout=120, env=dict(os.environ), stdin=subprocess.DEVNULL)


def test_a_service_call_then_an_event_from_a_topic(ros_graph, tmp_path):
    ros_graph.start_node([sys.executable, os.path.join(NODES, "recognizer.py")], "/recognizer")
    _start_module(ros_graph)
    out = _run(tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    calls = [line for line in out.stdout.splitlines() if line.startswith("  +")]
    assert len(calls) == 1 and "keywords.listen" in calls[0] and "succeeded" in calls[0]


def test_a_service_that_is_not_there_fails_the_call_saying_so(ros_graph, tmp_path):
    _start_module(ros_graph)
    out = _run(tmp_path)
    assert out.returncode == 1, out.stdout + out.stderr
    assert ("reason: keywords.listen failed: /speech_recognition/enable: timeout exceeded while waiting for "
            "service /speech_recognition/enable") in out.stdout, out.stdout
