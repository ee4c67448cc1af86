"""A machine that cannot be reached says nothing of its processes: a Wi-Fi link that dropped for a few
seconds made the run call a live module lost ("its process is gone"), the Blackboard node gone ("results
from now on are not stored") and a live run dead (``bmtree watch``). Only a refusal or a reset from the
peer's machine says its process ended; no route, or no answer, is the network."""
from __future__ import annotations

import errno
import http.client
import socket

import pytest

from comm.liveness import Watchdog
from comm.rpc import PidLine


def _connect_fails(monkeypatch, code):
    def connect(self):
        raise OSError(code, "simulated: %s" % errno.errorcode[code])
    monkeypatch.setattr(http.client.HTTPConnection, "connect", connect)


@pytest.mark.parametrize("code", [errno.EHOSTUNREACH, errno.ENETUNREACH, errno.ETIMEDOUT, errno.EHOSTDOWN,
                                  errno.ENETDOWN])
def test_an_unreachable_machine_is_no_answer(monkeypatch, code):
    _connect_fails(monkeypatch, code)
    assert PidLine("http://10.200.0.2:40000/", 0.5).ask() is None


@pytest.mark.parametrize("code", [errno.ECONNREFUSED, errno.ECONNRESET])
def test_a_refusal_from_its_machine_is_a_process_gone(monkeypatch, code):
    _connect_fails(monkeypatch, code)
    with pytest.raises(OSError):
        PidLine("http://10.200.0.2:40000/", 0.5).ask()


def test_a_closed_port_on_this_machine_is_refused():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    with pytest.raises(OSError):
        PidLine("http://127.0.0.1:%d/" % port, 0.5).ask()


def test_a_call_to_an_unreachable_module_is_left_to_its_timeout(monkeypatch):
    """The watchdog does not report a module whose node's machine does not answer: the call waits (the link
    may come back, and the call with it), bounded by its own timeout."""
    _connect_fails(monkeypatch, errno.EHOSTUNREACH)
    lost = []
    dog = Watchdog(lost.append, lambda module: "/bm_navigation", lambda node: "http://10.200.0.2:40000/",
                   period=0.0)
    dog.call_sent("c1", "navigation")
    dog.check()
    dog.check()
    assert lost == []
    _connect_fails(monkeypatch, errno.ECONNREFUSED)   # its machine answers: the process is gone
    dog.check()
    assert [(m.module, m.reason, m.call_ids) for m in lost] == [
        ("navigation", "node /bm_navigation stopped (its process is gone)", ["c1"])]
