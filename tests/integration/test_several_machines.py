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

import pytest

from tests.conftest import TREES
from tests.integration.netnskit import Hosts, ip, machines, need_namespaces
from tests.integration.netnskit import bmtree as _bmtree

TAG = "bmt%d" % (os.getpid() % 100000)
NS = {"master": TAG + "m", "modules": TAG + "n", "coord": TAG + "c"}
ADDR = {"master": "10.200.0.1", "modules": "10.200.0.2", "coord": "10.200.0.3"}
URI = "http://%s:11311/" % ADDR["master"]


@pytest.fixture
def network():
    need_namespaces(TAG)
    with machines(NS, ADDR):
        yield NS


@pytest.fixture
def hosts(network):
    h = Hosts(NS, ADDR, URI)
    yield h
    h.close()


def test_modules_blackboard_and_coordinator_on_three_hosts(hosts, slow_world, tmp_path):
    import shutil

    # the namespaces really are separate hosts: no loopback shortcut, only the little network
    ping = hosts.run("coord", "ping", "-c", "1", "-W", "5", ADDR["modules"]) if shutil.which("ping") else None
    assert ping is None or ping.returncode == 0, ping.stdout + ping.stderr
    assert ADDR["modules"] not in ip("-4", "addr").stdout  # not on this machine's own network

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
            ip("-n", NS["modules"], "link", "set", "eth0", "down")  # the cable is pulled
            break
    rest = run.communicate(timeout=120)[0]
    text = "".join(lines) + rest
    assert run.returncode == 1, text
    assert "kitchen: FAILURE" in text
    call = [line for line in text.splitlines() if line.strip().startswith("+") and "navigation.go_to" in line]
    assert len(call) == 1 and " timeout " in call[0], text
