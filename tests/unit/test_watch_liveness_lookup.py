"""``bmtree watch``'s liveness lookup gives up on a master that accepts and never answers."""
from __future__ import annotations

import socket
import threading

import pytest

from coordinator.watchlive import RunLiveness


def test_the_watch_asks_a_silent_master_for_a_node_with_a_time_limit(monkeypatch):
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(8)  # the kernel accepts connections, nothing reads them: a SIGSTOPped master
    monkeypatch.setenv("ROS_MASTER_URI", "http://127.0.0.1:%d/" % silent.getsockname()[1])
    got = []

    def ask():
        try:
            got.append(RunLiveness._uri_of("/bmtree_run"))
        except OSError as exc:
            got.append(exc)

    t = threading.Thread(target=ask, daemon=True)
    t.start()
    t.join(15.0)
    silent.close()
    assert not t.is_alive(), "the lookup still waits for the master"
    with pytest.raises(OSError):
        raise got[0]
