"""A private ROS graph: ``rosmaster`` on a free port and nodes as processes.

Used by ``bmtree run --sim``/``demo``, the test kit's fixtures and the benchmarks.
Every process it starts is ended by pid, nothing else is touched. Each runs in its own session
(a Ctrl-C in the terminal reaches only the coordinator, which stops the graph: its nodes
together, then the ``stop_last`` ones, then the master) and, where util-linux's ``setpriv`` is
installed (Debian and Ubuntu always have it), gets SIGTERM when the process that started it
dies, even by SIGKILL or the OOM killer: nothing is orphaned.
"""
from __future__ import annotations

import http.client
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import xmlrpc.client
from typing import Callable, Dict, List, Optional, Sequence, Set

from comm.errors import EnvironmentProblem
from modules.discovery import node_alive

_HOME = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))   # where bmtree's packages are
# ``python -m`` would put the working directory first on sys.path, where a team's own ``modules/``
# folder hides bmtree's package: run the module with bmtree's folder there instead.
_RUN_MODULE = ("import runpy, sys; sys.path[0] = %r; del sys.argv[0]; "
               "runpy.run_module(sys.argv[0], run_name='__main__', alter_sys=True)" % _HOME)

__all__ = ["RosGraph", "GraphError", "free_port", "orphan_guard", "end_processes", "LOOPBACK"]

#: Address every process of a private graph advertises: the graph works where the machine's
#: hostname does not resolve (minimal images, containers, chroots) and exposes nothing.
LOOPBACK = "127.0.0.1"


def orphan_guard() -> List[str]:
    """The prefix that makes a child get SIGTERM when its starter dies (empty without ``setpriv``).

    The kernel ties this to the *thread* that started the child (``PR_SET_PDEATHSIG``): start
    a graph's processes from a thread that lives as long as the graph, as the main thread does.
    """
    exe = shutil.which("setpriv")
    return [exe, "--pdeathsig", "TERM", "--"] if exe else []


