"""A master that does not answer at all: its machine dropped off the network (packets silently
dropped) or its process stopped. A SIGSTOPped rosmaster behaves the same way for its clients:
the kernel still accepts their connections, and nothing ever answers.

rospy and rosgraph ask the master with no timeout: ``bmtree run`` sat in its start-up for
minutes whatever ``--wait`` said, a run that had printed its result waited in its unregistering
until the master came back, ``bmtree watch`` the same, and Ctrl-C and SIGTERM did nothing.
Every bound here is against a hang, not a measure of speed.

Each test has a master of its own (``own_graph``), continued (SIGCONT) whatever happens.
"""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time

from tests.integration.conftest import bmtree_cmd
from tests.integration.watchkit import Lines

WAIT = "format: 1\nroot:\n  wait: %g\n"


def _tree(tmp_path, seconds, name="wait.yaml"):
    path = tmp_path / name
    path.write_text(WAIT % seconds)
    return str(path)


def _start(graph, *args):
    proc = subprocess.Popen(bmtree_cmd(*args), env=graph.env, text=True, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    return proc, Lines(proc.stdout)


@contextlib.contextmanager
def _stopped(graph):
    """The master stopped (SIGSTOP) inside the block, continued whatever happens."""
    os.kill(graph.master.pid, signal.SIGSTOP)
    try:
        yield
    finally:
        os.kill(graph.master.pid, signal.SIGCONT)


def _ends(proc, out, bound):
    """The exit code of ``proc`` if it ends within ``bound`` seconds; else it is killed (a hang)."""
    try:
        return proc.wait(bound)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(5)
        raise AssertionError("still running %g s on, with the master stopped:\n%s" % (bound, out.all_text()))


def _finish(*procs):
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)


def test_run_waits_for_a_master_that_does_not_answer_no_longer_than_wait(own_graph, tmp_path):
    """``--wait`` bounds the wait for the master: each question to it is bounded too."""
    with _stopped(own_graph):
        run, out = _start(own_graph, "run", "--wait", "3", "-q", _tree(tmp_path, 0.1))
        try:
            code = _ends(run, out, 3 + 10)
        finally:
            _finish(run)
    text = out.all_text()
    assert code == 3, text
    assert "error: no ROS master at %s after 3 s" % own_graph.uri in text, text


def test_a_run_whose_master_stops_prints_its_result_and_leaves_without_unregistering(own_graph, tmp_path):
    run, out = _start(own_graph, "run", "--wait", "10", _tree(tmp_path, 3))
    try:
        out.wait_for("RUNNING   wait", 30)  # the first tick: start-up is over
        with _stopped(own_graph):
            code = _ends(run, out, 3 + 15)
    finally:
        _finish(run)
    text = out.all_text()
    assert code == 0 and "wait: SUCCESS in" in text, text
    assert ("the ROS master at %s does not answer: leaving without unregistering" % own_graph.uri) in text, text
    assert "Traceback" not in text, text


def test_a_stop_signal_ends_a_run_while_its_master_does_not_answer(own_graph, tmp_path):
    """SIGINT in the middle of the tree, and at start-up while the master is waited for: each
    ends the run (exit 3), the first within a bounded leave, a second one at once."""
    run, out = _start(own_graph, "run", "--wait", "10", _tree(tmp_path, 120))
    early = None
    try:
        out.wait_for("RUNNING   wait", 30)
        with _stopped(own_graph):
            early, early_out = _start(own_graph, "run", "--wait", "60", "-q", _tree(tmp_path, 0.1, "early.yaml"))
            early_out.wait_for("waiting up to 60 s (--wait)", 30)
            run.send_signal(signal.SIGINT)
            early.send_signal(signal.SIGINT)
            code = _ends(run, out, 15)
            early_code = _ends(early, early_out, 15)
        again, again_out = _start(own_graph, "run", "--wait", "10", _tree(tmp_path, 120, "again.yaml"))
        try:
            again_out.wait_for("RUNNING   wait", 30)
            with _stopped(own_graph):
                again.send_signal(signal.SIGTERM)
                again_out.wait_for("interrupted", 15)
                time.sleep(0.5)  # a second stop, not one of the same burst
                again.send_signal(signal.SIGINT)
                again_code = _ends(again, again_out, 15)
        finally:
            _finish(again)
    finally:
        _finish(*[p for p in (run, early) if p is not None])
    text = out.all_text()
    assert code == 3 and "interrupted before any call was sent" in text, text
    assert "leaving without unregistering" in text, text
    early_text = early_out.all_text()
    assert early_code == 3 and "interrupted during start-up: nothing was called" in early_text, early_text
    again_text = again_out.all_text()
    assert again_code == 3 and "leaving without unregistering" in again_text, again_text


def test_watch_ends_after_its_run_while_the_master_does_not_answer(own_graph, tmp_path):
    watch, watch_out = _start(own_graph, "watch", "--plain", "--wait", "30")
    run = None
    try:
        time.sleep(1.0)  # subscribed before the run starts (else the run's stream settles on it)
        run, out = _start(own_graph, "run", "--wait", "10", _tree(tmp_path, 4))
        out.wait_for("RUNNING   wait", 30)
        watch_out.wait_for("RUNNING", 30)
        with _stopped(own_graph):
            code = _ends(run, out, 4 + 15)
            watch_code = _ends(watch, watch_out, 15)
    finally:
        _finish(*[p for p in (watch, run) if p is not None])
    text, watch_text = out.all_text(), watch_out.all_text()
    assert code == 0 and "SUCCESS" in text, text
    assert watch_code == 0 and "end       SUCCESS" in watch_text, watch_text
    assert "does not answer: leaving without unregistering" in watch_text, watch_text
