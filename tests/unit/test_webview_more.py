"""The web view's server (no browser, no ROS master): a page closed mid long-poll is no error, a
live run's end is served on for a page opened late, and a replay knows a killed run's length and
the failure that ended a run."""
from __future__ import annotations

import io
import json
import os
import socket
import struct
import threading
import time
import urllib.request

import pytest

from coordinator.runlog import read_log
from coordinator.watchstate import WatchState
from coordinator.webview import WebServer, replay_meta, replay_states
from tests.conftest import TREES
from tests.unit.test_recording import recorded

FIND_APPLE = os.path.join(TREES, "find_apple.yaml")
TREE = {"v": 1, "type": "tree", "run": "r1", "t": 0.0, "started": 1.7e9, "name": "demo",
        "nodes": [{"id": 0, "name": "root", "parent": None, "kind": "sequence"}]}


def _state(*records):
    state = WatchState()
    for rec in (TREE,) + records:
        state.apply(rec)
    return state


def _get(server, path, timeout=10.0):
    with urllib.request.urlopen(server.url + path, timeout=timeout) as answer:
        return json.loads(answer.read().decode("utf-8"))


def _hang_up_mid_poll(server, since):
    """A long poll whose page goes away before the answer (a closed tab): the connection is reset."""
    sock = socket.create_connection(("127.0.0.1", int(server.url.rsplit(":", 1)[1].strip("/"))))
    sock.sendall(b"GET /state?since=%d HTTP/1.1\r\nHost: x\r\n\r\n" % since)
    time.sleep(0.1)  # the handler is waiting for a change
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    sock.close()  # a reset, as a browser closing the tab


def test_a_page_closed_during_a_long_poll_prints_nothing(capfd):
    state = _state()
    server = WebServer(state)
    try:
        for n in range(3):
            _hang_up_mid_poll(server, state.version)
            state.apply({"v": 1, "type": "write", "run": "r1", "t": 0.1 * n, "key": "k", "value": n})  # the answer
        time.sleep(1.0)  # the handlers have answered the pages that went away
        assert _get(server, "state?since=-1")["tree"]["name"] == "demo"  # it serves on
    finally:
        server.close()
    err = capfd.readouterr().err
    assert "Traceback" not in err and "BrokenPipe" not in err and "ConnectionReset" not in err, err


def test_a_page_closed_during_any_answer_is_quiet_too(capfd):
    """The page itself (a large file) to a client that resets at once: nothing on the terminal."""
    server = WebServer(_state())
    try:
        port = int(server.url.rsplit(":", 1)[1].strip("/"))
        for _ in range(5):
            sock = socket.create_connection(("127.0.0.1", port))
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            sock.sendall(b"GET /app.js HTTP/1.1\r\nHost: x\r\n\r\n")
            sock.close()
        time.sleep(0.5)
    finally:
        server.close()
    assert "Traceback" not in capfd.readouterr().err


END = {"v": 1, "type": "end", "run": "r1", "t": 2.0, "status": "FAILURE", "reason": "root: no", "ticks": 3,
       "duration": 2.0, "calls": 0}


def test_an_end_no_page_was_sent_is_served_on_until_a_page_gets_it():
    """``watch --web`` closes its server 5 s after the run's end; a page opened later still gets the
    end: close() serves on until a page has been sent it (and a second more for the others)."""
    out = io.StringIO()
    server = WebServer(_state(END), linger=60.0, out=out)
    closed = threading.Event()
    threading.Thread(target=lambda: (server.close(), closed.set()), daemon=True).start()
    assert not closed.wait(1.5)  # no page yet: still serving
    assert "no page has shown the end yet" in out.getvalue() and "up to 60 s (Ctrl-C ends)" in out.getvalue()
    assert _get(server, "state?since=-1")["end"]["status"] == "FAILURE"  # the page opened late
    start = time.monotonic()
    assert closed.wait(5.0)
    assert 0.8 <= time.monotonic() - start < 3.0


def test_an_end_a_page_got_or_a_stop_signal_ends_at_once(monkeypatch):
    server = WebServer(_state(END), linger=60.0, out=io.StringIO())
    assert _get(server, "state?since=-1")["end"]["status"] == "FAILURE"
    start = time.monotonic()
    server.close()  # a page has the end: nothing to wait for
    assert time.monotonic() - start < 1.0

    import comm.nodelife

    server = WebServer(_state(END), linger=60.0, out=io.StringIO())
    monkeypatch.setattr(comm.nodelife, "_installed", type("Stopped", (), {"requested": True})())
    start = time.monotonic()
    server.close()  # Ctrl-C
    assert time.monotonic() - start < 1.0


