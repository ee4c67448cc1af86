"""A shutdown request of ``bmtree run``'s node (``rosnode kill``: its XML-RPC ``shutdown``; or the master,
when a node of the same name registers) stops the run as Ctrl-C does, with real processes: root halted,
its call cancelled at the module, the cleanup's calls answered by the modules while ROS is still up,
the request in the run log, exit 3, and the request answered once the process left the master."""
from __future__ import annotations

import json
import subprocess
import threading
import time
import xmlrpc.client

import pytest

from coordinator.runlog import read_log
from tests.integration.conftest import bmtree_cmd, start_sim_module
from tests.integration.test_recording_ros import world

TREE = """format: 1
name: drive_and_clean
root:
  call: navigation.go_to
  inputs: {place: kitchen}
  timeout: 60
cleanup:
  sequence:
    - call: speech.say
      inputs: {text: "Sorry, I was {ended}."}
    - call: navigation.go_to
      inputs: {place: entrance}
cleanup_timeout: 8
"""


def _run_node(master, pid):
    """The node of the ``bmtree run`` process ``pid`` (``/bmtree_<pid>_<ms>``)."""
    _, _, state = master.getSystemState("/test")
    names = {n for kind in state for _, nodes in kind for n in nodes if n.startswith("/bmtree_%d_" % pid)}
    assert len(names) == 1, names
    return names.pop()


@pytest.mark.parametrize("how", ["rosnode kill", "same name"])
def test_a_shutdown_request_of_the_run_node_stops_the_run_as_ctrl_c_does(ros_graph, tmp_path, how):
    crawl = world(tmp_path, "crawl.yaml", speed=0.25)   # the kitchen half a minute away
    start_sim_module(ros_graph, "navigation", crawl)
    start_sim_module(ros_graph, "speech")
    tree = tmp_path / "drive_and_clean.yaml"
    tree.write_text(TREE)
    log_path = tmp_path / "run.jsonl"
    proc = subprocess.Popen(bmtree_cmd("run", "-q", "--record", str(log_path), str(tree)), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL, env=ros_graph.env)
    master = xmlrpc.client.ServerProxy(ros_graph.uri)
    fake_api = "http://127.0.0.1:9/"
    node = ""
    try:
        end = time.monotonic() + 30
        while not (log_path.exists() and '"call_start"' in log_path.read_text()):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < end, "the drive never started"
            time.sleep(0.05)
        time.sleep(0.8)   # driving to the kitchen
        node = _run_node(master, proc.pid)
        answer = []
        asked = time.monotonic()
        if how == "rosnode kill":
            code, _, uri = master.lookupNode("/test", node)
            assert code == 1
            # rospy answers once the node has shut down: the run's cleanup comes first
            asking = threading.Thread(target=lambda: answer.append(
                xmlrpc.client.ServerProxy(uri).shutdown("/test_caller", "rosnode kill")), daemon=True)
            asking.start()
        else:   # the master shuts down the node whose name another node registers with
            master.registerSubscriber(node, "/test_same_name", "std_msgs/String", fake_api)
        try:
            out, err = proc.communicate(timeout=15)   # cleanup_timeout 8, and the leave
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
            pytest.fail("bmtree run still ran 15 s after the shutdown request:\n" + out + err)
        took = time.monotonic() - asked
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        if node and how == "same name":
            master.unregisterSubscriber(node, "/test_same_name", fake_api)
    assert proc.returncode == 3, out + err
    assert took < 12, "the run took %.1f s to end after the shutdown request" % took   # cleanup_timeout 8
    if how == "rosnode kill":
        asking.join(5)
        assert answer == [[1, "shutdown", 0]]   # rosnode kill reports the node killed
        said = "external shutdown request from [/test_caller]: [rosnode kill]"
    else:
        said = "new node registered with same name"
    assert "interrupted by a shutdown request of its node (external shutdown request from [" in err, err
    assert "running calls were cancelled, then the cleanup ran" in err, err
    assert "cleanup (root stopped): succeeded in" in out, out
    run = read_log(str(log_path))
    notices = [n for n in run.of_type("notice") if n["what"] == "shutdown_request"]
    assert len(notices) == 1 and said in notices[0]["text"] and node in notices[0]["text"], notices
    assert "stopping the run as Ctrl-C does" in notices[0]["text"]
    assert run.end["status"] == "INVALID" and run.end["cleanup"]["status"] == "SUCCESS", json.dumps(run.end)
    assert run.end["cleanup"]["ended"] == "stopped"
    starts = run.of_type("call_start")
    ends = {r["call_id"]: r for r in run.of_type("call_end")}
    assert [(s["target"], s["inputs"]) for s in starts] == [
        ("navigation.go_to", {"place": "kitchen"}), ("speech.say", {"text": "Sorry, I was stopped."}),
        ("navigation.go_to", {"place": "entrance"})]
    drive, say, back = (ends[s["call_id"]] for s in starts)
    assert drive["status"] == "halted" and notices[0]["t"] <= drive["t"]
    assert say["answer"] == "succeeded"
    # answered by the navigation module, not "busy": the root's drive was cancelled there first
    assert back["answer"] == "succeeded" and back["outputs"]["room"] == "entrance", back
    # the node left the master (its topics unregistered before rospy's own shutdown ended)
    _, _, state = master.getSystemState("/test")
    assert not [t for kind in state for t, nodes in kind if node in nodes and t != "/test_same_name"], state
