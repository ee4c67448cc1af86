"""Several machines on this one: network namespaces joined by veth pairs and a bridge (needs root).

One namespace per role; the first role's namespace (the master's) also holds the bridge ``br0``
of the little network, each other role a veth pair into it. The addresses exist only inside the
namespaces, which are created and deleted by name (each test file gives its own prefix).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from contextlib import contextmanager
from typing import Dict, Iterator, List, Mapping, Optional

from coordinator.graph import end_processes

__all__ = ["ip", "can_create_namespaces", "machines", "Hosts", "bmtree"]


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    out = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if check and out.returncode != 0:
        raise OSError("ip %s: %s" % (" ".join(args), out.stderr.strip()))
    return out


def need_namespaces(tag: str) -> None:
    """Skip the test where machines cannot be simulated: creating network namespaces needs root and
    iproute2 (a CI container without them); ``tag``: the caller's namespace prefix."""
    import pytest

    reason = can_create_namespaces(tag + "p")
    if reason:
        pytest.skip("machines are simulated with network namespaces, which this machine cannot create: %s" % reason)


def can_create_namespaces(probe: str) -> str:
    """'' if this machine lets the test create network namespaces, else the reason (``probe``: a
    namespace name of the caller's own, created and deleted)."""
    if os.geteuid() != 0:
        return "creating network namespaces needs root (CAP_SYS_ADMIN and CAP_NET_ADMIN); running as uid %d" % (
            os.geteuid())
    try:
        ip("netns", "add", probe)
    except (OSError, FileNotFoundError) as exc:
        return "this machine cannot create network namespaces: %s" % exc
    ip("netns", "del", probe, check=False)
    return ""


def _delete(ns: Mapping[str, str]) -> None:
    for name in ns.values():
        ip("netns", "del", name, check=False)


@contextmanager
def machines(ns: Mapping[str, str], addr: Mapping[str, str]) -> Iterator[Mapping[str, str]]:
    """The namespaces ``ns`` (role -> name), each role at ``addr[role]`` on one /24; all deleted at the end."""
    _delete(ns)
    try:
        for name in ns.values():
            ip("netns", "add", name)
            ip("-n", name, "link", "set", "lo", "up")
        roles = list(ns)
        m = ns[roles[0]]
        ip("-n", m, "link", "add", "br0", "type", "bridge")
        ip("-n", m, "addr", "add", addr[roles[0]] + "/24", "dev", "br0")
        ip("-n", m, "link", "set", "br0", "up")
        for role in roles[1:]:
            inner, outer = "eth0", "to_" + role
            ip("-n", ns[role], "link", "add", inner, "type", "veth", "peer", "name", outer, "netns", m)
            ip("-n", ns[role], "addr", "add", addr[role] + "/24", "dev", inner)
            ip("-n", ns[role], "link", "set", inner, "up")
            ip("-n", m, "link", "set", outer, "master", "br0")
            ip("-n", m, "link", "set", outer, "up")
        yield ns
    finally:
        _delete(ns)


class Hosts:
    """Processes started in the namespaces (each ended by its pid).

    Every process gets ``ROS_MASTER_URI=master_uri`` and its role's address as ``ROS_IP``, as the
    README's "Several machines" says; ``ros_ip`` overrides a role's (None: ``ROS_IP`` unset).
    """

    def __init__(self, ns: Mapping[str, str], addr: Mapping[str, str], master_uri: str):
        self.ns = dict(ns)
        self.addr = dict(addr)
        self.master_uri = master_uri
        self.ros_ip: Dict[str, Optional[str]] = {}
        self.home = tempfile.mkdtemp(prefix="bmtree-netns-")
        self.procs: List[subprocess.Popen] = []

    def env(self, role: str) -> Dict[str, str]:
        env = dict(os.environ, ROS_MASTER_URI=self.master_uri, ROS_HOME=os.path.join(self.home, role),
                   PYTHONUNBUFFERED="1")
        address = self.ros_ip.get(role, self.addr[role])
        if address is None:
            env.pop("ROS_IP", None)
        else:
            env["ROS_IP"] = address
        env.pop("ROS_HOSTNAME", None)
        env.pop("ROS_LOG_DIR", None)
        return env

    def argv(self, role: str, *args: str) -> List[str]:
        return ["ip", "netns", "exec", self.ns[role], *args]

    def start(self, role: str, *args: str) -> subprocess.Popen:
        log = open(os.path.join(self.home, "%s-%d.out" % (role, len(self.procs))), "w")
        proc = subprocess.Popen(self.argv(role, *args), env=self.env(role), stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL)
        proc.log_path = log.name  # type: ignore[attr-defined]
        log.close()
        self.procs.append(proc)
        return proc

    def run(self, role: str, *args: str, timeout: float = 180) -> subprocess.CompletedProcess:
        return subprocess.run(self.argv(role, *args), env=self.env(role), capture_output=True, text=True,
                              timeout=timeout, stdin=subprocess.DEVNULL)

    def close(self) -> None:
        """SIGINT to all at once, then wait: a node cut off from the master cannot unregister in time."""
        end_processes(self.procs, 10)
        shutil.rmtree(self.home, ignore_errors=True)


def bmtree(*args: str) -> List[str]:
    return [sys.executable, "-m", "coordinator", *args]
