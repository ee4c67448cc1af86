"""A module known to be gone ends what waits on it, with real processes.

A module node stopped cleanly (Ctrl-C, ``rosnode kill``) removes its announcement and unregisters:
the watchdog found no node for it, and a call with ``timeout: none`` sent afterwards waited for
ever, then ran on the node started next. A ``wait_event`` whose module was killed waited for ever,
unwatched. A call held for a module's node to connect waited without bound, and one to an original
module whose node died went into its dead connection.
"""
from __future__ import annotations

import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time

import pytest
import rospy

from comm.liveness import ModuleLost
from comm.messages import FunctionResult
from coordinator.ros_transport import RosTransport
from modules.definition import load_definitions
from modules.discovery import PARAM_ROOT
from tests.conftest import REFERENCE
from tests.integration.conftest import NODES, start_sim_module
from tests.integration.faultkit import PROBE_JSON, probe_def, start_probe, wait_item


class _Run:
    """``bmtree run TREE`` as a process, its output lines read as they come (with their time)."""

    def __init__(self, tmp_path, tree_text, *args):
        tree = tmp_path / "tree.yaml"
        tree.write_text("format: 1\nroot:\n" + tree_text)
        self.proc = subprocess.Popen([sys.executable, "-m", "coordinator", "run", str(tree), "--modules", PROBE_JSON,
                                      *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     env=dict(os.environ))
        self.lines = []
        self._new = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            with self._new:
                self.lines.append((time.monotonic(), line))
                self._new.notify_all()

    def wait_line(self, *parts, timeout=10.0):
        """When the first line with all of ``parts`` came (None if none within ``timeout``)."""
        end = time.monotonic() + timeout
        with self._new:
            while True:
                for at, line in self.lines:
                    if all(p in line for p in parts):
                        return at
                if not self._new.wait(max(0.0, end - time.monotonic())) and time.monotonic() >= end:
                    return None

    def end(self, timeout=30.0):
        try:
            self.proc.wait(timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.send_signal(signal.SIGINT)
                self.proc.wait(10)
        time.sleep(0.1)
        return "".join(line for _, line in self.lines)


def _calls(out):
    return [line.split() for line in out.split("calls:")[-1].splitlines() if line.strip().startswith("+")]


def test_a_call_with_no_time_limit_to_a_module_that_stopped_ends_and_never_runs_later(ros_graph, tmp_path):
    """The audit's follower: stopped mid-call, the tree's next call (timeout: none) sat pending until the
    node was started again 40 s later, and then ran. It ends module_lost at once now (the call running when
    the node stopped is answered cancelled by the stopping node); the node started again takes the calls
    made after it is back."""
    proc = start_probe(ros_graph)
    run = _Run(tmp_path, "  sequence:\n"
                         "    - force_success: {call: probe.work, inputs: {seconds: 100, tag: first}, timeout: none}\n"
                         "    - wait: 1\n"  # the stopped node answers the first call, then leaves the graph
                         "    - force_success: {call: probe.work, inputs: {seconds: 0.1, tag: second}, timeout: none}\n"
                         "    - wait: 5\n"
                         "    - call: probe.echo\n      inputs: {tag: third}\n      timeout: none\n",
               "--max-duration", "30")
    assert run.wait_line("RUNNING", "probe.work", timeout=20), run.end(1)
    time.sleep(0.3)
    stopped = time.monotonic()
    ros_graph.stop_node(proc)  # a clean stop: its announcement removed, its node unregistered
    waited = run.wait_line("RUNNING", "wait 5s", timeout=6)
    start_probe(ros_graph)  # back during the wait (before the fix: the second call went to it then)
    out = run.end()
    assert waited is not None and waited - stopped < 3.0, out
    assert run.proc.returncode == 0, out
    first, second, third = _calls(out)
    assert first[3] == "cancelled" and second[3] == "module_lost" and float(second[4][:-1]) < 2.0, out
    assert ("the module's node /bm_probe is stopping (SIGINT); its code returned after the cancel"
            in " ".join(first)), out
    assert "module probe lost: node /bm_probe stopped (its process is gone)" in " ".join(second), out
    assert third[2:4] == ["probe.echo", "succeeded"], out
    assert "answered" not in out and "NOTICE" not in out, out  # no late answer: the second call never ran


@pytest.mark.parametrize("how", ["kill", "stop"])
def test_a_wait_event_whose_module_dies_fails_and_says_why(ros_graph, tmp_path, how):
    """The audit's hotword module, killed during a parallel of follow-or-stop: the wait went on for ever
    and the robot could no longer be stopped by voice."""
    proc = start_probe(ros_graph)
    run = _Run(tmp_path, "  parallel:\n    - wait: 30\n    - wait_event: probe.done\n", "--max-duration", "20")
    assert run.wait_line("RUNNING", "probe.done", timeout=20), run.end(1)
    time.sleep(0.3)
    gone = time.monotonic()
    if how == "kill":
        ros_graph.kill_node(proc)
    else:
        ros_graph.stop_node(proc)
    failed = run.wait_line("FAILURE", "probe.done", timeout=8)
    out = run.end()
    assert failed is not None and failed - gone < 3.0, out
    assert run.proc.returncode == 1, out
    reason = "probe's node is gone (node /bm_probe stopped (its process is gone)): no probe.done event can come"
    assert "reason: probe.done: " + reason in out, out
    assert "NOTICE    %s; the wait_event for it fails" % reason in out, out


def test_a_wait_event_started_after_its_module_stopped_fails_as_a_call_would(ros_graph, tmp_path):
    proc = start_probe(ros_graph)
    run = _Run(tmp_path, "  sequence:\n    - wait: 2\n    - wait_event: probe.done\n", "--max-duration", "15")
    assert run.wait_line("RUNNING", "wait 2s", timeout=20), run.end(1)
    ros_graph.stop_node(proc)
    started = run.wait_line("RUNNING", "probe.done", timeout=5)
    failed = run.wait_line("FAILURE", "probe.done", timeout=5)
    out = run.end()
    assert started is not None and failed is not None and failed - started < 2.0, out
    assert "no probe.done event can come" in out and run.proc.returncode == 1, out


def _transport(**kwargs):
    items: queue.Queue = queue.Queue()
    transport = RosTransport(**kwargs)
    transport.connect(items.put)
    return transport, items


def test_a_call_held_for_a_node_that_does_not_connect_is_given_up_and_never_sent(ros_graph):
    """The module's node stopped; the master names a live node for it that never connects to its call
    topic (here a stand-in announcement): the call used to wait for ever, then went to the next node."""
    start_sim_module(ros_graph, "battery")  # a live node that does not take probe's calls
    proc = start_probe(ros_graph)
    transport, items = _transport(hold_limit=1.5)
    try:
        transport.wait_ready(["probe"], 20)
        ros_graph.stop_node(proc)
        rospy.set_param("%s/probe" % PARAM_ROOT, {"node": "/bm_battery"})
        call = probe_def().function("echo").build_call({"tag": "held"})
        sent = time.monotonic()
        transport.send_call(call)
        lost = wait_item(items, lambda r: isinstance(r, ModuleLost), 6)
        assert lost is not None and call.call_id in lost.call_ids, lost
        assert 1.4 < time.monotonic() - sent < 4.0
        assert "no node of it connected to /bmtree/call/probe within 1.5s (node /bm_battery" in lost.reason
        rospy.delete_param("%s/probe" % PARAM_ROOT)
        start_probe(ros_graph)  # connects: what was given up is not sent to it
        answered = wait_item(items, lambda r: isinstance(r, FunctionResult) and r.call_id == call.call_id, 3)
        assert answered is None, answered
    finally:
        if rospy.has_param("%s/probe" % PARAM_ROOT) and rospy.get_param("%s/probe" % PARAM_ROOT).get("node") \
                == "/bm_battery":
            rospy.delete_param("%s/probe" % PARAM_ROOT)
        transport.close()


def test_a_call_to_an_original_module_whose_node_died_ends_at_once(ros_graph):
    """ROS drops a message for a node that is not connected, and a killed node's connection stays until
    a write fails: the call waited for the watchdog (here asked every 5 s), or for ever if the node was
    started again meanwhile."""
    defs = load_definitions([REFERENCE])
    proc = ros_graph.start_node([sys.executable, os.path.join(NODES, "legacy_python_bm.py")], "/PYTHON_BM")
    transport, items = _transport(liveness=5.0)
    try:
        transport.wait_ready(["PYTHON_BM"], 20, definitions=defs)
        ros_graph.kill_node(proc)
        time.sleep(0.2)
        call = defs["PYTHON_BM"].function("goSafePos").build_call({})
        sent = time.monotonic()
        transport.send_call(call)
        lost = wait_item(items, lambda r: isinstance(r, ModuleLost), 4)
        assert lost is not None and lost.call_ids == [call.call_id], lost
        assert time.monotonic() - sent < 1.0
        assert lost.reason == "node /PYTHON_BM is not connected to /master/output (gone, or restarting): the call " \
                              "was not sent"
    finally:
        transport.close()


def test_a_retry_to_a_killed_module_that_is_not_restarted_says_its_process_is_gone(ros_graph, tmp_path):
    """The run knew the node's process was gone; the retry's reason guessed 'restarting, or unable to reach
    this process?' and a timed-out one said only 'no answer within 3s', though it was never sent."""
    proc = start_probe(ros_graph)
    run = _Run(tmp_path, "  retry: 3\n  child:\n    call: probe.work\n    inputs: {seconds: 100.0, tag: x}\n"
                         "    timeout: 3\n")
    try:
        assert run.wait_line("RUNNING", "probe.work", timeout=60) is not None, run.end(1)
        ros_graph.kill_node(proc)
        out = run.end(60)
    finally:
        if run.proc.poll() is None:
            run.proc.kill()
    assert run.proc.returncode == 1, out
    rows = [line for line in out.split("calls:")[-1].splitlines() if "probe.work" in line]
    assert len(rows) == 3 and "module_lost" in rows[0] and "its process is gone" in rows[0], out
    for row in rows[1:]:   # held for a node that does not come back: timed out, never sent, and why
        assert "timeout" in row and re.search(r"no answer within 3s \(never sent: node /bm_probe stopped \(its "
                                              r"process is gone\) \d+\.\d s ago and was not started again\)", row), out
    assert "restarting, or unable to reach" not in out, out
    # a call never sent cannot be running: no "may still be running: its module did not answer the cancel"
    assert "may still be running" not in out, out
