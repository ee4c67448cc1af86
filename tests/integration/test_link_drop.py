"""A Wi-Fi link that drops for a while is no process that died, for real: two network namespaces (the robot:
master, Blackboard, modules; the laptop: ``bmtree run``) joined by a veth pair and a bridge, and the laptop's
link pulled for 12 s (longer than the kernel's keepalive probes take to give a connection up) while the run
waits, so that its next call is sent during the outage.

Before, the run reported that call ``module_lost: … node /bm_navigation stopped (its process is gone)`` about
3 s after sending it (the liveness check took "no route to host" for a refused connection), and the
Blackboard node "gone: results from now on are not stored (its process ended)", while every process lived.
Now the call waits for the link, bounded by its own timeout, and succeeds.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time

import pytest

from tests.integration.netnskit import Hosts, ip, machines, need_namespaces
from tests.integration.netnskit import bmtree as _bmtree

TAG = "bld%d" % (os.getpid() % 100000)
NS = {"robot": TAG + "r", "laptop": TAG + "l"}
ADDR = {"robot": "10.201.0.1", "laptop": "10.201.0.2"}
URI = "http://%s:11311/" % ADDR["robot"]
DOWN = 12.0   # s the laptop's link stays down: past TCP keepalive's ~11 s

TREE = """format: 1
name: drop
root:
  sequence:
    - call: speech.say
      inputs: {text: leaving}
    - wait: 2
      name: before the drive
    - call: navigation.go_to
      name: drive
      inputs: {place: kitchen}
      timeout: 60
"""


@pytest.fixture
def hosts():
    need_namespaces(TAG)
    with machines(NS, ADDR):
        h = Hosts(NS, ADDR, URI)
        yield h
        h.close()


def test_a_call_sent_while_the_link_is_down_waits_for_it_and_nothing_is_called_dead(hosts, slow_world, tmp_path):
    hosts.start("robot", shutil.which("rosmaster"), "--core", "-p", "11311", "-w", "3")
    hosts.start("robot", sys.executable, "-m", "blackboard.node", "--db", ":memory:")
    for module in ("navigation", "speech"):
        hosts.start("robot", sys.executable, "-m", "modules.sim", module, "--world", slow_world)
    tree = tmp_path / "drop.yaml"
    tree.write_text(TREE)
    run = subprocess.Popen(hosts.argv("laptop", *_bmtree("run", "--wait", "60", str(tree))), env=hosts.env("laptop"),
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, stdin=subprocess.DEVNULL)
    hosts.procs.append(run)
    lines = []
    pulled = threading.Event()

    def cable() -> None:
        ip("-n", NS["laptop"], "link", "set", "eth0", "down")   # the Wi-Fi drops
        pulled.set()
        time.sleep(DOWN)
        ip("-n", NS["laptop"], "link", "set", "eth0", "up")

    plug = threading.Thread(target=cable)
    for line in run.stdout:
        lines.append(line)
        if "RUNNING" in line and "before the drive" in line:
            plug.start()
            break
    rest = run.communicate(timeout=180)[0]
    plug.join(60)
    text = "".join(lines) + rest
    assert pulled.is_set(), text
    for p in hosts.procs[:-1]:   # every process of the robot lived through it
        assert p.poll() is None, open(p.log_path).read()
    assert run.returncode == 0 and "drop: SUCCESS" in text, text
    assert "process is gone" not in text and "process ended" not in text and "module_lost" not in text, text
    assert "restarted ROS master" not in text, text
