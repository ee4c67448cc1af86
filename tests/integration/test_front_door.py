"""Where the machine's hostname does not resolve (minimal images, containers, chroots).

Each test runs bmtree in a UTS namespace of its own whose hostname resolves nowhere, the
condition of a fresh minimal Debian: private graphs must work, a user's own graph must say
which variable to set.
"""
from __future__ import annotations

import os
import socket
import subprocess
import sys
import textwrap

from tests.conftest import ROOT, TREES
from tests.integration.conftest import bmtree_cmd, start_sim_module

NOWHERE = "bmtree-unresolvable-host"


def nowhere(argv):
    """``argv`` run under a hostname that does not resolve."""
    unshare = ["unshare", "--uts"] if os.geteuid() == 0 else ["unshare", "--map-root-user", "--uts"]
    return [*unshare, "sh", "-c", 'hostname "$0" && exec "$@"', NOWHERE, *argv]


def env_without_addressing(**extra):
    env = dict(os.environ)
    env.pop("ROS_IP", None)
    env.pop("ROS_HOSTNAME", None)
    env.update(extra)
    return env


def test_the_hostname_really_does_not_resolve():
    out = subprocess.run(nowhere(["hostname"]), capture_output=True, text=True, timeout=30)
    assert out.stdout.strip() == NOWHERE
    try:
        socket.getaddrinfo(NOWHERE, None)
        raise AssertionError("%s resolves on this machine: the tests below would prove nothing" % NOWHERE)
    except OSError:
        pass


def test_sim_run_works_where_the_hostname_does_not_resolve():
    # a user's own ROS_HOSTNAME that resolves nowhere must not leak into the private graph either
    env = env_without_addressing(ROS_HOSTNAME=NOWHERE)
    out = subprocess.run(nowhere(bmtree_cmd("run", "--sim", os.path.join(TREES, "find_apple.yaml"), "-q")),
                         capture_output=True, text=True, timeout=180, env=env, stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "find_apple: SUCCESS" in out.stdout


def test_own_graph_unreachable_says_which_variable_to_set(ros_graph):
    start_sim_module(ros_graph, "speech")
    tree = os.path.join(ROOT, "tests", "data", "say_hello.yaml")
    out = subprocess.run(nowhere(bmtree_cmd("run", tree, "--wait", "3", "-q")), capture_output=True, text=True,
                         timeout=120, env=env_without_addressing(), stdin=subprocess.DEVNULL)
    assert out.returncode == 3, out.stdout + out.stderr
    assert "%r does not resolve" % NOWHERE in out.stderr
    assert "ROS_IP" in out.stderr and "ROS_HOSTNAME" in out.stderr
    # and with ROS_IP the same command works
    out = subprocess.run(nowhere(bmtree_cmd("run", tree, "--wait", "10", "-q")), capture_output=True, text=True,
                         timeout=120, env=env_without_addressing(ROS_IP="127.0.0.1"), stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stdout + out.stderr


def test_plugin_fixtures_work_where_the_hostname_does_not_resolve(tmp_path):
    """A user's integration test with the plugin's fixtures, in a pytest of its own."""
    test = tmp_path / "test_user_graph.py"
    test.write_text(textwrap.dedent('''
        import json
        from modules.definition import load_definitions
        from modules.sim import SIM_DIR

        def test_call_a_module(ros_graph, ros_probe):
            ros_graph.start_node(["-m", "modules.sim", "speech", "__name:=bm_speech"], "/bm_speech")
            results = ros_probe.collect("/function/output", publishers=1)
            call = load_definitions([SIM_DIR])["speech"].function("say").build_call({"text": "hi"})
            ros_probe.publish("/master/output", call.encode())
            got = results.wait_for(lambda t: json.loads(t).get("call_id") == call.call_id, 20)
            assert json.loads(got[0])["status"] == "succeeded"
    '''))
    env = env_without_addressing(PYTHONPATH=ROOT)
    env.pop("ROS_MASTER_URI", None)
    out = subprocess.run(nowhere([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(test)]),
                         capture_output=True, text=True, timeout=180, env=env, cwd=str(tmp_path),
                         stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "1 passed" in out.stdout
