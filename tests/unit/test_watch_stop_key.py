"""The watch's side of ``stop`` and of a refused shared name: ``:stop`` sends the command to the run
shown, the help names it, and a long answer (the candidates of a shared name) wraps in the footer
instead of being cut at the width (no ROS)."""
from __future__ import annotations

import os
import threading

from coordinator.watchstate import WatchState
from coordinator.watchterm import KEYS_HELP, Keys, LiveView
from coordinator.watchview import render
from tests.unit.test_watch_operator import lines_of, tree

WEB = os.path.join(os.path.dirname(__file__), "..", "..", "coordinator", "web")


class Client:
    def __init__(self, reply):
        self.sent, self.reply, self.done = [], reply, threading.Event()

    def send(self, cmd, timeout):
        self.sent.append(cmd)
        self.done.set()
        return self.reply


def _type(keys, text):
    for ch in text:
        keys.press(ch)


def test_colon_stop_sends_stop_to_the_run_shown():
    s = WatchState()
    s.apply(tree(control=True))
    view = LiveView(s)
    client = Client({"ok": True, "answer": "stopping: the running nodes are halted and their calls cancelled"})
    keys = Keys(view, client, threading.Event(), to=lambda: "/bmtree_1_2")
    _type(keys, ":stop\n")
    assert client.done.wait(5)
    assert client.sent == [{"command": "stop", "to": "/bmtree_1_2"}]
    assert "stop," in KEYS_HELP


def test_a_long_refusal_wraps_in_the_footer_and_the_help_stays_one_line():
    s = WatchState()
    s.apply(tree())
    refusal = ("refused: 2 nodes are named 'speech.say': speech.say@3 (go.yaml:7, in go > sequence), speech.say@5 "
               "(go.yaml:11, in go > cleanup); say which one by its id (force speech.say@3 SUCCESS), or give them "
               "names of their own (name: in the tree)")
    lines = lines_of(render(s, 80, 24, refusal, footer_wrap=True))
    assert len(lines) <= 24 and all(len(line) <= 80 for line in lines), lines
    start = next(k for k, line in enumerate(lines) if line.startswith("refused: 2 nodes"))
    assert "(name: in the tree)" in " ".join(" ".join(lines[start:]).split()), lines   # before: cut at 80 columns
    assert lines_of(render(s, 80, 24, KEYS_HELP))[-1].startswith("q quit  p pause/resume")   # the help is not wrapped
    view = LiveView(s)
    view.answered(refusal)
    view.console.width = 80
    assert "(name: in the tree)" in " ".join(" ".join(lines_of(view._frame([]))).split())


def test_the_page_has_a_stop_button_and_names_shared_nodes_by_id():
    with open(os.path.join(WEB, "index.html")) as fh:
        assert '<button id="stop"' in fh.read()
    with open(os.path.join(WEB, "app.js")) as fh:
        app = fh.read()
    assert 'control({ command: "stop" })' in app and 'n.name + "@" + n.id' in app
