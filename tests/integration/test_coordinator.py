"""bmtree run against real module processes: shipped trees, failures, late answers, legacy modules."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import yaml

from tests.conftest import REFERENCE, TREES, until
from tests.integration.conftest import NODES, bmtree_cmd, processes_running, start_sim_module


def run(*args, timeout=120, env=None):
    return subprocess.run(bmtree_cmd(*args), capture_output=True, text=True, timeout=timeout,
                          env=env or dict(os.environ), stdin=subprocess.DEVNULL)


def test_shipped_trees_succeed_on_the_simulated_robot():
    for tree, said in (("find_apple.yaml", "report"), ("invite_to_dining_room.yaml", "lead to the dining room"),
                       ("greet_guest.yaml", "look while nobody is seen")):
        out = run("run", "--sim", os.path.join(TREES, tree))
        assert out.returncode == 0, out.stdout + out.stderr
        assert "SUCCESS" in out.stdout.splitlines()[-1] or ": SUCCESS in" in out.stdout
        assert said in out.stdout
    # the run report names every call with its status
    assert "navigation.go_to" in out.stdout and "succeeded" in out.stdout


def test_find_apple_without_an_apple_ends_in_its_fallback(tmp_path):
    from modules.sim import DEFAULT_WORLD

    with open(DEFAULT_WORLD) as fh:
        world = yaml.safe_load(fh)
    del world["objects"]["apple"]
    path = tmp_path / "no_apple.yaml"
    path.write_text(yaml.safe_dump(world))
    out = run("run", "--sim", "--world", str(path), os.path.join(TREES, "find_apple.yaml"), "-q")
    assert out.returncode == 1, out.stdout + out.stderr
    # stdout is the outcome alone (for scripts); the start-up's progress is on stderr
    assert out.stdout.strip().splitlines()[0].startswith("find_apple: FAILURE in"), out.stdout
    assert "simulated robot up, master at" in out.stderr and "running find_apple" in out.stderr
    calls = [line.split()[2] for line in out.stdout.splitlines() if line.startswith("  +")]
    assert calls.count("vision.find_object") == 4 and calls[-1] == "speech.say"
    assert "navigation.approach" not in calls


def test_recall_through_the_blackboard_node(tmp_path):
    tree = tmp_path / "recall.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n    - call: navigation.go_to\n      inputs: {place: kitchen}\n"
                    "    - recall: {where: navigation/go_to/room}\n    - check: 'where == \"kitchen\"'\n"
                    "    - force_success: {recall: {ghost: never_written}}\n")
    out = run("run", "--sim", str(tree))
    assert out.returncode == 0, out.stdout + out.stderr
    assert "the Blackboard has no never_written" in out.stdout


def test_module_killed_mid_call_fails_as_module_lost_and_falls_back(ros_graph, slow_world, tmp_path):
    nav = start_sim_module(ros_graph, "navigation", slow_world)
    start_sim_module(ros_graph, "speech")
    tree = tmp_path / "killed.yaml"
    tree.write_text("format: 1\nroot:\n  selector:\n    - call: navigation.go_to\n      name: drive\n"
                    "      inputs: {place: kitchen}\n      timeout: 3\n"
                    "    - call: speech.say\n      name: fallback\n      inputs: {text: I am stuck}\n")
    proc = subprocess.Popen(bmtree_cmd("run", str(tree)), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=dict(os.environ))
    try:
        seen = ""  # the run's own line-per-change display says when the call is under way
        while not any("RUNNING" in line and line.endswith(" drive") for line in seen.splitlines()):
            line = proc.stdout.readline()
            assert line, "bmtree run ended before the call started (exit %s): %s%s" % (
                proc.wait(30), seen, proc.stderr.read())
            seen += line
        t0 = time.monotonic()
        ros_graph.kill_node(nav)
        out, err = proc.communicate(timeout=30)
        out = seen + out
        elapsed = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out + err
    go_to = next(line for line in out.splitlines() if line.startswith("  +") and "navigation.go_to" in line)
    # noticed by the liveness check, before the call's own 3 s timeout
    assert "module_lost" in go_to and "module navigation lost" in go_to
    assert any("speech.say" in line and "succeeded" in line for line in out.splitlines() if line.startswith("  +"))
    assert elapsed < 20  # bounded by the call's 3 s timeout, not by the robot


def test_late_answer_of_a_timed_out_call_is_not_taken(ros_graph, tmp_path):
    ros_graph.start_node([sys.executable, os.path.join(NODES, "late_module.py")], "/bm_late")
    tree = tmp_path / "late.yaml"
    tree.write_text("""format: 1
