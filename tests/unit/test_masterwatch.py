"""MasterWatch against a stand-in master process (real sockets, real process death).

The stand-in is rosgraph's own XML-RPC server (the one rosmaster uses, HTTP/1.1) answering
``getPid`` and counting the questions in a file; killing it closes its connections as a dead
rosmaster does. Re-registration itself needs a rospy node and is tested with a real master in
``tests/integration/test_master_restart.py``.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from comm.masterwatch import MasterWatch, PidLine

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


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class StandIn:
    def __init__(self, tmp_path, http10=False):
        self.port = _free_port()
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


@pytest.fixture
def stand_in(tmp_path, monkeypatch):
    master = StandIn(tmp_path)
    master.start()
    monkeypatch.setenv("ROS_MASTER_URI", "http://127.0.0.1:%d/" % master.port)
    yield master
    if master.proc.poll() is None:
        master.kill()


def _until(check, timeout=10.0):
    end = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < end, "condition not met within %gs" % timeout
        time.sleep(0.02)


@pytest.fixture
def watch(stand_in, monkeypatch):
    w = MasterWatch(period=0.05)
    registered = []
    monkeypatch.setattr(w, "register_again", lambda: registered.append(time.monotonic()))
    w.registrations = registered
    w.start()
    yield w
    w.stop()
    w._thread.join(5)


def test_an_idle_node_asks_the_master_nothing(watch, stand_in):
    time.sleep(1.0)  # twenty periods: the old watch asked twenty times
    assert stand_in.questions() == 1  # the question at start only
    assert watch._thread.is_alive()


def test_a_killed_and_restarted_master_is_noticed_at_once_and_registered_with_again(watch, stand_in):
    first_pid = watch._pid
    stand_in.kill()
    killed = time.monotonic()
    stand_in.start()  # same port, another pid
    _until(lambda: watch.registrations)
    assert watch.registrations[0] - killed < 2.0
    assert watch.restarts == 1 and watch._pid == stand_in.proc.pid != first_pid
    before = stand_in.questions()
    time.sleep(0.5)
    assert stand_in.questions() == before  # idle again: waiting on the new connection


def test_a_master_that_comes_back_after_a_while_is_waited_for(watch, stand_in):
    stand_in.kill()
    time.sleep(0.5)  # down: asked every period, nobody answers
    assert not watch.registrations
    stand_in.start()
    _until(lambda: watch.registrations)
    assert watch.restarts == 1


def test_stop_ends_the_waiting_thread_at_once(watch):
    t0 = time.monotonic()
    watch.stop()
    watch._thread.join(5)
    assert not watch._thread.is_alive() and time.monotonic() - t0 < 1.0


def test_a_master_that_closes_every_connection_is_asked_every_period(tmp_path, monkeypatch):
    master = StandIn(tmp_path, http10=True)
    master.start()
    try:
        line = PidLine("http://127.0.0.1:%d/" % master.port, 2.0)
        assert line.pid() == master.proc.pid and not line.kept
        monkeypatch.setenv("ROS_MASTER_URI", "http://127.0.0.1:%d/" % master.port)
        w = MasterWatch(period=0.05)
        w.start()
        try:
            _until(lambda: master.questions() >= 6)
        finally:
            w.stop()
        assert w.restarts == 0
    finally:
        master.kill()


def test_the_pid_line_answers_none_without_a_master_and_keeps_its_connection_with_one(stand_in):
    line = PidLine("http://127.0.0.1:%d/" % _free_port(), 1.0)
    assert line.pid() is None and not line.kept
    line = PidLine("http://127.0.0.1:%d/" % stand_in.port, 1.0)
    assert line.pid() == stand_in.proc.pid and line.kept
    sock = line._conn.sock
    assert sock.getsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE) == 1
    assert line.pid() == stand_in.proc.pid and line._conn.sock is sock  # the same connection
    line.close()
    assert os.path.exists(stand_in.counter)
