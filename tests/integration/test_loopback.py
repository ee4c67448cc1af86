"""Single-machine default: what ``bmtree run --sim`` starts listens on loopback only (checked with ``ss``),
and ``--ros-ip`` opens it on purpose."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import threading

import pytest

from tests.integration.conftest import bmtree_cmd

LONG_TREE = "format: 1\nroot:\n  sequence:\n    - call: speech.say\n      inputs: {text: hello}\n    - wait: 600\n"


def _descendants(pid):
    """``pid`` and every process below it (from /proc)."""
    children = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open("/proc/%s/stat" % entry) as fh:
                    ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry))
    found, todo = set(), [pid]
    while todo:
        p = todo.pop()
        if p not in found:
            found.add(p)
            todo.extend(children.get(p, []))
    return found


def _listening(pids):
    """(local address, port, pid) of every listening TCP/UDP socket of ``pids``, from ``ss``."""
    out = subprocess.run(["ss", "-H", "-l", "-n", "-t", "-u", "-p"], capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    found = []
    for line in out.stdout.splitlines():
        owners = {int(p) for p in re.findall(r"pid=(\d+)", line)}
        if owners & pids:
            local = line.split()[4]
            addr, _, port = local.rpartition(":")
            found.append((addr.split("%")[0], int(port), sorted(owners & pids)[0]))
    return found


def _run_long(tmp_path, *extra):
    tree = tmp_path / "long.yaml"
    tree.write_text(LONG_TREE)
    env = dict(os.environ, ROS_HOSTNAME="bmtree-user-hostname.example", ROS_IP="")
    proc = subprocess.Popen(bmtree_cmd("run", "--sim", "-q", *extra, str(tree)), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env, stdin=subprocess.DEVNULL)
    lines = []
    guard = threading.Timer(120, proc.kill)  # a run that never says "running" must not hang the suite
    guard.start()
    try:
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("running "):
                return proc, lines
    finally:
        guard.cancel()
    proc.wait(30)
    raise AssertionError("bmtree run ended before the tree ran:\n" + "".join(lines))


def _stop(proc):
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)
    proc.stdout.close()


def test_a_private_graph_listens_on_loopback_only(tmp_path):
    proc, lines = _run_long(tmp_path)
    try:
        pids = _descendants(proc.pid)
        assert len(pids) >= 6, "expected bmtree, rosmaster, the Blackboard and 3 modules, got %s" % pids
        sockets = _listening(pids)
        # the master, and each node's XML-RPC and TCPROS servers
        assert len({pid for _, _, pid in sockets}) >= 6 and len(sockets) >= 11, sockets
        exposed = [s for s in sockets if s[0] not in ("127.0.0.1", "[::1]")]
        assert exposed == [], "listening beyond loopback: %s" % exposed
        assert any("master at http://127.0.0.1:" in line for line in lines), lines
    finally:
        _stop(proc)


def _public_address():
    out = subprocess.run(["ip", "-4", "-o", "addr", "show", "scope", "global"], capture_output=True, text=True,
                         timeout=30)
    found = re.findall(r"inet (\d+\.\d+\.\d+\.\d+)/", out.stdout)
    return found[0] if found else ""


def test_ros_ip_opens_the_private_graph_on_purpose(tmp_path):
    address = _public_address()
    if not address:
        pytest.skip("--ros-ip needs an address other nodes can reach, and `ip -4 addr show scope global` "
                    "lists none on this machine (only loopback): connect it to a network to run this test")
    proc, lines = _run_long(tmp_path, "--ros-ip", address)
    try:
        sockets = _listening(_descendants(proc.pid))
        assert any(s[0] in ("0.0.0.0", "*", address) for s in sockets), sockets
        assert any("master at http://%s:" % address in line for line in lines), lines
    finally:
        _stop(proc)
