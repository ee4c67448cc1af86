"""The README's move_base example (modules/example/mobile_base.*, on modules/actions.py) against a real
actionlib SimpleActionServer in its own process, driven by ``bmtree run``: success with outputs, an
aborted goal, a goal preempted when a ``timeout`` halts the call or when the module's node is stopped, and
50 goals answered at once."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest

from tests.conftest import ROOT, until
from tests.integration.conftest import NODES, bmtree_cmd, wait_announced

EXAMPLE = os.path.join(ROOT, "modules", "example")
DEFINITION = os.path.join(EXAMPLE, "mobile_base.json")
TARGET = "{position: {x: 1.5, y: -2.0}, orientation: {w: 1.0}}"


@pytest.fixture
def move_base(ros_graph, tmp_path):
    """``start(mode)``: the stand-in move_base server, then the example module; the server's log."""
    log = tmp_path / "server.log"

    def start(mode):
        ros_graph.start_node([sys.executable, os.path.join(NODES, "move_base_server.py"), mode, str(log)], "/move_base")
        start.module = ros_graph.start_node(["-m", "modules.node", "--definition", DEFINITION, "--class",
                                             os.path.join(EXAMPLE, "mobile_base.py") + ":MobileBase"], "/bm_mobile_base")
        wait_announced("mobile_base")
        return log

    return start


def _run(tmp_path, root, timeout=120):
    tree = tmp_path / "tree.yaml"
    tree.write_text("format: 1\nroot:\n" + root)
    return subprocess.run(bmtree_cmd("run", "-q", "--modules", DEFINITION, str(tree)), capture_output=True,
                          text=True, timeout=timeout, env=dict(os.environ), stdin=subprocess.DEVNULL)


def _calls(out):
    return [line for line in out.stdout.splitlines() if line.startswith("  +")]


def test_a_goal_that_succeeds_answers_its_outputs(move_base, tmp_path):
    log = move_base("succeed")
    out = _run(tmp_path, "  sequence:\n    - call: mobile_base.go_to\n      inputs: {target: %s}\n"
                         "      outputs: {position: at}\n"
                         "    - check: 'at.x == 1.5 and at.y == -2.0 and at.z == 0.5'\n" % TARGET)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "mobile_base.go_to" in _calls(out)[0] and "succeeded" in _calls(out)[0]
    assert log.read_text().splitlines()[1:] == ["goal 1.5 -2.0", "succeeded"]  # z: from the feedback


def test_an_aborted_goal_fails_the_call_with_the_state_and_text(move_base, tmp_path):
    move_base("abort")
    out = _run(tmp_path, "  call: mobile_base.go_to\n  inputs: {target: %s}\n" % TARGET)
    assert out.returncode == 1, out.stdout + out.stderr
    line = _calls(out)[0]
    assert "failed" in line and "/move_base: goal ABORTED: no valid plan to the goal" in line, line


def test_a_timeout_that_halts_the_call_preempts_the_goal(move_base, tmp_path, ros_probe):
    log = move_base("slow")
    answers = ros_probe.collect("/function/output", nodes=("/bm_mobile_base",))
    try:
        out = _run(tmp_path, "  timeout: 1.5\n  child:\n    call: mobile_base.go_to\n    inputs: {target: %s}\n"
                             "    timeout: none\n" % TARGET)
        assert out.returncode == 1, out.stdout + out.stderr
        assert "timed out after 1.5s" in out.stdout, out.stdout
        # the module answered the halted call `cancelled` once the server had preempted the goal
        text = answers.wait_for(lambda t: json.loads(t).get("function") == "go_to", 10)[0]
        assert json.loads(text)["status"] == "cancelled", text
        until(lambda: "preempted" in log.read_text(), 5, log.read_text)
        assert log.read_text().splitlines()[1:] == ["goal 1.5 -2.0", "preempted"]
        # and the module is free again: the next call runs
        log.write_text("")
        out = _run(tmp_path, "  timeout: 0.5\n  child:\n    call: mobile_base.go_to\n    inputs: {target: %s}\n"
                             % TARGET)
        assert "timed out after 0.5s" in out.stdout, out.stdout + out.stderr
        until(lambda: "preempted" in log.read_text(), 5, log.read_text)
    finally:
        ros_probe.close_collector(answers)


