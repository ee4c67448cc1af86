"""The long-lived nodes (a module node, the C++ bridge, the Blackboard) against a master that does
not answer: SIGSTOPped, as a master whose machine dropped off the network (the kernel accepts
connections, nothing answers; see test_master_unreachable.py).

rospy and rosgraph ask the master with no timeout: a node started then sat in its start-up
without a word, a stop signal did nothing to a running node (its unregistering waited for the
master), and a question asked while serving (a caller's or a C++ node's URI) held what waited
for it. A node waits for its master and says so, comes up when it answers, and leaves without
unregistering. Every bound is against a hang, not a measure of speed.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from comm.rpc import master_api
from tests.conftest import REFERENCE
from tests.integration.conftest import NODES, bmtree_cmd
from tests.integration.faultkit import PROBE_CLASS, PROBE_JSON
from tests.integration.test_master_unreachable import _ends, _finish, _stopped
from tests.integration.watchkit import Lines

DEMO_JSON = os.path.join(REFERENCE, "DEMO_BM.json")
MODULE = ["-m", "modules.node", "--definition", PROBE_JSON, "--class", PROBE_CLASS]


def _node(graph, *args):
    proc = subprocess.Popen([sys.executable, *args], env=graph.env, text=True, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    return proc, Lines(proc.stdout)


def _registered(graph, node, topic, timeout=20.0):
    """Wait until ``node`` subscribes ``topic`` on the master (asked with a bound)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        subs = master_api("/test_nodes", 1.0, graph.uri).getSystemState()[1]
        if any(node in nodes for t, nodes in subs if t == topic):
            return
        time.sleep(0.05)
    raise AssertionError("%s does not subscribe %s after %g s" % (node, topic, timeout))


def test_a_module_node_waits_for_a_master_that_does_not_answer_says_so_and_comes_up_with_it(own_graph):
    """Started while its master is stopped: it says which master and that it keeps trying, comes
    up once the master answers, and a stop while the master is stopped again ends it."""
    with _stopped(own_graph):
        node, out = _node(own_graph, *MODULE)
        try:
            said = out.wait_for("the ROS master at %s does not answer" % own_graph.uri, 15)
        except AssertionError:
            _finish(node)
            raise
    try:
        assert "node bm_probe waits for it and keeps trying" in said, said
        out.wait_for("basic module 'probe' serving echo, work", 15)
        out.wait_for("answers again; node bm_probe starts", 5)
        with _stopped(own_graph):
            node.send_signal(signal.SIGINT)
            code = _ends(node, out, 15)
    finally:
        _finish(node)
    text = out.all_text()
    assert code == 0, text
    assert ("the ROS master at %s does not answer: leaving without unregistering" % own_graph.uri) in text, text
    assert "Traceback" not in text, text


def test_a_module_node_cancels_the_call_of_a_caller_killed_while_the_master_does_not_answer(own_graph, tmp_path):
    """The caller's process is watched from half a second into its call; when it dies, the node
    asks the master whether it was restarted elsewhere: that question is bounded, so the orphaned
    call is still cancelled while the master does not answer."""
    node, out = _node(own_graph, *MODULE)
    run = None
    try:
        out.wait_for("serving echo, work", 20)
        tree = tmp_path / "slow.yaml"
        tree.write_text("format: 1\nroot:\n  call: probe.work\n  inputs: {seconds: 60.0, tag: x}\n  timeout: 100\n")
        run, run_out = _node(own_graph, *bmtree_cmd("run", "--modules", PROBE_JSON, "--wait", "15", str(tree))[1:])
        run_out.wait_for("RUNNING", 30)
        time.sleep(1.5)  # the caller is watched now (its URI looked up, a connection kept to it)
        with _stopped(own_graph):
            run.send_signal(signal.SIGKILL)
            run.wait(5)
            line = out.wait_for("its caller /bmtree_%d_" % run.pid, 15)
    finally:
        _finish(*[p for p in (node, run) if p is not None])
    assert "cancelled call" in line and "of module probe" in line, out.text()


def test_the_blackboard_waits_for_a_master_that_does_not_answer_and_a_stop_ends_it(own_graph):
    """At start (it looks for another Blackboard node first) and while it serves."""
    with _stopped(own_graph):
        early, early_out = _node(own_graph, "-m", "blackboard.node", "--db", ":memory:")
        try:
            said = early_out.wait_for("the ROS master at %s does not answer" % own_graph.uri, 15)
            early.send_signal(signal.SIGINT)
            early_code = _ends(early, early_out, 10)
        finally:
            _finish(early)
    assert "node blackboard waits for it and keeps trying" in said, said
    assert early_code == 0, early_out.all_text()

    bb, out = _node(own_graph, "-m", "blackboard.node", "--db", ":memory:")
    try:
        out.wait_for("blackboard storing in :memory:", 20)
        time.sleep(1.0)  # serving (the stop is not one during its start-up)
        with _stopped(own_graph):
            bb.send_signal(signal.SIGTERM)
            code = _ends(bb, out, 15)
    finally:
        _finish(bb)
    text = out.all_text()
    assert code == 0, text
    assert ("the ROS master at %s does not answer: leaving without unregistering" % own_graph.uri) in text, text
    assert "Traceback" not in text, text


def test_a_bridge_whose_cpp_node_dies_mid_call_answers_while_the_master_does_not(own_graph, tmp_path):
    """The bridge asks the master what became of its C++ node (exited, restarted, killed) from the
    call's own thread: bounded, the call ends 'exited during the call' instead of its timeout."""
    cpp, _ = _node(own_graph, os.path.join(NODES, "original_cpp_demo_bm.py"), "_delay:=60")
    bridge, out = _node(own_graph, "-m", "modules.bridge", "--definition", DEMO_JSON, "--call-timeout", "90")
    run = None
    try:
        out.wait_for("bridge for 'DEMO_BM': C++ node /DEMO_BM connected", 30)
        tree = tmp_path / "demo.yaml"
        tree.write_text("format: 1\nroot:\n  call: DEMO_BM.functionA\n  inputs: {Aviso: hola, Bandera: true}\n"
                        "  timeout: 60\n")
        run, run_out = _node(own_graph, *bmtree_cmd("run", "--modules", DEMO_JSON, "--wait", "15", str(tree))[1:])
        run_out.wait_for("RUNNING", 30)
        time.sleep(1.0)  # the call reached the C++ node, which answers in 60 s
        with _stopped(own_graph):
            cpp.send_signal(signal.SIGKILL)
            cpp.wait(5)
            code = _ends(run, run_out, 20)
    finally:
        _finish(*[p for p in (cpp, bridge, run) if p is not None])
    text = run_out.all_text()
    assert code == 1, text
    assert "the C++ node /DEMO_BM exited during the call (no BM_output)" in text, text


def test_a_bridge_that_looks_for_its_cpp_node_while_the_master_does_not_answer_gives_up_after_wait(own_graph):
    """No C++ node: the bridge asks the master for it until --wait ends; a master that stops
    answering meanwhile does not hold that wait."""
    bridge, out = _node(own_graph, "-m", "modules.bridge", "--definition", DEMO_JSON, "--wait", "6")
    try:
        _registered(own_graph, "/DEMO_BM_bridge", "/DEMO_BM/BM_info")  # its last topic: it looks for the node now
        with _stopped(own_graph):
            code = _ends(bridge, out, 6 + 15)
    finally:
        _finish(bridge)
    text = out.all_text()
    assert code == 3, text
    assert "the C++ node of module 'DEMO_BM' is not ready after 6s: the ROS master does not answer" in text, text
    assert "Traceback" not in text, text
