"""The liveness watchdog keeps a connection to each watched node and waits on it.

Against stand-in node processes (rosgraph's XML-RPC server answering ``getPid``): a node that
dies closes the connection and is reported at once, however long the period; a node that
stays up is not asked again. With real module processes: ``tests/integration/test_liveness.py``.
"""
from __future__ import annotations

import time

import pytest

from comm.liveness import ModuleLost, Watchdog
from tests.conftest import until
from tests.unit.xmlrpc_standin import StandIn


@pytest.fixture
def node(tmp_path):
    n = StandIn(tmp_path)
    n.start()
    yield n
    if n.proc.poll() is None:
        n.kill()


def _watching(node, period):
    got = []
    uri = "http://127.0.0.1:%d/" % node.port
    dog = Watchdog(got.append, lambda module: "/bm_x", lambda name: uri, period=period)
    dog.start()
    dog.call_sent("c1", "x")
    until(lambda: "x" in dog._known)  # watched once the call is a period old
    return dog, got


def test_a_watched_node_that_dies_is_reported_at_once_not_a_period_later(node, monkeypatch):
    from comm import liveness

    shift = {"s": 0.0}

    class _Time:  # the watchdog's clock, which the test moves on
        @staticmethod
        def monotonic():
            return time.monotonic() + shift["s"]

    monkeypatch.setattr(liveness, "time", _Time)
    dog, got = _watching(node, 0.1)
    try:
        dog.period = 600.0  # from now on, only a closed connection can wake the watchdog early
        shift["s"] = 1000.0  # and the call stays older than a period
        time.sleep(0.3)
        node.kill()
        until(lambda: got, timeout=20.0)
    finally:
        dog.stop()
    assert len(got) == 1 and isinstance(got[0], ModuleLost)
    assert got[0].call_ids == ["c1"] and "its process is gone" in got[0].reason


def test_a_watched_node_is_not_asked_again_while_its_connection_stays_open(node):
    dog, got = _watching(node, 0.05)
    try:
        asked = node.questions()
        time.sleep(0.5)  # ten periods
        assert node.questions() == asked == 1 and got == []
    finally:
        dog.stop()


def test_a_node_that_closes_every_connection_is_asked_every_period(tmp_path):
    node = StandIn(tmp_path, http10=True)
    node.start()
    try:
        dog, got = _watching(node, 0.05)
        try:
            until(lambda: node.questions() >= 6)
            assert got == []
        finally:
            dog.stop()
    finally:
        node.kill()