def test_fifty_goals_answered_at_once_all_succeed(move_base, tmp_path, ros_graph):
    """The server succeeds inside its goal callback: a result that can overtake ``send_goal``'s return
    (SimpleActionClient drops it, "a goal handle that we're not tracking", and its goal never ends)."""
    log = move_base("instant")
    out = _run(tmp_path, "  repeat: 50\n  child:\n    call: mobile_base.go_to\n    inputs: {target: %s}\n"
                         "    timeout: 5\n" % TARGET)
    assert out.returncode == 0, out.stdout + out.stderr
    calls = _calls(out)
    assert len(calls) == 50 and all("succeeded" in c for c in calls), "\n".join(calls)
    assert log.read_text().count("succeeded") == 50
    with open(os.path.join(ros_graph.ros_home, "bm_mobile_base.out")) as fh:
        module_log = fh.read()
    assert "not tracking" not in module_log, module_log  # no transition of any goal was dropped


def test_a_module_node_stopped_during_a_goal_cancels_it(move_base, tmp_path, ros_graph, ros_probe):
    """Ctrl-C to the module's node: move_base must not drive on for a node that is gone, and the call's
    answer says the node stopped, not that navigation failed (the server honours the cancel: PREEMPTED)."""
    log = move_base("slow")
    answers = ros_probe.collect("/function/output", nodes=("/bm_mobile_base",))
    tree = tmp_path / "tree.yaml"
    tree.write_text("format: 1\nroot:\n  call: mobile_base.go_to\n  inputs: {target: %s}\n  timeout: none\n" % TARGET)
    run = subprocess.Popen(bmtree_cmd("run", "-q", "--modules", DEFINITION, str(tree)), stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL, env=dict(os.environ), stdin=subprocess.DEVNULL)
    try:
        until(lambda: "goal" in log.read_text(), 30, log.read_text)
        move_base.module.send_signal(signal.SIGINT)
        until(lambda: "preempted" in log.read_text(), 5, log.read_text)
        assert move_base.module.wait(10) == 0
        ros_graph.nodes.remove(move_base.module)
        answer = json.loads(answers.wait_for(lambda t: json.loads(t).get("function") == "go_to", 10)[0])
        assert (answer["status"], answer["error"]) == ("failed", "/move_base: the module's node stops: goal cancelled")
    finally:
        ros_probe.close_collector(answers)
        if run.poll() is None:
            run.kill()
            run.wait(10)


def test_a_server_that_was_stopped_is_not_named_as_the_server(move_base, tmp_path, ros_graph):
    """The server was connected, then stopped (SIGTERM): the call says nothing publishes its status, not
    that the dead server has not subscribed to the goal topic (actionlib keeps its last status for ever)."""
    log = move_base("succeed")
    out = _run(tmp_path, "  call: mobile_base.go_to\n  inputs: {target: %s}\n" % TARGET)
    assert out.returncode == 0, out.stdout + out.stderr  # connected once: the module has the server's last status
    server = next(p for p in ros_graph.nodes if p is not move_base.module and "move_base_server.py" in " ".join(p.args))
    server.send_signal(signal.SIGTERM)
    server.wait(10)
    ros_graph.nodes.remove(server)
    out = _run(tmp_path, "  call: mobile_base.go_to\n  inputs: {target: %s}\n  timeout: 30\n" % TARGET)
    assert out.returncode == 1, out.stdout + out.stderr
    line = _calls(out)[0]
    assert "failed" in line and "no action server on /move_base within 5s: nothing publishes /move_base/status" in line, \
        line
    assert log.read_text().count("goal") == 1