root:
  sequence:
    - force_success:
        call: late.echo
        inputs: {seconds: 1.5, tag: first}
        timeout: 0.5
    - call: late.echo
      inputs: {seconds: 2.0, tag: second}
      outputs: {tag: got}
    - check: 'got == "second"'
""")
    out = run("run", str(tree), "--modules", os.path.join(NODES, "late.json"), "-q")
    assert out.returncode == 0, out.stdout + out.stderr
    lines = [line for line in out.stdout.splitlines() if line.startswith("  +")]
    assert "timeout" in lines[0] and "succeeded" in lines[1]


def test_original_style_module_is_driven_correctly(ros_graph, tmp_path):
    ros_graph.start_node([sys.executable, os.path.join(NODES, "legacy_python_bm.py")], "/PYTHON_BM")
    tree = tmp_path / "arm.yaml"
    tree.write_text("""format: 1
root:
  sequence:
    - call: PYTHON_BM.graspObject
      inputs: {target_pos: {x: 0.3, y: 0.1, z: 0.9}, obj_radius: 0.2}
      outputs: {final_pos: held_at}
    - check: 'held_at.x == 0.3 and held_at.z == 0.9'
    - call: PYTHON_BM.putObject
      inputs: {target_pos: {x: -0.2, y: 0.0, z: 0.7}}
      outputs: {final_pos: put_at}
    - call: PYTHON_BM.goSafePos
      outputs: {final_pos: safe}
    - check: 'put_at.x == -0.2 and safe.z == 0.5'
""")
    out = run("run", str(tree), "--modules", REFERENCE, "-q")
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.count("succeeded") == 3
    # no Blackboard node on this graph: the tree needs none, but its results are stored nowhere
    assert "warning: no Blackboard node is running on this master: the results of this run's calls are not " \
        "stored" in out.stderr, out.stderr
    ros_graph.start_node(["-m", "blackboard.node", "--db", str(tmp_path / "bb.sqlite")], "/blackboard")
    deadline = time.monotonic() + 30
    while "warning: no Blackboard" in out.stderr:
        assert time.monotonic() < deadline, out.stderr
        out = run("run", str(tree), "--modules", REFERENCE, "-q")
        assert out.returncode == 0, out.stdout + out.stderr


def first_use(tree, prefix):
    """(line, column) of the first ``prefix`` in a shipped tree (1-based)."""
    for line, text in enumerate(open(os.path.join(TREES, tree)), 1):
        if prefix in text:
            return line, text.index(prefix) + 1
    raise AssertionError("%s not in %s" % (prefix, tree))


def test_missing_module_is_an_environment_error(ros_master, tmp_path):
    out = run("run", os.path.join(TREES, "find_apple.yaml"), "--wait", "1")
    assert out.returncode == 3
    assert "module 'navigation' is not running" in out.stderr and "Traceback" not in out.stderr
    # where the tree uses it (here in the tree it includes), as a tree error would say
    assert "search_room.yaml:%d:%d: module 'navigation' is not running" % first_use("search_room.yaml", "navigation.") \
        in out.stderr, out.stderr


def test_no_master_is_an_environment_error():
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:9/")
    out = run("run", os.path.join(TREES, "find_apple.yaml"), "--wait", "0.5", env=env)
    assert out.returncode == 3 and "no ROS master at http://127.0.0.1:9/" in out.stderr


def test_invalid_tree_exits_2_before_touching_ros(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: 1\nroot:\n  call: speech.sya\n")
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:9/")
    out = run("run", "--sim", str(bad), env=env)
    assert out.returncode == 2 and "bad.yaml:3:9: module 'speech' has no function 'sya'" in out.stderr


def _driving(slow_world):
    """``bmtree run --sim`` of find_apple, once the robot drives: (process, its output so far)."""
    proc = subprocess.Popen(bmtree_cmd("run", "--sim", "--world", slow_world, os.path.join(TREES, "find_apple.yaml")),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    seen = ""
    while "RUNNING   navigation.go_to" not in seen and time.monotonic() < deadline:
        seen += proc.stdout.readline()
    return proc, seen


def test_ctrl_c_cancels_and_cleans_up(slow_world):
    import socket

    proc, seen = _driving(slow_world)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 3 and "interrupted" in err, seen + out + err
    uri = next(line.split("master at ")[1] for line in err.splitlines() if "master at " in line)  # start-up: stderr
    # what it did, why it ended and where its log is, as at a normal end
    assert "reason: interrupted while 'navigation.go_to' was running" in out, out
    assert "navigation.go_to           interrupted" in out and "run log: " in out and "module logs: " in out, out
    port = int(uri.rstrip("/").rsplit(":", 1)[1])
    with socket.socket() as s:
        assert s.connect_ex(("127.0.0.1", port)) != 0, "the private rosmaster still runs"
    left = processes_running(slow_world)
    assert left == [], "nodes left running: %s" % left


def _children(pid):
    kids = set()
    for tid in os.listdir("/proc/%d/task" % pid):
        with open("/proc/%d/task/%s/children" % (pid, tid)) as fh:
            kids.update(int(k) for k in fh.read().split())
    return kids


def _alive(pid):
    try:
        with open("/proc/%d/stat" % pid) as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _cmdline(pid):
    try:
        with open("/proc/%d/cmdline" % pid, "rb") as fh:
            return fh.read().replace(b"\0", b" ").decode(errors="replace").strip()
    except OSError:
        return "?"


def _stacks(pid):
    """Every thread's stack of a bmtree node (SIGUSR1, printed to its log, which is its stderr)."""
    try:
        log = os.readlink("/proc/%d/fd/2" % pid)
        size = os.path.getsize(log)
        os.kill(pid, signal.SIGUSR1)
        time.sleep(1)
        with open(log, errors="replace") as fh:
            fh.seek(size)
            return "%s:\n%s" % (log, fh.read()[-6000:])
    except OSError as exc:
        return "no stacks of %d: %s" % (pid, exc)