def test_a_run_still_going_or_a_linger_of_zero_closes_at_once():
    for server in (WebServer(_state(), linger=60.0), WebServer(_state(END))):
        start = time.monotonic()
        server.close()
        assert time.monotonic() - start < 1.0


# replay ------------------------------------------------------------------------------------------------
def _camera_down(sim_defs, tmp_path):
    from coordinator.testing.mocks import succeed

    def script(m):
        m["navigation.go_to"].script(succeed(delay=2.0))
        m["vision.find_object"].fail("camera driver not responding")
    return recorded(FIND_APPLE, sim_defs, tmp_path, script)[0]


def _killed(log_path, tmp_path, alive=5.0, keep=8):
    """The log of ``log_path`` cut after ``keep`` records, as if the run was killed, its file last
    touched ``alive`` s after the start (the writer's heartbeat)."""
    lines = open(log_path).read().splitlines()[:keep]
    path = tmp_path / "killed.jsonl"
    path.write_text("\n".join(lines) + "\n")
    started = json.loads(lines[0])["started"]
    os.utime(str(path), (started + alive, started + alive))
    return str(path)


def _replay_server(path):
    log = read_log(path)
    meta = replay_meta(log)
    return WebServer(None, at=replay_states(list(log.records), meta["duration"]), duration=meta["duration"],
                     replay=meta)


def test_a_killed_runs_replay_lasts_until_it_was_last_seen_and_ends_unfinished(sim_defs, tmp_path):
    path = _killed(_camera_down(sim_defs, tmp_path), tmp_path, alive=5.0)
    last_record = json.loads(open(path).read().splitlines()[-1])["t"]
    assert last_record < 1.0
    server = _replay_server(path)
    try:
        whole = _get(server, "state")
        assert whole["duration"] == pytest.approx(5.0, abs=0.01) and whole["at"] == pytest.approx(5.0, abs=0.01)
        assert whole["t"] == pytest.approx(5.0, abs=0.01)  # not its last record's 0.00s
        assert whole["end"]["status"] == "UNFINISHED"
        assert "last seen alive at 5.00s" in whole["end"]["reason"] and "killed" in whole["end"]["reason"]
        assert whole["replay"]["unfinished"] and whole["replay"]["last_alive"] == pytest.approx(5.0, abs=0.01)
        assert whole["replay"]["failure"] is None
        assert _get(server, "state?at=end")["end"]["status"] == "UNFINISHED"
        before = _get(server, "state?at=%f" % (last_record / 2))
        assert before["end"] is None and before["t"] == pytest.approx(last_record / 2)
    finally:
        server.close()


def test_a_failed_runs_replay_knows_the_failure_that_ended_it(sim_defs, tmp_path):
    server = _replay_server(_camera_down(sim_defs, tmp_path))
    try:
        whole = _get(server, "state?at=end")
        assert whole["end"]["status"] == "FAILURE" and not whole["replay"]["unfinished"]
        failure = whole["replay"]["failure"]
        assert failure["name"] == "look for the object"
        assert failure["message"] == "vision.find_object failed: camera driver not responding"
        assert 0 < failure["t"] <= whole["duration"]
        then = _get(server, "state?at=%r" % failure["t"])  # the jump: the tick where it failed
        assert then["status"].get(str(failure["node"])) == "FAILURE" or then["last"].get(str(failure["node"])) == "FAILURE"
        assert then["feedback"][str(failure["node"])] == failure["message"]
        # the slider's last step (its max rounded up to 0.01 s) shows the end, whose record comes after the duration
        assert _get(server, "state?at=%.2f" % (whole["duration"] + 0.005))["end"]["status"] == "FAILURE"
    finally:
        server.close()


def test_a_taken_port_says_which_and_how_to_get_a_free_one():
    """A second ``watch --web`` on one host said only ``[Errno 98] Address already in use``."""
    first = WebServer(WatchState(), "127.0.0.1", 0, out=io.StringIO())
    try:
        port = first.httpd.server_address[1]
        with pytest.raises(OSError) as caught:
            WebServer(WatchState(), "127.0.0.1", port, out=io.StringIO())
        assert str(caught.value) == ("port %d on 127.0.0.1 is taken (another bmtree watch --web or replay --web?): "
                                     "give --port 0 for any free port, or another --port" % port)
    finally:
        first.close()
