"""The terminal view in a real terminal: tmux panes of 80x24 and 200x50 running ``bmtree watch``
(and ``bmtree run``), read back with ``capture-pane``."""
from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
import time

import pytest

from tests.conftest import DATA
from tests.integration.watchkit import SimRun, ask_tree, slow_world

LONG = os.path.join(DATA, "watch", "long_errand.yaml")
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


class Tmux:
    """A private tmux server (its own socket) with one session; killed at the end."""

    def __init__(self, tmp_path, name, width, height, command, env):
        self.sock = "bmtree-test-%d-%s" % (os.getpid(), name)
        self.env = dict(env, TERM="xterm-256color")
        for name in ("TMUX", "COLUMNS", "LINES"):  # pytest-xdist's workers set COLUMNS=80, LINES=24
            self.env.pop(name, None)
        self.tmux("new-session", "-d", "-s", name, "-x", str(width), "-y", str(height), command)
        self.tmux("set-option", "-t", name, "remain-on-exit", "on")
        self.name = name

    def tmux(self, *args):
        return subprocess.run(["tmux", "-L", self.sock, *args], capture_output=True, text=True, env=self.env,
                              timeout=30, cwd=ROOT)

    def screen(self):
        return self.tmux("capture-pane", "-p", "-t", self.name).stdout

    def wait_screen(self, *texts, timeout=90.0):
        end = time.monotonic() + timeout
        while True:
            shown = self.screen()
            if all(t in shown for t in texts):
                return shown
            if time.monotonic() >= end:
                raise AssertionError("%r not all on screen:\n%s" % (texts, shown))
            time.sleep(0.2)  # polling the pane: the screen has no event to wait on

    def close(self):
        self.tmux("kill-server")


def _cmd(*args):
    return " ".join(shlex.quote(a) for a in [sys.executable, "-m", "coordinator", *args])


@pytest.mark.parametrize("width,height", [(80, 24), (200, 50)])
def test_watch_in_a_real_terminal(tmp_path, width, height):
    run = SimRun(tmp_path, tree=LONG, world=slow_world(tmp_path, speed=0.6))
    term = None
    try:
        run.out.wait_for("RUNNING   go to the kitchen")
        term = Tmux(tmp_path, "w%d" % width, width, height, _cmd("watch", "--wait", "60"), run.env)
        shown = term.wait_screen("go to the kitchen", "navigation.go_to", "/ 30s")
        lines = shown.rstrip("\n").split("\n")
        assert len(lines) <= height and all(len(line) <= width for line in lines), shown
        assert "bmtree watch long_errand" in lines[0]
        running = next(line for line in lines if "go to the kitchen" in line and "RUNNING" in line)
        assert running.lstrip().startswith("*")
        assert "pending calls" in shown and "tree blackboard" in shown and "call log" in shown
        if height == 24:  # the finished and the untouched branches fold to one line each
            assert "prepare" in shown and "(+8 folded)" in shown and "before 3" not in shown.split("pending calls")[0]
        else:  # everything fits, the panels too: the lines the tree does not use are theirs
            assert "before 8" in shown and "after 8" in shown and "folded" not in shown
            assert not re.search(r"\(\d+ of \d+", shown), shown
        # redrawn in place: the screen follows the run to its end, nothing is left in the scrollback
        shown = term.wait_screen("SUCCESS in", timeout=120)
        history = term.tmux("capture-pane", "-p", "-S", "-1000", "-t", term.name).stdout
        assert history.count("bmtree watch long_errand") == 1, history
        assert "result: SUCCESS" in shown
        assert run.finish() == 0, run.out.text()
    finally:
        if term is not None:
            term.close()
        run.close()


def _clock(shown):
    """The header's run time and the pending navigation call's elapsed time on a screen (or None)."""
    head = re.search(r"  t=(\d+\.\d)s  tick (\d+)", shown.split("\n")[0])
    call = re.search(r"navigation\.go_to +(\d+\.\d)s / 30s", shown)
    return (float(head.group(1)), float(call.group(1))) if head and call else None


def test_run_shows_the_same_view_on_a_terminal(tmp_path):
    """... titled ``bmtree run TREE``, its clock moving on while a call runs (no record comes then)."""
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    world = slow_world(tmp_path, speed=1.0)
    # the pane's shell prints the exit status: tmux shows "Pane is dead" only once it has reaped
    # the child, which it sometimes does long after the pane's output has ended
    command = "sh -c %s" % shlex.quote('%s; echo "[bmtree exited $?]"' % _cmd("run", "--sim", "--world", world, LONG))
    term = Tmux(tmp_path, "run", 80, 24, command, env)
    try:
        shown = term.wait_screen("bmtree run long_errand", "navigation.go_to", "/ 30s", "pending calls")
        assert all(len(line) <= 80 for line in shown.split("\n"))
        first = _clock(shown)
        time.sleep(1.5)
        later = _clock(term.screen())
        assert first and later, term.screen()
        # the header's clock moved on as the call's elapsed time did (redrawn every 0.2 s)
        assert later[0] - first[0] >= 1.0 and abs((later[0] - first[0]) - (later[1] - first[1])) < 0.5, (first, later)
        term.wait_screen("[bmtree exited 0]", timeout=150)
        history = term.tmux("capture-pane", "-p", "-S", "-1000", "-t", term.name).stdout
        assert "long_errand: SUCCESS in" in history and "result: SUCCESS" in history
        assert "Traceback" not in history
    finally:
        term.close()


def test_a_reset_node_keeps_its_last_outcome_and_ctrl_c_after_the_run_is_quiet(tmp_path):
    """A selector's failed child, reset by py_trees a tick later, shows ``was FAILURE`` (not ``-``,
    never ticked) while the next child runs; an interrupted run's finished nodes ``was SUCCESS``.
    Then Ctrl-C of a ``--follow`` watch whose ``--sim`` master is gone ends it without warnings."""
    run = SimRun(tmp_path, tree=ask_tree(tmp_path), world=slow_world(tmp_path, speed=0.5))
    term = None
    try:
        run.out.wait_for("RUNNING   ask a person")
        # the pane's shell outlives the Ctrl-C (a trap) to print the watch's exit status
        command = "sh -c %s" % shlex.quote('trap : INT; %s; echo "[watch exited $?]"' % _cmd(
            "watch", "--follow", "--wait", "60"))
        term = Tmux(tmp_path, "was", 100, 24, command, run.env)
        shown = term.wait_screen("ask a person  RUNNING", "look for it  was FAILURE")
        assert "x look for it  was FAILURE" in shown and "+ announce  SUCCESS" in shown
        run.proc.send_signal(signal.SIGINT)  # Ctrl-C: the run stops its tree, and its master
        assert run.finish() == 3, run.out.text()
        shown = term.wait_screen("announce  was SUCCESS", "ask a person  HALTED", "look for it  was FAILURE")
        term.tmux("send-keys", "-t", term.name, "C-c")
        term.wait_screen("[watch exited 0]", timeout=60)
        history = term.tmux("capture-pane", "-p", "-S", "-1000", "-t", term.name).stdout
        assert "out of sync" not in history and "[WARN]" not in history and "Traceback" not in history, history
    finally:
        if term is not None:
            term.close()
        run.close()
