"""What bmtree-bridge says when its C++ node is not there to serve: one clear sentence, exit 3."""
from __future__ import annotations

import os
import subprocess
import sys
import xmlrpc.client

from tests.conftest import REFERENCE, until
from tests.integration.conftest import NODES

DEMO_JSON = os.path.join(REFERENCE, "DEMO_BM.json")

_DEAF = """
import rospy
from std_msgs.msg import String
rospy.init_node("deaf_tool")
rospy.Subscriber("/DEMO_BM/BM_input", String, lambda m: None)  # a tool that only listens to BM_input
rospy.spin()
"""


def _bridge(ros_graph):
    return subprocess.run([sys.executable, "-m", "modules.bridge", "--definition", DEMO_JSON, "--wait", "0.5"],
                          capture_output=True, text=True, timeout=60, env=ros_graph.env, stdin=subprocess.DEVNULL)


def test_a_cpp_node_killed_outright_is_said_to_be_not_running(ros_graph):
    """Its registration stays on the master: the bridge says it is gone, not every topic it misses."""
    cpp = ros_graph.start_node([sys.executable, os.path.join(NODES, "original_cpp_demo_bm.py")], "/DEMO_BM")
    master = xmlrpc.client.ServerProxy(ros_graph.uri)
    until(lambda: "/DEMO_BM" in dict(master.getSystemState("/test")[2][1]).get("/DEMO_BM/BM_input", []), 20)
    ros_graph.kill_node(cpp)
    out = _bridge(ros_graph)
    assert out.returncode == 3, out.stdout + out.stderr
    assert "the C++ node of module 'DEMO_BM' is not ready after 0.5s: the C++ node /DEMO_BM is registered with " \
           "the master but not running (its process is gone: start it again) (the bridge waits --wait seconds " \
           "for it)" in out.stderr, out.stderr
    assert "does not receive" not in out.stderr and "Traceback" not in out.stderr


def test_a_node_connected_to_nothing_is_said_in_one_clause_per_direction(ros_graph, tmp_path):
    """A live node goes before one killed outright (the earlier test's /DEMO_BM, still registered)."""
    script = tmp_path / "deaf.py"
    script.write_text(_DEAF)
    ros_graph.start_node([sys.executable, str(script)], "/deaf_tool")
    master = xmlrpc.client.ServerProxy(ros_graph.uri)
    until(lambda: "/deaf_tool" in dict(master.getSystemState("/test")[2][1]).get("/DEMO_BM/BM_input", []), 20)
    out = _bridge(ros_graph)
    assert out.returncode == 3, out.stdout + out.stderr
    said = out.stderr.split("is not ready after 0.5s: ", 1)[1]
    assert said.startswith("/deaf_tool does not receive /DEMO_BM/bool, /DEMO_BM/string; /deaf_tool does not publish "
                           "/DEMO_BM/BM_output, /DEMO_BM/string, /DEMO_BM/bool to the bridge"), out.stderr


def test_a_call_that_would_wait_longer_than_the_bridge_is_warned_of(ros_graph, tmp_path):
    """The bridge announces its --call-timeout: a tree timeout beyond it would end in the bridge's
    'no BM_output … it hangs or crashed', blaming a node that was only slow."""
    from tests.integration.conftest import bmtree_cmd, wait_announced

    ros_graph.start_node([sys.executable, os.path.join(NODES, "original_cpp_demo_bm.py")], "/DEMO_BM")
    ros_graph.start_node(["-m", "modules.bridge", "--definition", DEMO_JSON, "--call-timeout", "2"], "/DEMO_BM_bridge")
    wait_announced("DEMO_BM")
    tree = tmp_path / "patient.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n    - call: DEMO_BM.functionA\n      inputs: {Aviso: hola, "
                    "Bandera: true}\n      timeout: 10\n    - call: DEMO_BM.functionA\n      inputs: {Aviso: b, "
                    "Bandera: false}\n      timeout: 1.5\n")
    out = subprocess.run(bmtree_cmd("run", str(tree), "-q"), capture_output=True, text=True, timeout=120,
                         env=ros_graph.env)
    assert out.returncode == 0, out.stdout + out.stderr
    warned = [line for line in out.stderr.splitlines() if "gives up a call after" in line]
    assert warned == ["warning: %s:4:13: call DEMO_BM.functionA waits up to 10 s, but module 'DEMO_BM' gives up a "
                      "call after 2 s (a bridge's --call-timeout): the call would fail then; give the module a "
                      "longer limit" % tree], out.stderr
