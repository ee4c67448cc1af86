"""A module or Blackboard killed with SIGKILL mid-call is noticed long before the call's timeout."""
from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import time

from comm import BlackboardRequest, FunctionResult
from comm.liveness import BlackboardLost, ModuleLost
from coordinator.ros_transport import RosTransport
from tests.conftest import until
from tests.integration.conftest import bmtree_cmd
from tests.integration.faultkit import (
    FULL,
    PROBE_JSON,
    figure,
    probe_def,
    scale,
    slow_run,
    start_probe,
    stop_run,
    wait_item,
)


def _transport():
    items: queue.Queue = queue.Queue()
    transport = RosTransport(liveness=0.25)
    transport.connect(items.put)
    return transport, items


def _ready(transport, items, echo):
    """Until the module answers (the preflight's connection counts may include a killed node's)."""
    for n in range(40):
        ping = echo.build_call({"tag": "ready %d" % n})
        transport.send_call(ping)
        if wait_item(items, lambda r, c=ping.call_id: getattr(r, "call_id", None) == c, 0.5):
            return
    raise AssertionError("the module never answered")


def test_killed_module_fails_its_calls_as_module_lost_and_a_restarted_one_answers(ros_graph):
    fn = probe_def().function("work")
    echo = probe_def().function("echo")
    transport, items = _transport()
    lost_after = []
    try:
        for i in range(scale(3, 20)):
            proc = start_probe(ros_graph)
            transport.wait_ready(["probe"], 20)
            _ready(transport, items, echo)
            call = fn.build_call({"seconds": 120.0, "tag": "slow %d" % i})
            transport.send_call(call)
            # the echo sent after it on the same connection proves the module took the call
            after = echo.build_call({"tag": "after %d" % i})
            transport.send_call(after)
            assert wait_item(items, lambda r, c=after.call_id: getattr(r, "call_id", None) == c, 20)
            killed = time.monotonic()
            ros_graph.kill_node(proc)
            lost = wait_item(items, lambda r: isinstance(r, ModuleLost), 60)
            assert lost is not None, "the killed module's call was not reported lost"
            lost_after.append(time.monotonic() - killed)
            assert lost.module == "probe" and call.call_id in lost.call_ids and "stopped" in lost.reason
        # restarted: the next call succeeds
        start_probe(ros_graph)
        transport.wait_ready(["probe"], 20)
        _ready(transport, items, echo)
        again = echo.build_call({"tag": "again"})
        transport.send_call(again)
        answer = wait_item(items, lambda r: isinstance(r, FunctionResult) and r.call_id == again.call_id, 20)
        assert answer is not None and answer.status == "succeeded"
    finally:
        transport.close()
    figure("module_lost after kill -9 (x%d)" % len(lost_after), lost_after)
    if FULL:
        assert max(lost_after) <= 2.0, lost_after


def test_killed_blackboard_fails_an_open_request(ros_graph, tmp_path):
    transport, items = _transport()
    try:
        bb = ros_graph.start_node(["-m", "blackboard.node", "--db", str(tmp_path / "bb.sqlite")], "/blackboard")
        transport.wait_ready([], 20, blackboard=True)
        # 'after' names a call the Blackboard never saw: it holds the request back for a while
        req = BlackboardRequest(var_names=["x"], after=["never-seen"])
        transport.send_request(req)
        killed = time.monotonic()
        ros_graph.kill_node(bb)
        lost = wait_item(items, lambda r: isinstance(r, (BlackboardLost,)) or getattr(r, "request_id", 0) == req.request_id, 30)
        took = time.monotonic() - killed
    finally:
        transport.close()
    assert isinstance(lost, BlackboardLost), lost
    assert req.request_id in lost.request_ids
    figure("blackboard lost after kill -9", [took])


def test_a_run_reports_module_lost_long_before_the_call_timeout(ros_graph, tmp_path):
    proc = start_probe(ros_graph)
    run = slow_run(tmp_path)
    try:
        ros_graph.kill_node(proc)
        out, _ = run.communicate(timeout=60)
    finally:
        stop_run(run)
    assert run.returncode == 1, out
    assert "module_lost" in out and "probe.work module_lost: module probe lost" in out, out


