"""The watch's footer and the page's controls offer steering only while the run shown takes commands
(its ``tree`` record said so, it has not ended); a key pressed meanwhile says why, locally, and sends
nothing; the run's answer to a key is shown a few seconds, and not over another run (no ROS)."""
from __future__ import annotations

import json
import threading
import urllib.request

import coordinator.watchterm as watchterm
from coordinator.watchstate import WatchState
from coordinator.watchterm import (
    ENDED_HELP,
    KEYS_HELP,
    NO_CONTROL_HELP,
    WAITING_HELP,
    Keys,
    LiveView,
    keys_help,
)
from coordinator.webview import WebServer
from tests.unit.test_watch_operator import lines_of, tree


class Client:
    def __init__(self, reply=None):
        self.sent, self.done = [], threading.Event()
        self.reply = reply or {"ok": True, "answer": "paused: no node starts; pending calls go on and their "
                                                     "timeouts keep counting"}

    def send(self, cmd, timeout):
        self.sent.append(cmd)
        self.done.set()
        return self.reply


def _view(state):
    view = LiveView(state, footer=keys_help)
    return view, Keys(view, client := Client(), threading.Event(), to=lambda: "/bmtree_1_2"), client


def test_while_waiting_for_a_run_no_steering_key_is_offered_and_a_key_says_why():
    s = WatchState()
    view, keys, client = _view(s)
    assert view.foot() == WAITING_HELP and "p pause" not in view.foot()
    for ch in "ps:":
        keys.press(ch)
        assert view.foot().startswith("'%s' not sent: no run is shown yet" % ch), view.foot()
    assert keys.line is None and client.sent == []   # nothing was sent, no command line opened
    view.console.width = 80
    shown = " ".join(" ".join(lines_of(view._frame([]))[-3:]).split())  # (wrapped in the footer)
    assert "':' not sent: no run is shown yet: the keys steer a run started with --control once one is shown" in shown


def test_a_run_without_control_and_an_ended_one_offer_no_keys_and_send_nothing():
    s = WatchState()
    s.apply(tree(control=False))
    view, keys, client = _view(s)
    assert view.foot() == NO_CONTROL_HELP
    keys.press("p")
    assert view.foot() == "'p' not sent: this run takes no commands: it was started without --control"
    ended = WatchState()
    ended.apply(tree(control=True))
    ended.apply({"type": "end", "run": "r1", "t": 1.0, "status": "SUCCESS", "ticks": 0, "duration": 1.0})
    view, keys, client2 = _view(ended)
    assert view.foot() == ENDED_HELP
    keys.press("s")
    assert "not sent: the run has ended" in view.foot()
    assert client.sent == client2.sent == []


def test_a_command_typed_while_the_run_ends_is_not_sent():
    s = WatchState()
    s.apply(tree(control=True))
    view, keys, client = _view(s)
    assert view.foot() == KEYS_HELP
    for ch in ":paus":
        keys.press(ch)
    assert view.foot() == ":paus"
    s.apply({"type": "end", "run": "r1", "t": 1.0, "status": "SUCCESS", "ticks": 0, "duration": 1.0})
    for ch in "e\n":
        keys.press(ch)
    assert client.sent == [] and view.foot() == "not sent: the run has ended: it takes no more commands"


