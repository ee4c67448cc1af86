"""A module's machine with a loopback ROS_IP (day one on Ubuntu), for real: network namespaces.

    ns "master" 10.201.0.1   rosmaster
    ns "modules" 10.201.0.2  the simulated speech module, started with ROS_IP=127.0.0.1
    ns "coord" 10.201.0.3    bmtree modules --live, bmtree run

The module registers http://127.0.0.1:PORT/, which no other machine can reach: the module says
so when it starts, ``bmtree modules --live`` lists it as unreachable with that URI (it used to
leave it out silently), and the run's error names the address and ROS_IP (it used to say the
module was not connected yet, or not running).
"""
from __future__ import annotations

import os
import sys
import time

import pytest

from tests.conftest import DATA
from tests.integration.netnskit import Hosts, bmtree, machines, need_namespaces

TAG = "bmw%d" % (os.getpid() % 100000)
NS = {"master": TAG + "m", "modules": TAG + "n", "coord": TAG + "c"}
ADDR = {"master": "10.201.0.1", "modules": "10.201.0.2", "coord": "10.201.0.3"}
URI = "http://%s:11311/" % ADDR["master"]


@pytest.fixture
def hosts():
    need_namespaces(TAG)
    with machines(NS, ADDR):
        h = Hosts(NS, ADDR, URI)
        try:
            yield h
        finally:
            h.close()


def test_a_module_host_with_a_loopback_ros_ip_is_named(hosts):
    import shutil

    hosts.ros_ip["modules"] = "127.0.0.1"
    hosts.start("master", shutil.which("rosmaster"), "--core", "-p", "11311", "-w", "3")
    speech = hosts.start("modules", sys.executable, "-m", "modules.sim", "speech")

    # (b) listed, as unreachable, with the URI it registered
    listing = ""
    end = time.monotonic() + 20
    while "speech  (node /bm_speech" not in listing and time.monotonic() < end:
        assert speech.poll() is None, open(speech.log_path).read()
        out = hosts.run("coord", *bmtree("modules", "--live", "--wait", "10"), timeout=60)
        assert out.returncode == 0, out.stdout + out.stderr
        listing = out.stdout
        time.sleep(0.2)
    assert "speech  (node /bm_speech, unreachable)" in listing, listing
    assert "registered http://127.0.0.1:" in listing and "a loopback address" in listing, listing
    assert "ROS_IP" in listing, listing

    # (a) the run's error names the address problem and ROS_IP, not "not connected yet"
    out = hosts.run("coord", *bmtree("run", "-q", "--wait", "3", os.path.join(DATA, "say_hello.yaml")), timeout=60)
    assert out.returncode == 3, out.stdout + out.stderr
    error = next((line for line in out.stderr.splitlines() if line.startswith("error: ")), out.stderr)
    assert "module 'speech' cannot be reached: node /bm_speech registered http://127.0.0.1:" in error, out.stderr
    assert "a wrong ROS_IP on the machine that runs it?" in error, out.stderr
    assert "not connected" not in error and "is not running" not in error, out.stderr

    # (1) and the module itself said so when it started
    said = open(speech.log_path).read()
    assert "warning: ROS_IP=127.0.0.1 is a loopback address" in said, said
    assert "set ROS_IP=<an address of this machine on the robot's network, e.g. %s>" % ADDR["modules"] in said, said


def test_the_coordinators_own_loopback_ros_ip_is_said_once_before_what_it_causes(hosts):
    """bmtree run on a machine with ROS_IP=127.0.0.1 and the master on another: every module waited for
    carried ': subscribers cannot reach this process at … set ROS_IP', and the whole hint came again at
    the end (a line of 1,500 characters for four modules); the hint now comes once, first."""
    import shutil

    hosts.ros_ip["coord"] = "127.0.0.1"
    hosts.start("master", shutil.which("rosmaster"), "--core", "-p", "11311", "-w", "3")
    hosts.start("modules", sys.executable, "-m", "modules.sim", "speech")
    out = hosts.run("coord", *bmtree("run", "-q", "--wait", "4", os.path.join(DATA, "say_hello.yaml")), timeout=60)
    assert out.returncode == 3, out.stdout + out.stderr
    error = next((line for line in out.stderr.splitlines() if line.startswith("error: ")), out.stderr)
    assert error.startswith("error: ROS_IP=127.0.0.1 is a loopback address while the ROS master %s is not" % URI), error
    assert "; so: %s:4:9: module 'speech' (node /bm_speech) is not connected to" % os.path.relpath(
        os.path.join(DATA, "say_hello.yaml")) in error, error
    assert error.count("ROS_IP") == error[:error.index("; so: ")].count("ROS_IP"), error   # said once, first
