"""On a terminal, the tree's drawing keeps py_trees' colours while a module's text in it stays escaped:
escaping the whole drawing after it was drawn showed ``\\x1b[1m{o}\\x1b[0m … [\\x1b[32m✓\\x1b[0m]`` in
``bmtree replay`` and ``bmtree run`` on every terminal. Run in a real pseudo-terminal."""
from __future__ import annotations

import os
import pty
import subprocess
import sys

from coordinator.testing.mocks import fail
from tests.conftest import ROOT, TREES
from tests.unit.test_recording import recorded


def _on_a_terminal(*args: str) -> str:
    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, *args], stdin=subprocess.DEVNULL, stdout=slave, stderr=slave,
                            cwd=ROOT, env=dict(os.environ, TERM="xterm", COLUMNS="200"))
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:   # EIO: the other side closed
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    assert proc.wait(timeout=60) == 0, b"".join(chunks).decode(errors="replace")
    return b"".join(chunks).decode(errors="replace")


def test_replay_on_a_terminal_draws_in_colour(sim_defs, tmp_path):
    log_path, _ = recorded(os.path.join(TREES, "find_apple.yaml"), sim_defs, tmp_path,
                           lambda m: m["vision.find_object"].script(fail("camera gone")))
    shown = _on_a_terminal("-m", "coordinator", "replay", log_path, "--at", "0.0")
    assert "\x1b[1m{o}\x1b[0m" in shown and "\x1b[31m" in shown, shown   # py_trees' bold root, red cross
    assert "\\x1b[" not in shown, shown                                 # none shown as text


def test_a_modules_text_in_the_drawing_is_escaped_and_its_colours_are_not():
    """What a node shows of a module (its feedback: a call's error) cannot drive the terminal."""
    code = (
        "import py_trees\n"
        "from coordinator.runevents import TerminalText, tree_drawing\n"
        "import sys\n"
        "leaf = py_trees.behaviours.Failure(name='look')\n"
        "root = py_trees.composites.Sequence('root', memory=True, children=[leaf])\n"
        "root.tick_once()\n"
        "leaf.feedback_message = 'camera\\x1b[2J gone'\n"
        "TerminalText(sys.stdout).write_drawing(tree_drawing(root) + '\\n')\n")
    shown = _on_a_terminal("-c", code)
    assert "camera\\x1b[2J gone" in shown and "\x1b[2J" not in shown, shown
    assert "\x1b[31m" in shown, shown   # the failure's red cross, as colour