def test_a_blackboard_restarted_while_a_result_came_makes_the_recall_fail_not_stale(ros_graph, tmp_path):
    """The Blackboard node is down when a call's result comes and back (on its store) before the
    tree recalls that output: its value is the one from before the call. The recall fails and
    says so; it does not hand the tree the older value."""
    db = str(tmp_path / "bb.sqlite")

    def blackboard():
        return ros_graph.start_node(["-m", "blackboard.node", "--db", db, "__name:=bb_restart"], "/bb_restart")

    bb = blackboard()
    start_probe(ros_graph)
    tree = tmp_path / "restart.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n"
                    "    - call: probe.echo\n      inputs: {tag: before}\n"
                    "    - call: probe.work\n      inputs: {seconds: 2.0, tag: after}\n"
                    "    - wait: 6\n"
                    "    - recall: {said: tag}\n")
    run = subprocess.Popen(bmtree_cmd("run", str(tree), "--modules", PROBE_JSON), stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True, env=dict(os.environ))
    seen = []
    try:
        for line in run.stdout:
            seen.append(line)
            if "RUNNING" in line and "probe.work" in line:
                ros_graph.kill_node(bb)
            if "SUCCESS" in line and "probe.work" in line:  # answered while the Blackboard was down
                bb = blackboard()
                break
        out, _ = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.send_signal(signal.SIGINT)
            run.wait(10)
    out = "".join(seen) + out
    assert run.returncode == 1, out
    assert "the Blackboard node did not store the result of probe.work (call" in out, out
    assert "that wrote tag, so its value is an older one" in out, out


def test_a_retry_sent_while_the_killed_module_restarts_reaches_the_new_process(ros_graph, tmp_path):
    """kill -9 of the module mid-call and an immediate restart: the call fails module_lost and the
    retry goes out at once, before the new process has connected; it waits for that connection
    (it used to be lost, and waited out its whole 15 s timeout)."""
    tree = tmp_path / "retry.yaml"
    tree.write_text("format: 1\nroot:\n  retry: 3\n  child:\n    call: probe.work\n    inputs: {seconds: 2.0, tag: x}\n"
                    "    timeout: 15\n")
    proc = start_probe(ros_graph)
    run = subprocess.Popen([sys.executable, "-m", "coordinator", "run", str(tree), "--modules", PROBE_JSON],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ))
    try:
        for line in run.stdout:
            if "RUNNING" in line and "probe.work" in line:
                break
        time.sleep(0.5)
        ros_graph.kill_node(proc)
        start_probe(ros_graph, wait=False)
        out, _ = run.communicate(timeout=60)
    finally:
        stop_run(run)
    assert run.returncode == 0, out
    calls = [line for line in out.splitlines() if "probe.work" in line and line.strip().startswith("+")]
    assert "module_lost" in calls[0] and "succeeded" in calls[-1], out
    assert "timeout" not in out.split("calls:")[1], out


def test_a_call_whose_caller_was_killed_is_cancelled_by_the_module(ros_graph, tmp_path):
    """kill -9 of ``bmtree run`` mid-call: nothing cancels the call from the run's side, and it used
    to drive the hardware to its end and refuse every other call meanwhile (``busy with call …``).
    The module watches the caller of a running call and cancels it when that process is gone."""
    start_probe(ros_graph)
    first = slow_run(tmp_path, 100)
    first.kill()  # no Ctrl-C: the run cannot cancel anything
    first.wait(10)
    first.stdout.close()
    log_path = os.path.join(ros_graph.ros_home, "bm_probe.out")
    until(lambda: "its caller /bmtree_%d_" % first.pid in open(log_path).read(), 30, lambda: open(log_path).read()[-3000:])
    line = next(x for x in open(log_path).read().splitlines() if "its caller /bmtree_%d_" % first.pid in x)
    assert "cancelled call" in line and "of module probe" in line and "(its process is gone)" in line, line
    quick = tmp_path / "quick.yaml"
    quick.write_text("format: 1\nroot:\n  call: probe.work\n  inputs: {seconds: 0.1, tag: next}\n")
    out = subprocess.run(bmtree_cmd("run", str(quick), "--modules", PROBE_JSON, "-q"), capture_output=True,
                         text=True, timeout=120, env=dict(os.environ))
    assert out.returncode == 0, out.stdout + out.stderr  # the module is free again, long before 100 s


def test_the_wait_for_a_killed_module_says_it_is_not_running(ros_graph, tmp_path):
    """Its announcement stays behind: the wait said 'not connected … yet', as for a slow start."""
    ros_graph.kill_node(start_probe(ros_graph))
    quick = tmp_path / "quick.yaml"
    quick.write_text("format: 1\nroot:\n  call: probe.echo\n  inputs: {tag: y}\n")
    out = subprocess.run(bmtree_cmd("run", str(quick), "--modules", PROBE_JSON, "-q", "--wait", "4"),
                         capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert out.returncode == 3, out.stdout + out.stderr
    waiting = next(line for line in out.stderr.splitlines() if "waiting up to" in line)
    assert "module 'probe' is not running (node /bm_probe announced it but does not answer)" in waiting, out.stderr
