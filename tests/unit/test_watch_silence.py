"""``bmtree watch`` when the run's node stops answering (its link down, its process stopped): the
state keeps it (:meth:`WatchState.heard`), the terminal's header, the ``--plain`` lines and the page's
state say that what is shown may be stale, and stop saying it once the node answers again. A run that
is merely idle (its node answers) shows nothing."""
from __future__ import annotations

import io
import time

from rich.console import Console

from coordinator.watch import RosWatcher
from coordinator.watchlive import RunLiveness
from coordinator.watchstate import KEEP, SILENT_AFTER, WatchState
from coordinator.watchtext import summary_lines
from coordinator.watchview import LinePrinter, render
from tests.unit.test_watchstate import tree_record
from tests.unit.xmlrpc_standin import StandIn

NODE = "/bmtree_4242_1795636146106"


def running(t0=100.0):
    """A state showing a run at tick 1, its node first asked at ``t0`` (monotonic)."""
    s = WatchState()
    s.apply(tree_record())
    s.apply({"type": "tick", "run": "r1", "n": 1, "t": 2.5, "changes": [[0, "RUNNING"], [1, "RUNNING"]]})
    assert not s.heard(NODE, True, now=t0)
    return s


def shown(group, width=200):
    buf = io.StringIO()
    Console(file=buf, width=width, no_color=True).print(group)
    return buf.getvalue()


def test_the_state_says_it_after_3_s_without_an_answer_and_again_when_it_answers():
    s = running()
    version = s.version
    assert not s.heard(NODE, False, now=101.0) and not s.heard(NODE, False, now=102.9)
    assert s.silence(now=102.9) == "" and s.notes == []
    assert s.heard(NODE, False, now=100.0 + SILENT_AFTER)  # began: said once
    assert s.version > version
    assert s.silence(now=107.4) == ("no answer from the run's node %s for 7 s (its machine unreachable, or its "
                                    "process stopped): what is shown may be stale" % NODE)
    assert not s.heard(NODE, False, now=105.0)  # still silent: nothing new to say
    assert [n["what"] for n in s.notes] == ["run_silent"] and s.notes[0]["watch"]
    assert "has not answered for 3 s (its machine unreachable, or its process stopped)" in s.notes[0]["text"]
    assert s.view()["silent"].startswith("no answer from the run's node %s for " % NODE)
    assert s.heard(NODE, True, now=112.2)
    assert s.silence(now=112.3) == "" and s.view()["silent"] == ""
    assert s.notes[-1]["what"] == "run_answers"
    assert s.notes[-1]["text"] == "the run's node %s answers again after 12 s: what is shown is current again" % NODE
    assert all(e.get("watch") for e in s.view()["events"] if e.get("what") in ("run_silent", "run_answers"))


def test_an_idle_run_whose_node_answers_shows_nothing():
    """No record for a minute (a long navigation call), but its node answers every second."""
    s = running()
    for k in range(1, 61):
        assert not s.heard(NODE, True, now=100.0 + k)
    assert s.silence(now=161.0) == "" and s.notes == [] and not s.silent
    assert "no answer" not in shown(render(s, 200, 40, now=60.0))


def test_a_silence_ends_with_the_run_and_a_new_run_starts_afresh():
    s = running()
    assert s.heard(NODE, False, now=104.0)
    s.apply({"type": "end", "run": "r1", "t": 3.0, "status": "SUCCESS", "ticks": 1, "duration": 3.0, "calls": 0})
    assert s.silence(now=105.0) == "" and not s.heard(NODE, True, now=106.0)
    assert not any("answer" in line for line in summary_lines(s))  # the end screen lists other runs only
    s.apply(tree_record(run="r2"))  # the next run (--follow)
    assert s.asked is None and not s.silent and s.notes == []


def test_the_terminal_header_says_it_and_its_seconds_count():
    t0 = time.monotonic() - 7.5  # its last answer 7.5 s ago
    s = running(t0)
    assert s.heard(NODE, False, now=t0 + 4.0)
    frame = shown(render(s, 200, 40, now=6.0)).split("\n")
    assert frame[0].startswith("bmtree watch t  t=")
    assert frame[1].startswith("no answer from the run's node %s for 7 s" % NODE)
    assert frame[1].rstrip().endswith("what is shown may be stale")
    narrow = shown(render(s, 80, 24, now=6.0), width=80).rstrip("\n").split("\n")
    assert len(narrow) <= 24 and all(len(line) <= 80 for line in narrow)
    assert narrow[1].startswith("no answer from the run's node") and "stale" in narrow[2]  # wrapped over two
    assert s.heard(NODE, True)
    assert "no answer" not in shown(render(s, 200, 40, now=7.0))


