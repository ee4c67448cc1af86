"""A stand-in ROS node or master for tests: a process answering ``getPid`` over XML-RPC.

It is rosgraph's own XML-RPC server (the one rosmaster and rospy nodes use, HTTP/1.1 with
kept-alive connections) and counts the questions in a file; killing it closes its
connections as a dead node or master does.
"""
from __future__ import annotations

import signal
import socket
import subprocess
import sys

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

    def questions(self):
        try:
            with open(self.counter) as fh:
                return len(fh.readlines())
        except FileNotFoundError:
            return 0
