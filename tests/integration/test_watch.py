"""``bmtree watch`` against a real ``bmtree run --sim`` on a slow world: attached mid-run it
catches up from the latched tree and the snapshot sent to it on connecting, then follows the run to its end."""
from __future__ import annotations

import subprocess

from tests.integration.conftest import bmtree_cmd
from tests.integration.watchkit import Lines, SimRun


def test_watch_attaches_mid_run_and_catches_up(tmp_path):
    run = SimRun(tmp_path)
    try:
        # the second leaf is running: the announcement is over before the watcher exists
        run.out.wait_for("RUNNING   go to the kitchen")
        watch = subprocess.Popen(bmtree_cmd("watch", "--plain", "--wait", "60"), stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True, env=run.env)
        out = Lines(watch.stdout)
        assert "run " in out.wait_for(": go_kitchen (")
        caught = out.wait_for("caught up at tick")
        assert "go to the kitchen RUNNING" in caught
        assert "pending calls: navigation.go_to since" in caught
        assert "1 call done" in caught  # speech.say ended before the watcher attached
        # then it follows live: the navigation ends, the last leaf runs, the run ends
        out.wait_for("succeeded navigation.go_to")
        out.wait_for("SUCCESS   arrived")
        out.wait_for("end       SUCCESS")
        assert watch.wait(60) == 0, out.text()
        assert run.finish() == 0, run.out.text()
        text = out.text()
        assert "HALTED" not in text and "Traceback" not in text
    finally:
        run.close()


def test_watch_without_a_run_says_so(ros_master, tmp_path):
    import os

    env = dict(os.environ, ROS_MASTER_URI=ros_master, ROS_IP="127.0.0.1", ROS_HOME=str(tmp_path))
    out = subprocess.run(bmtree_cmd("watch", "--plain", "--wait", "2", "--namespace", "/nobody/run"),
                         capture_output=True, text=True, env=env, timeout=60, stdin=subprocess.DEVNULL)
    assert out.returncode == 3, out.stdout + out.stderr
    assert "no run on /nobody/run/tree" in out.stderr
    assert "Traceback" not in out.stderr


def test_a_watch_ended_by_sigterm_or_sighup_leaves_the_master_as_ctrl_c_does(ros_master, tmp_path):
    """``timeout``, ``kill`` or a closed terminal: the watch unregisters (a dead subscriber left on
    the master would make every later run wait for it)."""
    import os
    import signal
    import time

    import rosgraph

    env = dict(os.environ, ROS_MASTER_URI=ros_master, ROS_IP="127.0.0.1", ROS_HOME=str(tmp_path))
    master = rosgraph.Master("/test", master_uri=ros_master)

    def watchers(pid):
        """The topics of the run stream that the watch with this pid subscribes (other tests' watches
        on this master are not this test's business)."""
        _, subs, _ = master.getSystemState()
        return sorted({t for t, nodes in subs if t.startswith("/bmtree/run/") for n in nodes
                       if n.startswith("/bmtree_watch_%d_" % pid)})

    for sig in (signal.SIGTERM, signal.SIGHUP):
        watch = subprocess.Popen(bmtree_cmd("watch", "--plain", "--follow"), stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True, env=env)
        end = time.monotonic() + 60
        while not watchers(watch.pid):
            assert watch.poll() is None and time.monotonic() < end, watch.stdout.read()
            time.sleep(0.05)
        watch.send_signal(sig)
        assert watch.wait(30) == 0
        assert watchers(watch.pid) == [], (sig, watchers(watch.pid))