def test_a_killed_coordinator_leaves_no_simulated_robot_behind(slow_world):
    """SIGKILL (or the OOM killer) gives bmtree no chance to stop its graph: the graph's processes,
    each in its own session, still end (util-linux's setpriv --pdeathsig)."""
    proc, seen = _driving(slow_world)
    graph = _children(proc.pid)
    assert len(graph) >= 5, seen  # rosmaster, the Blackboard and the simulated modules
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    end = time.monotonic() + 20
    while any(_alive(p) for p in graph) and time.monotonic() < end:
        time.sleep(0.05)
    left = {p: _cmdline(p) for p in graph if _alive(p)}
    stacks = {p: _stacks(p) for p in left}
    for p in left:  # end what this test started, then fail
        os.kill(p, signal.SIGKILL)
    assert left == {}, "left running after the coordinator was killed: %s\n%s" % (left, "\n".join(stacks.values()))


def test_a_graph_started_with_sigint_ignored_still_stops_its_master(tmp_path):
    """``bmtree run --sim &`` in a script starts everything with SIGINT ignored (inherited):
    closing the graph must still end rosmaster by asking, not by SIGKILL after a wait."""
    from coordinator.graph import RosGraph

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        graph = RosGraph(str(tmp_path / "ros"))
        graph.start_master()
    finally:
        signal.signal(signal.SIGINT, previous)
    master = graph.master
    graph.close()
    assert master.returncode == -signal.SIGTERM


_STOPPING = """
import os, signal, sys, time
def alive(pid):
    try:
        os.kill(pid, 0)
        return "alive"
    except ProcessLookupError:
        return "gone"
def on_int(*_):
    with open(sys.argv[1], "w") as fh:
        fh.write(" ".join(alive(int(p)) for p in sys.argv[3:]))
    time.sleep(float(sys.argv[2]))
    sys.exit(0)
signal.signal(signal.SIGINT, on_int)
open(sys.argv[1] + ".ready", "w").close()
while True:
    time.sleep(60)
"""


