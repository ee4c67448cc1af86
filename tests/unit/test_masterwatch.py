"""MasterWatch against a stand-in master process (real sockets, real process death).

Re-registration itself needs a rospy node and is tested with a real master in
``tests/integration/test_master_restart.py``.
"""
from __future__ import annotations

import os
import socket
import time

import pytest

from comm.masterwatch import MasterWatch
from comm.rpc import PidLine
from tests.conftest import until
from tests.unit.xmlrpc_standin import StandIn, free_port


@pytest.fixture
def stand_in(tmp_path, monkeypatch):
    master = StandIn(tmp_path)
    master.start()
    monkeypatch.setenv("ROS_MASTER_URI", "http://127.0.0.1:%d/" % master.port)
    yield master
    if master.proc.poll() is None:
        master.kill()


@pytest.fixture
def watch(stand_in, monkeypatch):
    w = MasterWatch(period=0.05)
    registered = []
    monkeypatch.setattr(w, "register_again", lambda restarted=True: registered.append(time.monotonic()))
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
    until(lambda: watch.registrations)
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
    until(lambda: watch.registrations)
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
            until(lambda: master.questions() >= 6)
        finally:
            w.stop()
        assert w.restarts == 0
    finally:
        master.kill()


def test_the_pid_line_answers_none_without_a_master_and_keeps_its_connection_with_one(stand_in):
    line = PidLine("http://127.0.0.1:%d/" % free_port(), 1.0)
    assert line.pid() is None and not line.kept
    line = PidLine("http://127.0.0.1:%d/" % stand_in.port, 1.0)
    assert line.pid() == stand_in.proc.pid and line.kept
    sock = line._conn.sock
    assert sock.getsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE) == 1
    assert line.pid() == stand_in.proc.pid and line._conn.sock is sock  # the same connection
    line.close()
    assert os.path.exists(stand_in.counter)