def end_processes(procs: Sequence[subprocess.Popen], timeout: float, sig: int = signal.SIGINT) -> None:
    """Ask every process still running to stop, then wait for them together; kill what is left
    after ``timeout`` seconds."""
    asked = [p for p in procs if p.poll() is None]
    for proc in asked:
        proc.send_signal(sig)
    end = time.monotonic() + timeout
    for proc in asked:
        try:
            proc.wait(max(0.0, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


class GraphError(EnvironmentProblem):
    """A process of the graph did not start or register in time."""


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((LOOPBACK, 0))
        return s.getsockname()[1]


def port_free(address: str, port: int) -> bool:
    """Whether a server could listen on ``address``:``port`` now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((address, port))
        except OSError:
            return False
    return True


class RosGraph:
    """Start with :meth:`start_master`, add nodes with :meth:`start_node`, end with :meth:`close`.

    Args:
        ros_home: ROS_HOME for every process (logs, the Blackboard's store); a
            temporary directory (removed at close) when not given.
        master_uri: an already running master to start nodes against.
        address: the ROS_IP of every process (default loopback: nothing is reachable from other
            machines; ROS 1 has no authentication). Another address opens the graph to that network.
    """

    def __init__(self, ros_home: Optional[str] = None, master_uri: str = "", address: str = ""):
        self.address = address or LOOPBACK
        self._tmp = None if ros_home else tempfile.mkdtemp(prefix="bmtree-ros-")
        self.ros_home = ros_home or self._tmp or ""
        os.makedirs(self.ros_home, exist_ok=True)
        self.uri = master_uri  # given: use that master, never stop it
        self.master: Optional[subprocess.Popen] = None
        self.nodes: List[subprocess.Popen] = []
        self._last: Set[int] = set()  # pids of the nodes stopped after the others
        self._names: Set[str] = set()  # every node name started, for forget_dead_nodes
        #: node name -> its process (the last one started under that name), for what asks why it ended
        self.procs: Dict[str, subprocess.Popen] = {}
        self._logs: List = []

    @property
    def env(self) -> Dict[str, str]:
        env = dict(os.environ)
        env.update(self.ros_env(), PYTHONUNBUFFERED="1")
        env.pop("ROS_HOSTNAME", None)
        return env

    def ros_env(self) -> Dict[str, str]:
        """The ROS variables of a process that joins this graph (loopback addressing)."""
        return {"ROS_MASTER_URI": self.uri, "ROS_HOME": self.ros_home,
                "ROS_LOG_DIR": os.path.join(self.ros_home, "log"), "ROS_IP": self.address}

    def adopt(self, home: bool = False) -> Callable[[], None]:
        """Make this process a member of the graph (before ``rospy.init_node``): its master and
        loopback addressing, so nodes can connect back to it whatever the hostname; with
        ``home``, its ``ROS_HOME`` too. Returns a function that restores the environment."""
        keys = ("ROS_MASTER_URI", "ROS_HOME", "ROS_LOG_DIR", "ROS_IP", "ROS_HOSTNAME")
        saved = {k: os.environ.get(k) for k in keys}
        os.environ.pop("ROS_HOSTNAME", None)
        env = self.ros_env()
        if not home:
            env.pop("ROS_HOME")
            env.pop("ROS_LOG_DIR")
        os.environ.update(env)

        def restore() -> None:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        return restore

    def log_path(self, name: str) -> str:
        """The file that takes the output of process ``name`` (a node's name, or ``rosmaster``)."""
        return os.path.join(self.ros_home, "%s.out" % name.strip("/").replace("/", "_"))

    def _log(self, name: str):
        fh = open(self.log_path(name), "ab")
        self._logs.append(fh)
        return fh

    def start_master(self, timeout: float = 15.0, port: int = 0) -> str:
        """Start a master on ``port`` (0: a free one, tried up to three times) and wait until it answers."""
        exe = shutil.which("rosmaster")
        if exe is None:
            raise GraphError("rosmaster is not installed (run 'make setup' or install python3-rosmaster)")
        if port and not port_free(self.address, port):
            raise GraphError("port %d of %s is in use (another ROS master, or another program): give another --port, "
                             "or none for a free one" % (port, self.address))
        for _attempt in range(1 if port else 3):
            at = port or free_port()
            self.uri = "http://%s:%d/" % (self.address, at)
            log = self._log("rosmaster")
            self.master = subprocess.Popen([*orphan_guard(), exe, "--core", "-p", str(at), "-w", "3"], env=self.env,
                                           stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                           start_new_session=True)
            end = time.monotonic() + timeout
            while time.monotonic() < end and self.master.poll() is None:
                try:
                    code, _, _ = xmlrpc.client.ServerProxy(self.uri).getPid("/bmtree")
                    if code == 1:
                        return self.uri
                except OSError:
                    pass
                time.sleep(0.05)
            self._end(self.master, sig=signal.SIGTERM)
        raise GraphError("rosmaster did not start (see %s)" % os.path.join(self.ros_home, "rosmaster.out"))

    def start_node(self, args: Sequence[str], name: str, timeout: float = 20.0,
                   env: Optional[Dict[str, str]] = None, wait: bool = True,
                   stop_last: bool = False) -> subprocess.Popen:
        """Start ``args`` (a leading ``-m``: that module, with ``sys.executable`` and not the working
        directory on its path) and, with ``wait``,
        wait until the node ``name`` is registered with the master and answers.

        :meth:`close` stops the nodes all at once (rospy takes over half a second to stop a node:
        its XML-RPC server polls twice a second), those started with ``stop_last`` (the
        Blackboard, which stores what the others sent) once the others have ended."""
        argv = [sys.executable, "-c", _RUN_MODULE, *args[1:]] if args and args[0] == "-m" else list(args)
        proc = subprocess.Popen([*orphan_guard(), *argv], env=dict(self.env, **(env or {})), stdin=subprocess.DEVNULL,
                                stdout=self._log(name), stderr=subprocess.STDOUT, start_new_session=True)
        self.nodes.append(proc)
        self._names.add(name)
        self.procs[name] = proc
        if stop_last:
            self._last.add(proc.pid)
        if wait:
            self.wait_node(name, timeout, proc)
        return proc

    def wait_node(self, name: str, timeout: float = 20.0, proc: Optional[subprocess.Popen] = None) -> str:
        master = xmlrpc.client.ServerProxy(self.uri)
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if proc is not None and proc.poll() is not None:
                raise GraphError("node %s exited with code %s (see %s)" % (name, proc.returncode, self.log_path(name)))
            code, _, uri = master.lookupNode("/bmtree", name)
            if code == 1 and node_alive(uri, 0.5):
                return uri
            time.sleep(0.05)
        raise GraphError("node %s did not register within %gs" % (name, timeout))

    def stop_node(self, proc: subprocess.Popen, timeout: float = 5.0) -> Optional[int]:
        self._end(proc, timeout)
        if proc in self.nodes:
            self.nodes.remove(proc)
        return proc.returncode

    def kill_node(self, proc: subprocess.Popen) -> None:
        """SIGKILL: the node gets no chance to clean up (crash tests)."""
        proc.send_signal(signal.SIGKILL)
        proc.wait(5)
        if proc in self.nodes:
            self.nodes.remove(proc)

    @staticmethod
    def _end(proc: subprocess.Popen, timeout: float = 5.0, sig: int = signal.SIGINT) -> None:
        end_processes([proc], timeout, sig)

    def close(self) -> None:
        end_processes([p for p in self.nodes if p.pid not in self._last], 3.0)
        end_processes([p for p in self.nodes if p.pid in self._last], 3.0)
        self.nodes.clear()
        self._last.clear()
        self.procs.clear()
        if self.master is None and self.uri:
            self.forget_dead_nodes()
        if self.master is not None:
            # SIGTERM: a process started with SIGINT ignored (``cmd &`` in a script, nohup) passes
            # that on, and rosmaster, a plain Python program, then ignores Ctrl-C; bmtree's nodes
            # and roscpp catch SIGINT themselves. rosmaster keeps nothing to save.
            self._end(self.master, 3.0, signal.SIGTERM)
            self.master = None
        for fh in self._logs:
            fh.close()
        self._logs.clear()
        if self._tmp:
            shutil.rmtree(self._tmp, ignore_errors=True)

    def forget_dead_nodes(self) -> List[str]:
        """Unregister, from a master this graph shares, what its nodes killed outright (SIGKILL, or a
        stop that timed out) left there, as ``rosnode cleanup`` does for them alone: a later user of the
        master would otherwise see the node registered, publishing and subscribing. A node that answers
        is left alone. Returns the names cleaned up."""
        master = xmlrpc.client.ServerProxy(self.uri)
        forgotten = []
        try:
            _, _, state = master.getSystemState("/bmtree")
            for name in sorted(self._names):
                code, _, uri = master.lookupNode("/bmtree", name)
                if code != 1 or node_alive(uri, 0.5):
                    continue
                publishers, subscribers, services = state
                for topic, nodes in publishers:
                    if name in nodes:
                        master.unregisterPublisher(name, topic, uri)
                for topic, nodes in subscribers:
                    if name in nodes:
                        master.unregisterSubscriber(name, topic, uri)
                for service, nodes in services:
                    if name in nodes:
                        code, _, service_uri = master.lookupService("/bmtree", service)
                        if code == 1:
                            master.unregisterService(name, service, service_uri)
                forgotten.append(name)
        except (OSError, xmlrpc.client.Error, http.client.HTTPException):
            pass  # the master is gone: nothing is left to clean
        self._names.clear()
        return forgotten

    def __enter__(self) -> RosGraph:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
