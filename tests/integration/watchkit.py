"""Helpers of the watch tests: a ``bmtree run --sim`` in the background on a slow world,
its output read as it comes, and the environment that reaches its private master."""
from __future__ import annotations

import os
import subprocess
import threading
import time

import yaml

from tests.conftest import DATA
from tests.integration.conftest import bmtree_cmd

GO = os.path.join(DATA, "watch", "go_kitchen.yaml")


def slow_world(tmp_path, speed=0.8, **changes):
    from modules.sim import DEFAULT_WORLD

    with open(DEFAULT_WORLD) as fh:
        data = yaml.safe_load(fh)
    data["speed"] = speed
    data.update(changes)
    path = tmp_path / ("world_%s.yaml" % speed)
    path.write_text(yaml.safe_dump(data))
    return str(path)


class Lines:
    """A process's output lines, read in a thread; ``wait_for`` blocks until one contains a text."""

    def __init__(self, stream):
        self.lines = []
        self.cond = threading.Condition()
        self.done = False
        threading.Thread(target=self._read, args=(stream,), daemon=True).start()

    def _read(self, stream):
        for line in stream:
            with self.cond:
                self.lines.append(line.rstrip("\n"))
                self.cond.notify_all()
        with self.cond:
            self.done = True
            self.cond.notify_all()

    def wait_for(self, text, timeout=90.0):
        end = time.monotonic() + timeout
        with self.cond:
            while True:
                for line in self.lines:
                    if text in line:
                        return line
                left = end - time.monotonic()
                if left <= 0 or self.done:
                    raise AssertionError("%r not in output:\n%s" % (text, "\n".join(self.lines)))
                self.cond.wait(min(left, 1.0))

    def text(self):
        with self.cond:
            return "\n".join(self.lines)

    def all_text(self, timeout=30.0):
        """Everything the process wrote, once its output has ended (it has exited)."""
        end = time.monotonic() + timeout
        with self.cond:
            while not self.done and time.monotonic() < end:
                self.cond.wait(min(1.0, max(0.0, end - time.monotonic())))
            assert self.done, "the output has not ended:\n" + "\n".join(self.lines)
            return "\n".join(self.lines)


class SimRun:
    """``bmtree run --sim`` of ``tree`` in the background; ``env`` reaches its master once up."""

    def __init__(self, tmp_path, tree=GO, world=None, extra=()):
        self.home = str(tmp_path / "home")
        base = dict(os.environ, ROS_HOME=self.home, PYTHONUNBUFFERED="1")
        base.pop("ROS_HOSTNAME", None)
        self.proc = subprocess.Popen(bmtree_cmd("run", "--sim", "--world", world or slow_world(tmp_path), *extra, tree),
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                     text=True, env=base)
        self.out = Lines(self.proc.stdout)
        uri = self.out.wait_for("simulated robot up, master at ").rsplit(" ", 1)[1]
        self.env = dict(base, ROS_MASTER_URI=uri, ROS_IP="127.0.0.1")

    def finish(self, timeout=120.0):
        try:
            return self.proc.wait(timeout)
        finally:
            self.close()

    def close(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


LONG_TREE = os.path.join(DATA, "watch", "long_errand.yaml")

ASK = """\
# announce, then a selector whose first child fails at once and whose second drives: py_trees
# resets the failed child a tick later, while the second one runs
format: 1
name: ask_around
root:
  sequence:
    name: find the apple
    children:
      - call: speech.say
        name: announce
        inputs: {text: "Looking for it."}
      - selector:
          name: find it
          children:
            - call: vision.find_object
              name: look for it
              inputs: {object: unicorn}
            - call: navigation.go_to
              name: ask a person
              inputs: {place: kitchen}
              timeout: 60
"""


def ask_tree(tmp_path):
    path = tmp_path / "ask_around.yaml"
    path.write_text(ASK)
    return str(path)
