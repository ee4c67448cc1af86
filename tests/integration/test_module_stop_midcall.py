"""A Python module's node stopped while a call runs (Ctrl-C, SIGTERM, ``rosnode kill``), with real processes.

Before, the process ended under the function: ``self.context.sleep(20)`` never returned, the code after it
("stop the motors") never ran, no answer went out (the run said ``module_lost … its process is gone``) and
the module's log said nothing of the call. Now the stop cancels the call as a coordinator's cancel does,
waits up to the 1 s grace for its code, answers ``cancelled`` saying why, and the node exits at once.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import xmlrpc.client

import pytest

from tests.integration.conftest import wait_announced
from tests.integration.test_cpp_modules import GRIPPER_JSON, gripper_exe, start_gripper  # noqa: F401 - a fixture

STOPPER_PY = '''
import os
import time

from modules import BasicModule


class Stopper(BasicModule):
    concurrent = {"stuck"}

    def work(self, seconds):
        ok = self.context.sleep(seconds.data)
        time.sleep(0.2)                                    # "stop the motors"
        with open(os.environ["STOPPER_MARKER"], "a") as fh:
            fh.write("work: sleep returned %r, cancelled %r; motors stopped\\n" % (ok, bool(self.context.cancelled)))
        return {"success": ok}

    def stuck(self):
        end = time.monotonic() + 30
        while time.monotonic() < end:                      # never looks at its cancel
            time.sleep(0.05)
        return {"success": True}

    def shutdown(self):
        with open(os.environ["STOPPER_MARKER"], "a") as fh:
            fh.write("shutdown() called\\n")
'''


def _setup(tmp_path, ros_graph, *options):
    out = [{"Name": "success", "Data-type": "std_msgs/Bool", "Description": "done"}]
    fns = [{"Name": "work", "Exec-condition": "", "Description": "sleeps, then stops the motors",
            "Input-params": [{"Name": "seconds", "Data-type": "std_msgs/Float64", "Description": "s"}],
            "Output-params": out},
           {"Name": "stuck", "Exec-condition": "", "Description": "ignores its cancel", "Input-params": [],
            "Output-params": out}]
    definition = tmp_path / "stopper.json"
    definition.write_text(json.dumps({"Basic Module": "stopper", "Brief Description": "stops mid-call",
                                      "Hardware Required": [], "Functions": fns}))
    (tmp_path / "stopper.py").write_text(STOPPER_PY)
    marker = tmp_path / "marker.txt"
    proc = ros_graph.start_node(["-m", "modules.node", "--definition", str(definition), "--class",
                                 str(tmp_path / "stopper.py") + ":Stopper", *options], "/bm_stopper",
                                env={"STOPPER_MARKER": str(marker)})
    wait_announced("stopper")
    return proc, definition, marker


class _Run:
    """``bmtree run`` of one call as a process, its output lines read as they come."""

    def __init__(self, tmp_path, definition, call):
        tree = tmp_path / "tree.yaml"  # the call, its inputs (on lines of their own) and a timeout
        tree.write_text("format: 1\nroot:\n  call: %s\n  timeout: 60\n" % call)
        self.proc = subprocess.Popen([sys.executable, "-m", "coordinator", "run", "--no-record", str(tree),
                                      "--modules", str(definition)], stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, env=dict(os.environ),
                                     stdin=subprocess.DEVNULL)
        self.lines = []
        self._new = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            with self._new:
                self.lines.append(line)
                self._new.notify_all()

    def wait_line(self, *parts, timeout=20.0):
        with self._new:
            return self._new.wait_for(lambda: any(all(p in line for p in parts) for line in self.lines), timeout)

    def end(self, timeout=30.0):
        try:
            self.proc.wait(timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.send_signal(signal.SIGINT)
                self.proc.wait(10)
        time.sleep(0.1)
        return "".join(self.lines)


def _stop(ros_graph, proc, how):
    if how == "rosnode kill":  # the node's XML-RPC shutdown, as rosnode kill asks it
        uri = xmlrpc.client.ServerProxy(ros_graph.uri).lookupNode("/test", "/bm_stopper")[2]

        def ask():
            try:
                xmlrpc.client.ServerProxy(uri).shutdown("/rosnode_test", "user request")
            except OSError:  # a module node may exit before its answer goes out (rospy's XML-RPC thread)
                pass
        threading.Thread(target=ask, daemon=True).start()
    else:
        proc.send_signal(how)


def _module_log(ros_graph, node="bm_stopper"):
    with open(os.path.join(ros_graph.ros_home, "%s.out" % node), errors="replace") as fh:
        return fh.read()


@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGTERM, "rosnode kill"],
                         ids=["SIGINT", "SIGTERM", "rosnode-kill"])
def test_a_module_stopped_mid_call_cancels_the_call_runs_its_code_and_answers(ros_graph, tmp_path, how):
    proc, definition, marker = _setup(tmp_path, ros_graph)
    run = _Run(tmp_path, definition, "stopper.work\n  inputs: {seconds: 20}")
    assert run.wait_line("RUNNING", "stopper.work"), run.end(1)
    time.sleep(0.5)
    stopped = time.monotonic()
    _stop(ros_graph, proc, how)
    code = proc.wait(10)
    took = time.monotonic() - stopped
    ros_graph.nodes.remove(proc)
    out = run.end()
    cause = {signal.SIGINT: "SIGINT", signal.SIGTERM: "SIGTERM"}.get(
        how, "a shutdown request from /rosnode_test: user request")
    why = "the module's node /bm_stopper is stopping (%s)" % cause
    # the code after the wait ran (the motors stopped), then the author's shutdown()
    assert marker.read_text() == "work: sleep returned False, cancelled True; motors stopped\nshutdown() called\n", (
        out, _module_log(ros_graph))
    # the coordinator got the answer, not module_lost
    assert "stopper.work cancelled: %s; its code returned after the cancel" % why in out, out
    assert "module_lost" not in out and "lost" not in out.split("calls:")[-1], out
    assert run.proc.returncode == 1, out
    # the module's log says what became of the call
    assert "cancelled call " in _module_log(ros_graph) and "of stopper.work: %s; its code returned" % why \
        in _module_log(ros_graph), _module_log(ros_graph)
    assert code == 0 and took < 3.0, (code, took, _module_log(ros_graph))


def test_a_call_whose_code_ignores_the_stop_is_answered_after_the_grace(ros_graph, tmp_path):
    proc, definition, marker = _setup(tmp_path, ros_graph)
    run = _Run(tmp_path, definition, "stopper.stuck")
    assert run.wait_line("RUNNING", "stopper.stuck"), run.end(1)
    time.sleep(0.5)
    stopped = time.monotonic()
    proc.send_signal(signal.SIGINT)
    code = proc.wait(10)
    took = time.monotonic() - stopped
    ros_graph.nodes.remove(proc)
    out = run.end()
    why = "the module's node /bm_stopper is stopping (SIGINT)"
    assert ("stopper.stuck cancelled: %s, but its code has not returned 1s after the cancel: the node stops without "
            "it, and what it drives may not have stopped" % why) in out, out
    assert "module_lost" not in out, out
    log = _module_log(ros_graph)
    assert "of stopper.stuck: %s, but its code has not returned 1s after the cancel; the node stops without it" % why \
        in log, log
    assert marker.read_text() == "shutdown() called\n"
    assert code == 0 and 0.9 < took < 3.5, (code, took, log)


def test_a_second_ctrl_c_leaves_at_once(ros_graph, tmp_path):
    """Within the grace a stuck call gets, a second Ctrl-C leaves without waiting out the grace (nor
    answering: the run learns of it as of a killed node)."""
    proc, definition, marker = _setup(tmp_path, ros_graph)
    run = _Run(tmp_path, definition, "stopper.stuck")
    assert run.wait_line("RUNNING", "stopper.stuck"), run.end(1)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    time.sleep(0.3)  # within the grace, a person's second Ctrl-C (not a re-sent burst)
    again = time.monotonic()
    proc.send_signal(signal.SIGINT)
    code = proc.wait(10)
    took = time.monotonic() - again
    ros_graph.nodes.remove(proc)
    out = run.end()
    log = _module_log(ros_graph)
    assert "stopped again: leaving without unregistering" in log, log
    assert "stopper.stuck cancelled" not in out and "module_lost" in out, out  # the grace was not waited out
    assert code == 0 and took < 1.5, (code, took, log)


def test_a_bridge_stopped_mid_call_cancels_the_cpp_function_and_answers(ros_graph, gripper_exe, tmp_path):  # noqa: F811
    """The bridge shares the node's stop: the cancel reaches the C++ node (built with bmtree's library), whose
    sleepFor() returns false, and the call is answered before the bridge leaves."""
    cpp, bridge = start_gripper(ros_graph, gripper_exe)
    run = _Run(tmp_path, GRIPPER_JSON, "gripper.squeeze\n  inputs: {seconds: 20.0, label: long}")
    assert run.wait_line("RUNNING", "gripper.squeeze"), run.end(1)
    time.sleep(0.5)
    stopped = time.monotonic()
    bridge.send_signal(signal.SIGINT)
    code = bridge.wait(10)
    took = time.monotonic() - stopped
    ros_graph.nodes.remove(bridge)
    out = run.end()
    why = "the module's node /gripper_bridge is stopping (SIGINT)"
    assert "gripper.squeeze cancelled: %s; its code returned after the cancel" % why in out, (
        out, _module_log(ros_graph, "gripper_bridge"))
    assert "gripper: squeeze cancelled, fingers stopped" in _module_log(ros_graph, "gripper")
    assert cpp.poll() is None  # the C++ node serves on
    assert code == 0 and took < 3.0, (code, took, _module_log(ros_graph, "gripper_bridge"))
