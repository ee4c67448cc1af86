"""Processes that die under a run: the master during ``bmtree run``'s start-up, a run killed
outright (later runs, ``bmtree watch``), the Blackboard node mid-run.

Each test has a master of its own (``own_graph``): some kill it, and dead registrations must not
reach the other tests.
"""
from __future__ import annotations

import http.client
import http.server
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.parse
import xmlrpc.client

from tests.integration.conftest import bmtree_cmd
from tests.integration.faultkit import PROBE_CLASS, PROBE_JSON
from tests.integration.watchkit import Lines

QUICK = "format: 1\nroot:\n  call: probe.echo\n  inputs: {tag: hi}\n"
LONG = "format: 1\nroot:\n  call: probe.work\n  name: long work\n  inputs: {seconds: 120.0, tag: a}\n"


def _probe(graph):
    graph.start_node(["-m", "modules.node", "--definition", PROBE_JSON, "--class", PROBE_CLASS], "/bm_probe")


def _tree(tmp_path, text, name="t.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _run(env, tree, *extra):
    return subprocess.Popen(bmtree_cmd("run", tree, "--modules", PROBE_JSON, *extra), env=env, text=True,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


class VanishingMaster:
    """A front of the real master that vanishes (every connection closed, new ones refused, as a
    master killed with ``kill -9``) when a ``bmtree`` node asks it to register a topic: the run is
    then inside rospy's registration, which retries for as long as rospy is not shut down.
    ``come_back()`` answers again on the same port."""

    def __init__(self, master_uri):
        real = urllib.parse.urlsplit(master_uri)
        self.real = (real.hostname, real.port)
        self.vanished = threading.Event()
        self.armed = True  # vanishes once
        self._conns = set()
        self._lock = threading.Lock()
        self._server = None
        self.port = self._listen(0)
        self.uri = "http://127.0.0.1:%d/" % self.port

    def _listen(self, port):
        front = self

        class Handler(http.server.BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def setup(self):
                super().setup()
                with front._lock:
                    front._conns.add(self.connection)

            def log_message(self, *args):
                pass

            def do_POST(self):
                body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
                if front.vanished.is_set():
                    self.close_connection = True
                    return
                if front.armed and b"/bmtree_" in body and (b"<methodName>registerPublisher<" in body
                                            or b"<methodName>registerSubscriber<" in body):
                    front.vanish()
                    self.close_connection = True
                    return
                conn = http.client.HTTPConnection(*front.real, timeout=10)
                conn.request("POST", self.path, body, {"Content-Type": "text/xml"})
                answer = conn.getresponse().read()
                conn.close()
                self.send_response(200)
                self.send_header("Content-Type", "text/xml")
                self.send_header("Content-Length", str(len(answer)))
                self.end_headers()
                self.wfile.write(answer)

        class Server(http.server.ThreadingHTTPServer):
            allow_reuse_address = True
            daemon_threads = True

        self._server = Server(("127.0.0.1", port), Handler)
        threading.Thread(target=self._server.serve_forever, args=(0.05,), daemon=True).start()
        return self._server.server_address[1]

    def vanish(self):
        self.armed = False
        self.vanished.set()
        server, self._server = self._server, None
        if server is not None:
            threading.Thread(target=lambda: (server.shutdown(), server.server_close()), daemon=True).start()
        with self._lock:
            conns, self._conns = list(self._conns), set()
        for c in conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def come_back(self):
        end = time.monotonic() + 10
        while True:
            try:
                self.vanished.clear()
                self._listen(self.port)
                return
            except OSError:  # the old socket is still closing
                assert time.monotonic() < end
                time.sleep(0.1)

    def close(self):
        self.vanish()


def _front_env(graph, front):
    return dict(graph.env, ROS_MASTER_URI=front.uri)


def test_a_master_that_vanishes_during_start_up_ends_the_run_after_wait(own_graph, tmp_path):
    """Before: rospy retried the registration for ever ("Unable to register with master node …"),
    whatever --wait said; now: one line, exit 3, and the process ends (no thread keeps it)."""
    _probe(own_graph)
    front = VanishingMaster(own_graph.uri)
    try:
        run = _run(_front_env(own_graph, front), _tree(tmp_path, QUICK), "--wait", "2")
        try:
            out, _ = run.communicate(timeout=60)
        finally:
            run.kill()
        assert front.vanished.is_set()
        assert run.returncode == 3, out
        assert ("error: the ROS master at %s stopped answering during start-up" % front.uri) in out, out
        assert "nothing was called" in out and "Traceback" not in out
        assert "running t" not in out
    finally:
        front.close()


def test_a_master_back_within_wait_lets_the_start_up_go_on(own_graph, tmp_path):
    _probe(own_graph)
    front = VanishingMaster(own_graph.uri)
    try:
        run = _run(_front_env(own_graph, front), _tree(tmp_path, QUICK), "--wait", "60", "-q")
        try:
            out = Lines(run.stdout)
            out.wait_for("stopped answering during start-up; waiting up to 60 s (--wait)")
            front.come_back()
            out.wait_for("answers again; starting goes on")
            assert run.wait(60) == 0, out.text()
            assert "t: SUCCESS" in out.text()
        finally:
            run.kill()
    finally:
        front.close()


def test_ctrl_c_while_the_master_is_gone_during_start_up(own_graph, tmp_path):
    """The stop signal is held inside a registration; with no master to finish it, it ends the
    wait at once, and the message does not speak of calls that were never sent."""
    _probe(own_graph)
    front = VanishingMaster(own_graph.uri)
    try:
        run = _run(_front_env(own_graph, front), _tree(tmp_path, QUICK), "--wait", "600", "-q")
        try:
            out = Lines(run.stdout)
            out.wait_for("stopped answering during start-up")
            run.send_signal(signal.SIGINT)
            assert run.wait(60) == 3, out.text()
        finally:
            run.kill()
        out.wait_for("interrupted during start-up: nothing was called")
        assert "running calls were cancelled" not in out.text()
    finally:
        front.close()


def _killed_run(graph, tmp_path):
    """A ``bmtree run`` killed with ``kill -9`` while its call runs: it stays registered."""
    run = _run(graph.env, _tree(tmp_path, LONG, "long.yaml"))
    out = Lines(run.stdout)
    out.wait_for("RUNNING   long work")
    return run, out


SETTLE = """
import rospy
from coordinator.ros_transport import RosTransport
rospy.init_node("settle_probe", anonymous=True, disable_signals=True)
tr = RosTransport()
sink = tr.stream_sink()
print("settled" if sink.settle(timeout=20.0) else "gave up")
tr.close()
rospy.signal_shutdown("done")
"""


def test_settle_leaves_out_the_subscribers_of_a_run_killed_outright(own_graph, tmp_path):
    """Before: every later run waited the whole settle (3 s) for the dead run's subscriber of
    /bmtree/run/tree, which never connects; now it is not waited for."""
    _probe(own_graph)
    run, _ = _killed_run(own_graph, tmp_path)
    run.send_signal(signal.SIGKILL)  # the probe module then cancels its call (its caller is gone)
    run.wait(10)
    master = xmlrpc.client.ServerProxy(own_graph.uri)
    _, _, (_, subs, _) = master.getSystemState("/t")
    assert any(t == "/bmtree/run/tree" and any(n.startswith("/bmtree_") for n in ns) for t, ns in subs)
    out = subprocess.run([sys.executable, "-c", SETTLE], env=own_graph.env, capture_output=True, text=True,
                         timeout=120, cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.strip().splitlines()[-1] == "settled", out.stdout + out.stderr


def test_watch_ends_when_the_run_it_shows_is_killed(own_graph, tmp_path):
    """Before: the view showed "long work RUNNING" for ever; now it ends, the run marked unfinished, exit 3."""
    _probe(own_graph)
    run, _ = _killed_run(own_graph, tmp_path)
    watch = subprocess.Popen(bmtree_cmd("watch", "--plain", "--wait", "30"), env=own_graph.env, text=True,
                             stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        out = Lines(watch.stdout)
        out.wait_for("long work RUNNING")  # the caught-up line
        run.send_signal(signal.SIGKILL)
        run.wait(10)
        line = out.wait_for("end       UNFINISHED")
        assert "the run (pid %d, node /bmtree_" % run.pid in line, line
        assert "is gone, its last tick (" in line and "its process ended" in line
        assert watch.wait(60) == 3, out.text()
        assert "Traceback" not in out.text()
    finally:
        watch.kill()
        run.kill()


BB_TREE = """format: 1
root:
  sequence:
    - call: probe.work
      inputs: {seconds: 120.0, tag: a}
      name: first
    - call: probe.echo
      inputs: {tag: b}
"""


def test_the_blackboard_node_dying_mid_run_is_a_notice_and_so_is_its_return(own_graph, tmp_path):
    """Before: the run ended SUCCESS without a word while its results went unstored."""
    _probe(own_graph)
    db = str(tmp_path / "bb.sqlite")
    bb = own_graph.start_node(["-m", "blackboard.node", "--db", db], "/blackboard")
    log = tmp_path / "run.jsonl"
    run = _run(own_graph.env, _tree(tmp_path, BB_TREE, "bb.yaml"), "-q", "--record", str(log),
               "--call-timeout", "600")
    out = Lines(run.stdout)
    try:
        out.wait_for("running bb")
        time.sleep(1.0)  # the run watches the Blackboard node from its first tick
        bb.send_signal(signal.SIGKILL)
        bb.wait(10)
        down = out.wait_for("NOTICE    the Blackboard node /blackboard is gone: results from now on are not stored")
        assert "its process ended" in down
        own_graph.start_node(["-m", "blackboard.node", "--db", db], "/blackboard")
        out.wait_for("NOTICE    the Blackboard node /blackboard is back: results from now on are stored again")
        run.send_signal(signal.SIGINT)  # the run log ends properly
        assert run.wait(30) == 3, out.text()
    finally:
        run.kill()
    notices = [json.loads(line) for line in log.read_text().splitlines() if '"notice"' in line]
    assert [n["what"] for n in notices] == ["blackboard_down", "blackboard_back"], notices
