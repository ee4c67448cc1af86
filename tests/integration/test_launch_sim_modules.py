"""``roslaunch bmtree sim.launch modules:=…``: only the simulated modules named start (beside a team's own
modules for the others), checked with real roslaunch on a private master port. The package is found on
ROS_PACKAGE_PATH (this checkout, a catkin package) and its node scripts run with this test's Python."""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
import xmlrpc.client

import pytest

from coordinator.graph import LOOPBACK, free_port
from tests.conftest import ROOT
from tests.integration.conftest import bmtree_cmd

SIMULATED = ("navigation", "vision", "speech", "battery")
SAY = "format: 1\nname: say_hi\nroot:\n  call: speech.say\n  inputs: {text: hello}\n"


def _env(tmp_path, port):
    env = {k: v for k, v in os.environ.items() if k not in ("ROS_HOSTNAME", "ROS_LOG_DIR", "BMTREE_MODULE_PATH",
                                                             "CMAKE_PREFIX_PATH", "PYTHONPATH")}
    env.update(ROS_PACKAGE_PATH=ROOT, ROS_MASTER_URI="http://%s:%d/" % (LOOPBACK, port), ROS_IP=LOOPBACK,
               ROS_HOME=str(tmp_path / "home"), PWD=str(tmp_path), PYTHONUNBUFFERED="1",
               PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))  # nodes' python3
    return env


def _roslaunch(tmp_path, env, *args, name="sim"):
    log = open(str(tmp_path / ("%s.out" % name)), "w")
    proc = subprocess.Popen(["roslaunch", *args], stdout=log, stderr=subprocess.STDOUT, env=env, cwd=str(tmp_path),
                            stdin=subprocess.DEVNULL, start_new_session=True)
    proc.log_path = log.name
    log.close()
    return proc


def _stop(proc):
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)   # roslaunch's own group, started by this test
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)


def _nodes(uri):
    """The nodes registered on the master at ``uri`` (publishers, subscribers, services)."""
    code, _, state = xmlrpc.client.ServerProxy(uri).getSystemState("/test")
    assert code == 1
    return {n for kind in state for _topic, nodes in kind for n in nodes}


def _live(uri):
    from modules.discovery import live_modules

    try:
        return set(live_modules(uri))
    except OSError:
        return set()


@pytest.fixture
def launched(tmp_path):
    procs = []

    def start(*args, **kw):
        procs.append(_roslaunch(tmp_path, *args, **kw))
        return procs[-1]

    yield start
    for p in reversed(procs):
        _stop(p)


def test_sim_launch_starts_only_the_simulated_modules_named(tmp_path, launched):
    if not all(shutil.which(exe) for exe in ("roslaunch", "rosmaster")):
        pytest.fail("roslaunch and rosmaster are needed: `make setup` installs them")
    port = free_port()
    env = _env(tmp_path, port)
    uri = env["ROS_MASTER_URI"]
    launch = launched(env, "-p", str(port), "bmtree", "sim.launch", "modules:=speech")
    end = time.monotonic() + 60
    while "speech" not in _live(uri):
        assert launch.poll() is None and time.monotonic() < end, open(launch.log_path).read()[-3000:]
        time.sleep(0.2)
    out = open(launch.log_path).read()
    started = sorted(set(re.findall(r"process\[([a-z_]+)-\d+\]: started", out)) - {"rosout"})
    assert started == ["blackboard", "bm_speech"], out[-3000:]   # roslaunch started no other simulated module
    time.sleep(1.0)   # (had it started one, it would have registered by now, as the Blackboard has)
    nodes = _nodes(uri)
    assert "/bm_speech" in nodes and "/blackboard" in nodes, nodes
    assert not nodes & {"/bm_navigation", "/bm_vision", "/bm_battery"}, nodes
    assert _live(uri) == {"speech"}
    tree = tmp_path / "say.yaml"
    tree.write_text(SAY)
    ran = subprocess.run(bmtree_cmd("run", "-q", "--no-record", str(tree)), env=env, capture_output=True, text=True,
                         timeout=120, stdin=subprocess.DEVNULL)
    assert ran.returncode == 0 and "say_hi: SUCCESS" in ran.stdout, ran.stdout + ran.stderr
    assert launch.poll() is None


def test_sim_launch_modules_takes_spaces_or_commas_and_refuses_a_name_it_does_not_simulate(tmp_path, launched):
    port = free_port()
    env = _env(tmp_path, port)

    def nodes_of(*args):
        out = subprocess.run(["roslaunch", "--nodes", "bmtree", "sim.launch", *args], env=env, capture_output=True,
                             text=True, timeout=60, stdin=subprocess.DEVNULL, cwd=str(tmp_path))
        assert out.returncode == 0, out.stdout + out.stderr
        return out.stdout.split()

    assert nodes_of() == ["/blackboard"] + ["/bm_%s" % m for m in SIMULATED]   # all four by default
    assert nodes_of("modules:=") == ["/blackboard"] + ["/bm_%s" % m for m in SIMULATED]
    assert nodes_of("modules:=navigation,battery") == ["/blackboard", "/bm_navigation", "/bm_battery"]
    assert nodes_of("modules:=vision speech") == ["/blackboard", "/bm_vision", "/bm_speech"]
    # a typo ends the launch at once, naming it, before any master or node starts
    bad = launched(env, "-p", str(port), "bmtree", "sim.launch", "modules:=speech,navgation", name="bad")
    assert bad.wait(60) != 0
    out = open(bad.log_path).read()
    assert "sim.launch modules:=speech,navgation: no simulated module 'navgation' (the simulated modules are " \
           "navigation vision speech battery, separated by spaces or commas)" in out, out
    assert "started with pid" not in out, out
    with pytest.raises(OSError):
        xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"]).getSystemState("/test")