def test_closing_a_graph_stops_its_nodes_together_and_the_stop_last_ones_after(tmp_path):
    """rospy takes a while to stop a node; four of them one after another made every
    ``bmtree run --sim`` seconds longer. The Blackboard still ends after the modules."""
    from coordinator.graph import RosGraph

    script = tmp_path / "stopping.py"
    script.write_text(_STOPPING)
    graph = RosGraph(str(tmp_path / "ros"))
    graph.start_master()
    try:
        first = graph.start_node([sys.executable, str(script), str(tmp_path / "first"), "1"], "/first", wait=False)
        second = graph.start_node([sys.executable, str(script), str(tmp_path / "second"), "0", str(first.pid)],
                                  "/second", wait=False)
        graph.start_node([sys.executable, str(script), str(tmp_path / "last"), "0", str(first.pid), str(second.pid)],
                         "/last", wait=False, stop_last=True)
        until(lambda: all((tmp_path / (n + ".ready")).exists() for n in ("first", "second", "last")), 30)
    finally:
        graph.close()
    assert (tmp_path / "second").read_text() == "alive"  # asked while the first was still stopping
    assert (tmp_path / "last").read_text() == "gone gone"


def test_a_graph_on_a_shared_master_unregisters_its_killed_nodes_when_closed(ros_master, tmp_path):
    """A node killed outright stays registered; the next test (or run) on the master found a
    /PYTHON_BM publishing and subscribing that was long gone. A live node of another graph is left."""
    import xmlrpc.client

    from coordinator.graph import RosGraph

    def registered(name):
        pubs, subs, _ = xmlrpc.client.ServerProxy(ros_master).getSystemState("/t")[2]
        return any(name in nodes for _, nodes in pubs + subs)

    other = RosGraph(str(tmp_path / "other"), master_uri=ros_master)
    graph = RosGraph(str(tmp_path / "ros"), master_uri=ros_master)
    try:
        other.start_node([sys.executable, os.path.join(NODES, "legacy_python_bm.py"), "__name:=alive_arm"],
                         "/alive_arm")
        proc = graph.start_node([sys.executable, os.path.join(NODES, "legacy_python_bm.py"), "__name:=killed_arm"],
                                "/killed_arm")
        graph.kill_node(proc)
        assert registered("/killed_arm")
    finally:
        graph.close()
    try:
        assert not registered("/killed_arm")
        assert registered("/alive_arm")
    finally:
        other.close()
    assert not registered("/alive_arm")  # ended by asking: it unregistered itself


def test_two_runs_on_one_master_are_each_told_of_the_other(ros_graph, tmp_path):
    """Two runs on one master share the Blackboard's names, the run stream and the control topics:
    the second one says so before it starts, and the first one, already running, gets a notice
    (on its display and in its run log) when the second starts."""
    from coordinator.runlog import read_log
    from tests.integration.faultkit import PROBE_JSON, slow_run, start_probe, stop_run

    start_probe(ros_graph)
    quick = tmp_path / "quick.yaml"
    quick.write_text("format: 1\nroot:\n  call: probe.echo\n  inputs: {tag: y}\n")
    first = slow_run(tmp_path, 60)
    try:
        out = run("run", str(quick), "--modules", PROBE_JSON, "-q")
    finally:
        stop_run(first)
    first_out = first.stdout.read() if first.stdout else ""
    alone = run("run", str(quick), "--modules", PROBE_JSON, "-q")
    assert out.returncode == 0, out.stdout + out.stderr
    assert "warning: another bmtree run is running on this master (node /bmtree_%d_" % first.pid in out.stderr, \
        out.stderr
    assert "same Blackboard names" in out.stderr and "both publish the run stream on /bmtree/run" in out.stderr
    # -q has no display (run.launch runs so): the notice still reaches the operator, on stderr
    assert "NOTICE    another bmtree run is running on this master (node /bmtree_%d_" % first.pid in out.stderr, \
        out.stderr
    assert alone.returncode == 0 and "another bmtree run" not in alone.stderr, alone.stderr
    told = [line for line in first_out.splitlines() if "NOTICE" in line]
    assert len(told) == 1 and "another bmtree run is running on this master (node /bmtree_" in told[0] \
        and str(quick) in told[0] and "a recall may read its values" in told[0], first_out
    log_path = next(line.split("run log: ", 1)[1].split()[0] for line in first_out.splitlines() if "run log: " in line)
    notices = read_log(log_path).of_type("notice")
    assert [n["what"] for n in notices] == ["other_run"] and str(quick) in notices[0]["text"], notices