def test_a_server_that_ignores_the_cancel_is_said_in_the_run_summary_and_log(move_base, tmp_path):
    """The tree halts the call; the server does not end the goal within the cancel's wait: the run's summary
    lists the call under "may still be running" and its log has a still_running notice (before, only the
    module's own log said so, and the goal drove on after the run had ended)."""
    from coordinator.runlog import read_log

    move_base("stubborn")
    log_path = tmp_path / "run.jsonl"
    tree = tmp_path / "tree.yaml"
    tree.write_text("format: 1\nroot:\n  timeout: 1\n  child:\n    call: mobile_base.go_to\n    inputs: {target: %s}\n"
                    "    timeout: none\n" % TARGET)
    out = subprocess.run(bmtree_cmd("run", "-q", "--modules", DEFINITION, "--record", str(log_path), str(tree)),
                         capture_output=True, text=True, timeout=120, env=dict(os.environ), stdin=subprocess.DEVNULL)
    assert out.returncode == 1, out.stdout + out.stderr
    said = "may still be running: its module says /move_base did not end the goal within 0.8s of its cancel: it may " \
           "not have stopped"
    assert said in out.stdout, out.stdout
    notices = [r for r in read_log(str(log_path)).records if r.get("type") == "notice" and r.get("what") == "still_running"]
    assert len(notices) == 1 and said.split(": ", 1)[1] in notices[0]["text"], notices


def test_a_server_killed_during_a_goal_loses_it_without_waiting_for_silence(move_base, tmp_path, ros_graph):
    """kill -9 of the server: its status connection closes, and the goal is LOST at the module's next look
    (not after silence_timeout, 5 s, of no status)."""
    log = move_base("slow")
    tree = tmp_path / "tree.yaml"
    tree.write_text("format: 1\nroot:\n  call: mobile_base.go_to\n  inputs: {target: %s}\n  timeout: none\n" % TARGET)
    run = subprocess.Popen(bmtree_cmd("run", "-q", "--modules", DEFINITION, str(tree)), stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True, env=dict(os.environ), stdin=subprocess.DEVNULL)
    try:
        until(lambda: "goal" in log.read_text(), 30, log.read_text)
        server = next(p for p in ros_graph.nodes if "move_base_server.py" in " ".join(map(str, p.args)))
        ros_graph.kill_node(server)
        out, _ = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(10)
    assert run.returncode == 1, out
    assert "/move_base: goal LOST: its server /move_base closed its connection to /move_base/status: it stopped or " \
           "died" in out, out
    assert "no status from the server" not in out, out


def test_a_restarted_module_cancels_the_goal_its_killed_process_left(move_base, tmp_path, ros_graph):
    """kill -9 of the module during a goal: nothing can cancel it then, and the server drives on; the module's
    node started again (a respawn) cancels it, as a goal of an earlier process of its node, before any goal
    of its own."""
    log = move_base("slow")
    tree = tmp_path / "tree.yaml"
    tree.write_text("format: 1\nroot:\n  call: mobile_base.go_to\n  inputs: {target: %s}\n  timeout: none\n" % TARGET)
    run = subprocess.Popen(bmtree_cmd("run", "-q", "--modules", DEFINITION, str(tree)), stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL, env=dict(os.environ), stdin=subprocess.DEVNULL)
    try:
        until(lambda: "goal" in log.read_text(), 30, log.read_text)
        ros_graph.kill_node(move_base.module)
        assert run.wait(60) == 1
        assert "preempted" not in log.read_text()  # the goal runs on without its module
        ros_graph.start_node(["-m", "modules.node", "--definition", DEFINITION, "--class",
                              os.path.join(EXAMPLE, "mobile_base.py") + ":MobileBase"], "/bm_mobile_base")
        until(lambda: "preempted" in log.read_text(), 30, log.read_text)  # its setup() connects: no call needed
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(10)
    with open(os.path.join(ros_graph.ros_home, "bm_mobile_base.out")) as fh:
        module_log = fh.read()
    assert "/move_base: cancelled goal /bm_mobile_base-1-" in module_log, module_log
    assert "which an earlier process of this node left running on /move_base" in module_log, module_log
