"""Several machines, for real, on this one: three network namespaces joined by veth pairs and a bridge.

    ns "master" 10.200.0.1   rosmaster, the Blackboard node (and the bridge of the little network)
    ns "modules" 10.200.0.2  the simulated navigation, vision and speech modules
    ns "coord" 10.200.0.3    bmtree run

Every process gets ROS_MASTER_URI=http://10.200.0.1:11311/ and its own namespace's address as
ROS_IP, exactly as on three computers (README "Several machines"). The addresses exist only
inside the namespaces this test creates, and everything is deleted by name at the end.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import pytest

from coordinator.graph import end_processes
from tests.conftest import TREES

TAG = "bmt%d" % (os.getpid() % 100000)
NS = {"master": TAG + "m", "modules": TAG + "n", "coord": TAG + "c"}
ADDR = {"master": "10.200.0.1", "modules": "10.200.0.2", "coord": "10.200.0.3"}
URI = "http://%s:11311/" % ADDR["master"]


def _ip(*args, check=True):
    out = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if check and out.returncode != 0:
        raise OSError("ip %s: %s" % (" ".join(args), out.stderr.strip()))
    return out


def _can_create_namespaces():
    """'' if this machine lets the test create network namespaces, else the reason."""
    if os.geteuid() != 0:
        return "creating network namespaces needs root (CAP_SYS_ADMIN and CAP_NET_ADMIN); running as uid %d" % (
            os.geteuid())
    probe = TAG + "p"
    try:
        _ip("netns", "add", probe)
    except (OSError, FileNotFoundError) as exc:
        return "this machine cannot create network namespaces: %s" % exc
    _ip("netns", "del", probe, check=False)
    return ""


def _delete_all():
    for ns in NS.values():
        _ip("netns", "del", ns, check=False)


@pytest.fixture
def network():
    reason = _can_create_namespaces()
    if reason:
        pytest.skip("three machines are simulated with network namespaces, which this machine cannot create: %s" % reason)
    _delete_all()
    try:
        for ns in NS.values():
            _ip("netns", "add", ns)
            _ip("-n", ns, "link", "set", "lo", "up")
        m = NS["master"]
        _ip("-n", m, "link", "add", "br0", "type", "bridge")
        _ip("-n", m, "addr", "add", ADDR["master"] + "/24", "dev", "br0")
        _ip("-n", m, "link", "set", "br0", "up")
        for role in ("modules", "coord"):
            inner, outer = "eth0", "to_" + role
            _ip("-n", NS[role], "link", "add", inner, "type", "veth", "peer", "name", outer, "netns", m)
            _ip("-n", NS[role], "addr", "add", ADDR[role] + "/24", "dev", inner)
            _ip("-n", NS[role], "link", "set", inner, "up")
            _ip("-n", m, "link", "set", outer, "master", "br0")
            _ip("-n", m, "link", "set", outer, "up")
        yield NS
    finally:
        _delete_all()


class Hosts:
    """Processes started in the namespaces (each ended by its pid)."""

    def __init__(self):
        self.home = tempfile.mkdtemp(prefix="bmtree-netns-")
        self.procs = []

    def env(self, role):
        env = dict(os.environ, ROS_MASTER_URI=URI, ROS_IP=ADDR[role], ROS_HOME=os.path.join(self.home, role),
                   PYTHONUNBUFFERED="1")
        env.pop("ROS_HOSTNAME", None)
        env.pop("ROS_LOG_DIR", None)
        return env

    def argv(self, role, *args):
        return ["ip", "netns", "exec", NS[role], *args]

    def start(self, role, *args):
        log = open(os.path.join(self.home, "%s-%d.out" % (role, len(self.procs))), "w")
        proc = subprocess.Popen(self.argv(role, *args), env=self.env(role), stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL)
        proc.log_path = log.name
        log.close()
        self.procs.append(proc)
        return proc

    def run(self, role, *args, timeout=180):
        return subprocess.run(self.argv(role, *args), env=self.env(role), capture_output=True, text=True,
                              timeout=timeout, stdin=subprocess.DEVNULL)

    def close(self):
        """SIGINT to all at once, then wait: a node cut off from the master cannot unregister in time."""
        end_processes(self.procs, 10)


@pytest.fixture
def hosts(network):
    h = Hosts()
    yield h
    h.close()


def _bmtree(*args):
    return [sys.executable, "-m", "coordinator", *args]


def test_modules_blackboard_and_coordinator_on_three_hosts(hosts, slow_world, tmp_path):
    import shutil

    # the namespaces really are separate hosts: no loopback shortcut, only the little network
    ping = hosts.run("coord", "ping", "-c", "1", "-W", "5", ADDR["modules"]) if shutil.which("ping") else None
    assert ping is None or ping.returncode == 0, ping.stdout + ping.stderr
    assert ADDR["modules"] not in _ip("-4", "addr").stdout  # not on this machine's own network

    hosts.start("master", shutil.which("rosmaster"), "--core", "-p", "11311", "-w", "3")
    hosts.start("master", sys.executable, "-m", "blackboard.node", "--db", ":memory:")
    for module in ("navigation", "vision", "speech"):
        hosts.start("modules", sys.executable, "-m", "modules.sim", module, "--world", slow_world)
    # `modules --live` from the coordinator's host waits for the master (event-based, bounded)
    listing = ""
    for _attempt in range(60):
        out = hosts.run("coord", *_bmtree("modules", "--live", "--wait", "30"))
        listing = out.stdout
        if all("%s  (node /bm_%s)" % (m, m) in listing for m in ("navigation", "vision", "speech")):
            break
        for p in hosts.procs:
            assert p.poll() is None, open(p.log_path).read()
    assert "navigation  (node /bm_navigation)" in listing, listing + out.stderr

    out = hosts.run("coord", *_bmtree("run", "-q", "--wait", "60", os.path.join(TREES, "find_apple.yaml")))
    assert out.returncode == 0, out.stdout + out.stderr
    assert "find_apple: SUCCESS" in out.stdout

    # a call that succeeds with the link up ...
    tree = tmp_path / "kitchen.yaml"
    tree.write_text("format: 1\nname: kitchen\nroot:\n  call: navigation.go_to\n  name: drive to the kitchen\n"
                    "  inputs: {place: bedroom}\n  timeout: 12\n")
    out = hosts.run("coord", *_bmtree("run", "-q", "--wait", "60", str(tree)))
    assert out.returncode == 0 and "kitchen: SUCCESS" in out.stdout, out.stdout + out.stderr
    # ... fails within its timeout when the modules' host drops off the network mid-call
    tree.write_text(tree.read_text().replace("bedroom", "kitchen"))
    run = subprocess.Popen(hosts.argv("coord", *_bmtree("run", "--wait", "60", str(tree))), env=hosts.env("coord"),
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, stdin=subprocess.DEVNULL)
    hosts.procs.append(run)
    lines = []
    for line in run.stdout:
        lines.append(line)
        if "RUNNING" in line and "drive to the kitchen" in line:
            _ip("-n", NS["modules"], "link", "set", "eth0", "down")  # the cable is pulled
            break
    rest = run.communicate(timeout=120)[0]
    text = "".join(lines) + rest
    assert run.returncode == 1, text
    assert "kitchen: FAILURE" in text
    call = [line for line in text.splitlines() if line.strip().startswith("+") and "navigation.go_to" in line]
    assert len(call) == 1 and " timeout " in call[0], text
