"""The terminal view in a real terminal: tmux panes of 80x24 and 200x50 running ``bmtree watch``
(and ``bmtree run``), read back with ``capture-pane``."""
from __future__ import annotations

import os
import shlex
import subprocess
import sys
import time

import pytest

from tests.conftest import DATA
from tests.integration.watchkit import SimRun, slow_world

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
            assert "prepare" in shown and "(+8 folded)" in shown and "before 3" not in shown
        else:  # everything fits
            assert "before 8" in shown and "after 8" in shown and "folded" not in shown
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


def test_run_shows_the_same_view_on_a_terminal(tmp_path):
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    world = slow_world(tmp_path, speed=2.0)
    # the pane's shell prints the exit status: tmux shows "Pane is dead" only once it has reaped
    # the child, which it sometimes does long after the pane's output has ended
    command = "sh -c %s" % shlex.quote('%s; echo "[bmtree exited $?]"' % _cmd("run", "--sim", "--world", world, LONG))
    term = Tmux(tmp_path, "run", 80, 24, command, env)
    try:
        shown = term.wait_screen("bmtree watch long_errand", "navigation.go_to", "/ 30s", "pending calls")
        assert all(len(line) <= 80 for line in shown.split("\n"))
        term.wait_screen("[bmtree exited 0]", timeout=150)
        history = term.tmux("capture-pane", "-p", "-S", "-1000", "-t", term.name).stdout
        assert "long_errand: SUCCESS in" in history and "result: SUCCESS" in history
        assert "Traceback" not in history
    finally:
        term.close()