def test_plain_prints_one_line_when_it_begins_and_one_when_it_ends():
    s = running()
    out = io.StringIO()
    p = LinePrinter(out)
    with s.lock:
        assert s.heard(NODE, False, now=103.5)
        p.notes(s)
        assert not s.heard(NODE, False, now=104.5)
        p.notes(s)  # nothing new
    p.record({"type": "tick", "run": "r1", "n": 2, "t": 2.6, "changes": [[2, "RUNNING"]]}, s)  # not said again
    with s.lock:
        assert s.heard(NODE, True, now=115.0)
        p.notes(s)
    lines = out.getvalue().splitlines()
    said = [line for line in lines if "run's node" in line]
    assert len(said) == 2, lines
    assert said[0].startswith("[") and "s] notice    the run's node %s has not answered for 3 s" % NODE in said[0]
    assert "what is shown may be stale" in said[0]
    assert "the run's node %s answers again after 15 s" % NODE in said[1]


def test_plain_keeps_printing_notices_past_the_ones_kept():
    """A link that drops again and again: the state keeps the last KEEP notices, ``--plain`` says each."""
    s = running()
    out = io.StringIO()
    p = LinePrinter(out)
    t = 100.0
    for _ in range(KEEP):
        t += 4.0
        with s.lock:
            s.heard(NODE, False, now=t)
            s.heard(NODE, True, now=t + 0.5)
            p.notes(s)
    assert len(s.notes) == KEEP
    assert out.getvalue().count("has not answered") == KEEP and out.getvalue().count("answers again") == KEEP


def _uri(standin):
    return "http://127.0.0.1:%d/" % standin.port


def test_the_watch_asks_the_run_node_and_a_stopped_process_does_not_answer(tmp_path):
    """RunLiveness.ask against a real node process (rosgraph's XML-RPC server), stopped with SIGSTOP."""
    node = StandIn(tmp_path)
    node.start()
    state = running()
    watcher = RosWatcher(state)
    watcher.nodes["r1"] = NODE
    changes = []
    liveness = RunLiveness(watcher, on_change=lambda: changes.append(state.silence()))
    liveness._uri_of = lambda name: _uri(node)
    try:
        liveness.ask()
        assert state.asked is not None and state.asked[0] == NODE and not state.silent
        liveness.ask()  # it answers: nothing to say
        assert changes == [] and node.questions() == 2
        with state.lock:
            state.asked = (NODE, state.asked[1] - SILENT_AFTER)  # its last answer 3 s ago
        node.stop()
        try:
            liveness.ask()  # no answer within a second
            assert state.silent and changes and changes[-1].startswith("no answer from the run's node " + NODE)
        finally:
            node.resume()
        liveness.ask()
        assert not state.silent and changes[-1] == "" and state.notes[-1]["what"] == "run_answers"
    finally:
        liveness.stop()
        node.kill()


def test_the_page_is_answered_when_it_begins_and_then_every_second_until_it_ends():
    """``/state``'s long poll (here up to a minute) answers when the silence begins, then while it lasts
    without a change (the page's seconds count), and when it ends."""
    import json
    import threading
    import urllib.request

    from coordinator.webview import WebServer

    t0 = time.monotonic() - 3.5  # its last answer 3.5 s ago
    s = running(t0)
    server = WebServer(s)
    server.poll_wait = 60.0
    got = []

    def poll(since):
        with urllib.request.urlopen(server.url + "state?since=%d" % since, timeout=120) as res:
            got.append(json.loads(res.read().decode("utf-8")))

    def answered(since):
        t = threading.Thread(target=poll, args=(since,), daemon=True)
        t.start()
        return t

    try:
        waiting = answered(s.version)
        assert s.heard(NODE, False)  # the change the poll waits for
        waiting.join(30)
        assert got and got[-1]["silent"].startswith("no answer from the run's node %s for 3 s" % NODE)
        assert got[-1]["events"][-1]["what"] == "run_silent"
        again = answered(got[-1]["version"])  # nothing changes: answered all the same, within the minute
        again.join(30)
        assert len(got) == 2 and got[-1]["silent"] and got[-1]["version"] == got[0]["version"]
        assert s.heard(NODE, True)
        assert json.loads(urllib.request.urlopen(server.url + "state?since=-1", timeout=30).read())["silent"] == ""
    finally:
        server.close()