def test_an_answer_is_shown_a_few_seconds_then_the_help_and_never_over_another_run(monkeypatch):
    clock = [1000.0]
    monkeypatch.setattr(watchterm.time, "monotonic", lambda: clock[0])
    s = WatchState()
    s.apply(tree(control=True))
    view, keys, client = _view(s)
    keys.press("p")
    assert client.done.wait(5)
    for _ in range(100):  # (the answer is handed over by the key's thread)
        if view.message:
            break
        threading.Event().wait(0.01)
    assert view.foot().startswith("ok: paused: no node starts")
    clock[0] += watchterm.SAID_FOR - 1
    assert view.foot().startswith("ok: paused")
    clock[0] += 2
    assert view.foot() == KEYS_HELP   # it stayed "ok: paused" for good, through later runs
    # an answer is about its run: another run shown takes it away at once
    view.answered("ok: paused: no node starts")
    s.apply({"type": "end", "run": "r1", "t": 1.0, "status": "SUCCESS", "ticks": 0, "duration": 1.0})
    s.apply(tree(run="r2", control=False))
    assert s.run == "r2" and view.foot() == NO_CONTROL_HELP
    view.answered("ok: resumed", run="r1")   # the answer of a key sent to the run before comes late
    assert view.foot() == NO_CONTROL_HELP


def _get(url):
    with urllib.request.urlopen(url, timeout=10) as r:
        return json.loads(r.read().decode())


def _post(url, cmd):
    req = urllib.request.Request(url + "control", data=json.dumps(cmd).encode(), method="POST",
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read().decode())


def test_the_page_offers_controls_only_while_a_run_that_takes_them_is_shown():
    s = WatchState()
    sent = []
    server = WebServer(s, port=0, control=lambda cmd: sent.append(cmd) or {"ok": True, "answer": "paused"})
    server.poll_wait = 0.1
    try:
        assert _get(server.url + "state")["steer"] is False   # before: the buttons were there, waiting for a run
        assert _post(server.url, {"command": "pause"}) == {
            "ok": False, "answer": "not sent: no run is shown yet: the keys steer a run started with --control "
                                   "once one is shown"}
        s.apply(tree(control=True))
        assert _get(server.url + "state")["steer"] is True
        assert _post(server.url, {"command": "pause"})["ok"] is True
        s.apply({"type": "end", "run": "r1", "t": 1.0, "status": "SUCCESS", "ticks": 0, "duration": 1.0})
        assert _get(server.url + "state")["steer"] is False
        assert _post(server.url, {"command": "pause"})["answer"].startswith("not sent: the run has ended")
        s.apply(tree(run="r2", control=False))
        assert _get(server.url + "state")["steer"] is False
        assert sent == [{"command": "pause"}]
    finally:
        server.httpd.shutdown()
        server.httpd.server_close()


def test_the_page_clears_an_answer_after_a_few_seconds_and_on_another_run():
    import os

    with open(os.path.join(os.path.dirname(watchterm.__file__), "web", "app.js")) as fh:
        app = fh.read()
    assert "SAID_MS = 6000" in app and 'Date.now() - answeredAt > SAID_MS) said("")' in app
    assert '(s.tree || {}).run !== answeredRun) said("")' in app


def test_a_resume_whose_records_came_before_its_answer_still_says_paused_again():
    """The records of the resume and of the breakpoint that paused the run again at once came before the
    run's answer to 'p': the footer said only 'ok: resumed' under PAUSED."""
    s = WatchState()
    s.apply(tree(control=True))
    s.apply({"type": "control", "run": "r1", "t": 5.0, "command": "pause", "args": {}, "ok": True,
             "answer": "paused", "by": "/op", "paused": True})

    class Racing(Client):
        def send(self, cmd, timeout):
            for command, answer, paused in (("resume", "resumed", False),
                                            ("breakpoint", "paused before 'x' starts", True)):
                s.apply({"type": "control", "run": "r1", "t": 9.0, "command": command, "args": {}, "ok": True,
                         "answer": answer, "by": "/op", "paused": paused})
            return super().send(cmd, timeout)

    view = LiveView(s, footer=keys_help)
    client = Racing({"ok": True, "answer": "resumed"})
    Keys(view, client, threading.Event()).press("p")
    assert client.done.wait(5)
    for _ in range(100):
        if view.message:
            break
        threading.Event().wait(0.01)
    assert client.sent == [{"command": "resume"}]
    assert view.foot() == "ok: resumed; paused again: paused before 'x' starts"
