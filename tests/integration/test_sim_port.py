"""``bmtree run --sim --port P``: the private master on a port known beforehand, so an operator's watch
can be started before the run (it waits for the master and the run); a port in use is said at once."""
from __future__ import annotations

import os
import socket
import subprocess

from coordinator.graph import LOOPBACK, free_port
from tests.conftest import TREES
from tests.integration.conftest import bmtree_cmd
from tests.integration.watchkit import Lines


def test_a_watch_started_before_the_run_follows_it_on_the_port_given(tmp_path):
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI="http://%s:%d/" % (LOOPBACK, port), ROS_HOME=str(tmp_path / "watch_home"))
    watch = subprocess.Popen(bmtree_cmd("watch", "--plain", "--wait", "120"), stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True, env=env, stdin=subprocess.DEVNULL)
    try:
        seen = Lines(watch.stdout)
        run = subprocess.run(bmtree_cmd("run", "--sim", "-q", "--port", str(port), os.path.join(TREES, "find_apple.yaml")),
                             capture_output=True, text=True, timeout=180, env=dict(os.environ, ROS_HOME=str(tmp_path)),
                             stdin=subprocess.DEVNULL)
        assert run.returncode == 0, run.stdout + run.stderr
        assert "simulated robot up, master at http://%s:%d/" % (LOOPBACK, port) in run.stderr, run.stderr
        seen.wait_for("find_apple", 60)
        seen.wait_for("SUCCESS", 60)
    finally:
        if watch.poll() is None:
            watch.terminate()
        watch.wait(30)


def test_a_port_in_use_is_said_before_anything_starts(tmp_path):
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind((LOOPBACK, 0))
        taken.listen()
        port = taken.getsockname()[1]
        run = subprocess.run(bmtree_cmd("run", "--sim", "-q", "--port", str(port), os.path.join(TREES, "find_apple.yaml")),
                             capture_output=True, text=True, timeout=120, env=dict(os.environ, ROS_HOME=str(tmp_path)),
                             stdin=subprocess.DEVNULL)
    assert run.returncode == 3, run.stdout + run.stderr
    assert ("error: port %d of %s is in use (another ROS master, or another program): give another --port, or none for "
            "a free one" % (port, LOOPBACK)) in run.stderr, run.stderr
    assert "Traceback" not in run.stderr
