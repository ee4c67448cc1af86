"""A stand-in ROS node or master for tests: a process answering ``getPid`` over XML-RPC.

It is rosgraph's own XML-RPC server (the one rosmaster and rospy nodes use, HTTP/1.1 with
kept-alive connections) and counts the questions in a file; killing it closes its
connections as a dead node or master does.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time

__all__ = ["StandIn", "free_port"]

STAND_IN = r"""
import os, sys
from rosgraph.xmlrpc import SilenceableXMLRPCRequestHandler, ThreadingXMLRPCServer
port, counter, http10 = int(sys.argv[1]), sys.argv[2], sys.argv[3] == "1"
if http10:  # a server that closes the connection after every answer
    SilenceableXMLRPCRequestHandler.protocol_version = "HTTP/1.0"
server = ThreadingXMLRPCServer(("127.0.0.1", port), log_requests=False)
def getPid(caller):
    with open(counter, "a") as fh:
        fh.write("q\n")
    return [1, "", os.getpid()]
server.register_function(getPid)
print("ready", flush=True)
server.serve_forever()
"""


def _all_stopped(pid):
    """Every thread of process ``pid`` is stopped (state T in /proc)."""
    tasks = os.listdir("/proc/%d/task" % pid)
    for tid in tasks:
        with open("/proc/%d/task/%s/stat" % (pid, tid)) as fh:
            if fh.read().rsplit(")", 1)[1].split()[0] != "T":
                return False
    return bool(tasks)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class StandIn:
    def __init__(self, tmp_path, http10=False):
        self.port = free_port()
        self.counter = str(tmp_path / "questions")
        self.http10 = http10
        self.proc = None

    def start(self):
        self.proc = subprocess.Popen([sys.executable, "-c", STAND_IN, str(self.port), self.counter,
                                      "1" if self.http10 else "0"], stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout.readline().strip() == "ready"

    def kill(self):
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(5)

    def stop(self, timeout=10.0):
        """SIGSTOP, and wait until every thread of the process is stopped: kill() returns before a thread
        running on another core has stopped, and such a thread could still answer a question sent now."""
        self.proc.send_signal(signal.SIGSTOP)
        end = time.monotonic() + timeout
        while not _all_stopped(self.proc.pid):
            assert time.monotonic() < end, "the stand-in (pid %d) did not stop" % self.proc.pid
            time.sleep(0.005)

    def resume(self):
        self.proc.send_signal(signal.SIGCONT)

    def questions(self):
        try:
            with open(self.counter) as fh:
                return len(fh.readlines())
        except FileNotFoundError:
            return 0
