"""What an operator audit of ``bmtree watch`` found, each from hand-made run-stream records or an
in-process run: the result and the reason of a run that is gone outlive the alternate screen, a
killed run keeps its real last tick and its calls, a second run on the master is not switched to,
calls show their inputs, outputs, node and for_each element, events keep their order, the call
count is the run's, and the steering commands suggest a node's name."""
from __future__ import annotations

import io
import json
import os
import types

from rich.console import Console

from coordinator.runstream import RunStream, Sink
from coordinator.watch import RosWatcher
from coordinator.watchlive import gone_record
from coordinator.watchsinks import SnapshotSink, StateSink
from coordinator.watchstate import WatchState
from coordinator.watchview import LinePrinter, render
from tests.conftest import DATA

GO = os.path.join(DATA, "watch", "go_kitchen.yaml")
REASON = ("look for the object: vision.find_object failed: camera driver not responding (the driver of "
          "/dev/video2 did not answer within 5 s; is the camera plugged in?)")


def nodes():
    return [{"id": 0, "parent": None, "kind": "sequence", "shape": "sequence", "name": "errand"},
            {"id": 1, "parent": 0, "kind": "call", "shape": "leaf", "name": "say hello", "target": "speech.say"},
            {"id": 2, "parent": 0, "kind": "for_each", "shape": "decorator", "name": "visit rooms"},
            {"id": 3, "parent": 2, "kind": "call", "shape": "leaf", "name": "go to the room",
             "target": "navigation.go_to"},
            {"id": 4, "parent": 0, "kind": "call", "shape": "leaf", "name": "look for the object",
             "target": "vision.find_object"}]


def tree(run="r1", name="huge", **more):
    return dict({"v": 1, "type": "tree", "run": run, "t": 0.0, "name": name, "pid": 4242, "started": 1.7e9,
                 "blackboard": {}, "nodes": nodes()}, **more)


def shown(group, width=80):
    buf = io.StringIO()
    Console(file=buf, width=width, no_color=True).print(group)
    return buf.getvalue()


def lines_of(group, width=80):
    return shown(group, width).rstrip("\n").split("\n")


# 1. the result and the reason outlive the alternate screen; the result line wraps -------------------
def test_the_result_line_wraps_instead_of_being_cut():
    s = WatchState()
    s.apply(tree())
    s.apply({"type": "end", "run": "r1", "t": 66.85, "status": "FAILURE", "reason": REASON, "ticks": 282,
             "duration": 66.85, "calls": 109})
    lines = lines_of(render(s, 80, 24, "q quit"))
    assert len(lines) <= 24 and all(len(line) <= 80 for line in lines), lines
    start = next(k for k, line in enumerate(lines) if line.startswith("result: FAILURE in 66.85s (282 ticks)"))
    said = " ".join(line.strip() for line in lines[start:start + 4])
    assert "is the camera plugged in?)" in said, lines  # before: "…reason: look for the object: vision.find…"
    assert lines[-1] == "q quit"


def test_after_the_view_the_normal_screen_keeps_the_end_and_the_whole_reason():
    s = WatchState()
    s.apply(tree())
    s.apply({"type": "end", "run": "r1", "t": 66.85, "status": "FAILURE", "reason": REASON * 3, "ticks": 282,
             "duration": 66.85, "calls": 109})
    from coordinator.watchterm import LiveView

    buf = io.StringIO()
    console = Console(file=buf, width=80, height=24, no_color=True)
    LiveView(s, console=console, summary=True).stop()  # never started: what it leaves on the normal screen
    text = buf.getvalue()
    assert "\nresult: FAILURE in 66.85s (282 ticks)\nreason: look for the object" in text
    assert " ".join(text.split()).count(" ".join(("reason: " + REASON * 3).split())) == 1, text
    assert all(len(line) <= 80 for line in text.split("\n"))


# 2. a run killed outright ----------------------------------------------------------------------------
def late_watch_of_a_killed_run():
    """The run ticks at 0.002 s and sends a long call; a watch attaches at 2.911 s (the snapshot's time)."""
    clock = {"now": 100.0}
    sink = SnapshotSink(publish=lambda text: None, clock=lambda: clock["now"])
    sink.write("tree", json.dumps(tree()))
    for rec in [{"type": "tick", "run": "r1", "n": 1, "t": 0.001, "changes": [[0, "RUNNING"], [1, "RUNNING"]]},
                {"type": "call_end", "run": "r1", "t": 0.001, "call_id": "c0", "target": "speech.say", "node": 1,
                 "status": "succeeded", "error": "", "outputs": {}, "duration": 0.0},
                {"type": "call_start", "run": "r1", "t": 0.002, "call_id": "c1", "target": "navigation.go_to",
                 "node": 3, "inputs": {"place": "kitchen"}, "timeout": 30},
                {"type": "tick", "run": "r1", "n": 2, "t": 0.002, "changes": [[1, "SUCCESS"], [2, "RUNNING"],
                                                                            [3, "RUNNING"]]}]:
        sink.write("any", json.dumps(rec))
    clock["now"] = 102.911
    late = WatchState()
    late.apply(tree())
    late.apply(json.loads(json.dumps(sink.snapshot())))
    return late


def test_a_killed_run_keeps_the_time_of_its_last_tick_not_of_the_catch_up():
    late = late_watch_of_a_killed_run()
    assert late.t == 2.911 and late.tick == 2
    assert late.tick_t == 0.002  # before: 2.911, the snapshot's time
    end = gone_record(late, "/bmtree_4242_1", "its process ended", alive=5.0)
    assert "its last tick (2) at 0.002s" in end["reason"] and "its process ended" in end["reason"]
    assert end["duration"] == 5.0 and end["calls"] == 1
    late.apply(end)
    assert "result: UNFINISHED, gone at about 5.00s (2 ticks)" in shown(render(late, 200, 40))


def test_the_end_of_a_killed_run_keeps_its_calls_as_maybe_still_running():
    from coordinator.watchtext import summary_lines

    late = late_watch_of_a_killed_run()
    late.apply(gone_record(late, "/bmtree_4242_1", "its process ended", alive=5.0))
    assert list(late.pending) == ["c1"] and late.pending["c1"]["maybe_running"]  # before: cleared
    text = shown(render(late, 120, 40), 120)
    assert "pending calls: none" not in text
    line = next(line for line in text.split("\n") if "navigation.go_to" in line and "run gone" in line)
    assert "since 0.00s, maybe still running (run gone)" in line and "'go to the room'" in line
    said = "\n".join(summary_lines(late))
    assert "maybe still running (run gone): navigation.go_to since 0.00s in 'go to the room'  place kitchen" in said
    assert "the run did not finish (exit 3)" in said
    out = io.StringIO()
    late2 = late_watch_of_a_killed_run()
    end = gone_record(late2, "/bmtree_4242_1", "its process ended", alive=5.0)
    late2.apply(end)
    LinePrinter(out).record(end, late2)
    assert "maybe still running (run gone): navigation.go_to since 0.002s" in out.getvalue()
    # a run that ends as it should halts its calls itself: nothing is left pending
    s = late_watch_of_a_killed_run()
    s.apply({"type": "end", "run": "r1", "t": 3.0, "status": "INVALID", "reason": "interrupted", "ticks": 3})
    assert not s.pending


# 3. two runs on one master ---------------------------------------------------------------------------
def test_a_second_run_on_the_master_gets_a_notice_and_the_watch_stays():
    from coordinator.watchtext import summary_lines

    s = WatchState()
    out = io.StringIO()
    printer = LinePrinter(out)
    watcher = RosWatcher(s, on_record=lambda r: printer.record(r, s))
    watcher.apply(tree("20261122-031500-aaaaaa", "huge"))
    watcher.apply({"type": "tick", "run": "20261122-031500-aaaaaa", "n": 1, "t": 0.1, "changes": [[0, "RUNNING"]]})
    watcher.apply(tree("20261122-031502-bbbbbb", "find_apple"))
    watcher.apply({"type": "tick", "run": "20261122-031502-bbbbbb", "n": 1, "t": 0.1, "changes": [[4, "FAILURE"]]})
    assert s.tree["name"] == "huge" and s.label(0) == "RUNNING" and s.label(4) == ""  # before: find_apple
    text = out.getvalue()
    assert "notice    another run started: find_apple (bmtree watch --run bbbbbb shows it); this watch stays on " \
           "huge (the other one: run 20261122-031502-bbbbbb, pid 4242)" in text, text
    assert "FAILURE" not in text  # the other run's lines are not mixed in
    assert "bmtree watch --run bbbbbb" in shown(render(s, 120, 30), 120)
    assert any("--run bbbbbb" in str(e.get("text")) for e in s.view()["events"])  # the page gets it too
    assert any("--run bbbbbb" in line for line in summary_lines(s))
    # the first run ends: the watch ends with it, unless --follow, which shows the other one now
    watcher.apply({"type": "end", "run": "20261122-031500-aaaaaa", "t": 1.0, "status": "SUCCESS", "ticks": 1})
    assert s.run.endswith("aaaaaa")
    assert watcher.show_next() and s.tree["name"] == "find_apple" and s.label(4) == "FAILURE"


def test_watch_run_shows_the_run_it_names():
    from coordinator.watch import no_run_message

    s = WatchState(only="bbbbbb")
    s.apply(tree("20261122-031500-aaaaaa", "huge"))
    assert not s.nodes
    s.apply({"type": "tick", "run": "20261122-031502-bbbbbb", "n": 1, "t": 0.1, "changes": [[4, "RUNNING"]]})
    s.apply(tree("20261122-031502-bbbbbb", "find_apple"))
    assert s.tree["name"] == "find_apple" and s.label(4) == "RUNNING"
    s.apply(tree("20261122-031503-cccccc", "third"))
    assert s.tree["name"] == "find_apple"
    assert [o["name"] for o in s.others.summary()] == ["huge", "third"]
    message = no_run_message("/bmtree/run", 10.0, "dddddd", s.others.summary())
    assert message.startswith("error: no run dddddd on /bmtree/run/tree after 10s")
    assert "; the runs seen: 20261122-031500-aaaaaa (huge), 20261122-031503-cccccc (third). A run" in message


# 4. calls: inputs, outputs, the node that made them and its for_each element -----------------------
def test_the_call_log_shows_inputs_and_outputs_and_the_pending_panel_the_node():
    s = WatchState()
    s.apply(tree())
    s.apply({"type": "tick", "run": "r1", "n": 1, "t": 0.1, "loops": [[2, 47, 90]],
             "changes": [[0, "RUNNING"], [2, "RUNNING"], [3, "RUNNING"]]})
    s.apply({"type": "call_start", "run": "r1", "t": 0.1, "call_id": "c1", "target": "navigation.go_to", "node": 3,
             "inputs": {"place": "kitchen"}, "timeout": 30})
    s.apply({"type": "call_end", "run": "r1", "t": 2.1, "call_id": "c1", "target": "navigation.go_to", "node": 3,
             "status": "succeeded", "error": "", "outputs": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}},
             "answer": "succeeded", "duration": 2.0})
    s.apply({"type": "call_start", "run": "r1", "t": 2.2, "call_id": "c2", "target": "navigation.go_to", "node": 3,
             "inputs": {"place": "bedroom"}, "timeout": 30})
    s.apply({"type": "call_end", "run": "r1", "t": 2.3, "call_id": "c3", "target": "vision.find_object", "node": 4,
             "status": "module_lost", "error": "module vision lost: its process ended", "outputs": {},
             "duration": 0.1})
    text = shown(render(s, 120, 30, now=3.0), 120)
    log = next(line for line in text.split("\n") if "succeeded" in line)
    assert "place kitchen  → position {x:0,y:0,z:0}" in log, text
    pending = next(line for line in text.split("\n") if "/ 30s" in line)
    assert "'go to the room' (item 47 of 90)  place bedroom" in pending, text
    assert "visit rooms [for_each]  RUNNING  item 47 of 90" in text
    lost = next(line for line in text.split("\n") if "module_lost" in line)
    assert log.index("2.00s") == lost.index("0.10s")  # the columns stay aligned
    for line in lines_of(render(s, 80, 24, now=3.0)):  # and all of it within the width
        assert len(line) <= 80


def test_the_stream_tells_the_element_each_for_each_is_at(sim_defs, tmp_path):
    from coordinator.testing.kit import TreeTest
    from coordinator.testing.mocks import succeed

    path = tmp_path / "rooms.yaml"
    path.write_text("format: 1\nname: rooms\nroot:\n  for_each: [kitchen, bedroom, bathroom]\n  name: visit rooms\n"
                    "  as: room\n  child:\n    call: navigation.go_to\n    name: go to the room\n"
                    "    inputs: {place: $room}\n")
    texts = []
    state = WatchState()

    class Views(Sink):
        def write(self, channel, text):
            state.apply_text(text)
            rec = json.loads(text)
            if rec["type"] == "tick" and state.pending:
                texts.append(shown(render(state, 120, 30), 120))

    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].script(*[succeed(room=r, delay=1.0) for r in ("kitchen", "bedroom", "bathroom")])
    records = []

    class Records(Sink):
        def write(self, channel, text):
            records.append(json.loads(text))

    assert t.run(observers=[RunStream([Records(), Views()])]).succeeded
    loops = [r["loops"] for r in records if r.get("loops")]
    assert [row[1:] for rows in loops for row in rows] == [[1, 3], [2, 3], [3, 3]], loops
    assert any("'go to the room' (item 2 of 3)  place bedroom" in text for text in texts), texts


# 5. order and counts ---------------------------------------------------------------------------------
def test_control_lines_of_one_time_keep_their_order():
    from coordinator.watchterm import LiveView

    s = WatchState()
    s.apply(tree())
    view = LiveView(s, console=Console(file=io.StringIO(), width=120))
    s.apply({"type": "control", "run": "r1", "t": 50.0, "command": "pause", "args": {}, "ok": True,
             "answer": "paused", "by": "/op", "paused": True})
    view.answered("ok: resumed")  # the reply to 'p' came before the record of the resume
    assert view.foot() == "ok: resumed"  # not "paused again" for the pause before it
    for command, answer, paused in (("resume", "resumed", False), ("breakpoint", "paused before 'x' starts", True)):
        s.apply({"type": "control", "run": "r1", "t": 50.82, "command": command, "args": {}, "ok": True,
                 "answer": answer, "by": "/op", "paused": paused})
    text = shown(render(s, 120, 30), 120)
    assert text.index("control resume") < text.index("control breakpoint"), text  # before: alphabetical
    assert view.foot() == "ok: resumed; paused again: paused before 'x' starts"  # before: "ok: resumed" under PAUSED


def test_the_call_log_counts_the_runs_calls():
    # the run's own view: more calls than the 200 kept
    s = WatchState()
    s.apply(tree())
    for k in range(290):
        s.apply({"type": "call_end", "run": "r1", "t": k * 0.1, "call_id": "c%d" % k, "target": "speech.say",
                 "status": "succeeded", "duration": 0.01})
    assert "call log (" in shown(render(s, 80, 24)) and " of 290)" in shown(render(s, 80, 24))  # before: of 200
    # a late watch: the calls before it attached count too
    late = WatchState()
    late.apply(tree())
    late.apply(json.loads(json.dumps(s.snapshot())))  # 50 calls in it
    assert late.calls_total == 290 and " of 290)" in shown(render(late, 80, 24))
    out = io.StringIO()
    LinePrinter(out).record(s.snapshot(), late)
    assert "290 calls done" in out.getvalue()
    late.apply({"type": "end", "run": "r1", "t": 30.0, "status": "SUCCESS", "ticks": 300, "duration": 30.0,
                "calls": 291})
    assert " of 291)" in shown(render(late, 80, 24))


def test_plain_lines_of_a_lost_module_keep_their_columns():
    s = WatchState()
    s.apply(tree())
    out = io.StringIO()
    p = LinePrinter(out)
    for status, error in (("succeeded", ""), ("module_lost", "module vision lost: its process ended")):
        rec = {"type": "call_end", "run": "r1", "t": 1.0, "call_id": status, "target": "vision.find_object",
               "status": status, "error": error, "outputs": {"seen": True} if not error else {}}
        s.apply(rec)
        p.record(rec, s)
    ok, lost = out.getvalue().splitlines()
    assert ok.index("vision.find_object") == lost.index("vision.find_object"), (ok, lost)
    assert ok.endswith("→ seen true") and lost.endswith("module vision lost: its process ended")


# 6. no run ---------------------------------------------------------------------------------------------
def test_no_run_says_where_a_run_that_ended_is():
    from coordinator.watch import no_run_message

    message = no_run_message("/bmtree/run", 10.0)
    assert message.startswith("error: no run on /bmtree/run/tree after 10s (is 'bmtree run' running on this master?")
    assert "'bmtree runs'" in message and "'bmtree replay" in message


# 7. steering: did you mean ---------------------------------------------------------------------------
def test_a_mistyped_node_name_gets_a_did_you_mean():
    import py_trees

    from coordinator.control import Controller

    root = py_trees.composites.Sequence("errand", memory=True, children=[
        py_trees.behaviours.Success("look for the object"), py_trees.behaviours.Success("go to the kitchen")])
    control = Controller(True)
    control.ctx = types.SimpleNamespace(blackboard={"room": "kitchen"}, observers=[])
    control.root = root
    ok, answer = control._apply({"command": "break", "node": "look for the objekt"})
    assert not ok and answer == "no node named 'look for the objekt' in this tree (did you mean 'look for the object'?)"
    ok, answer = control._apply({"command": "set", "key": "rooom", "value": "hall"})
    assert not ok and "(did you mean 'room'?)" in answer


# 8. an answer that came while paused -----------------------------------------------------------------
def test_a_call_answered_while_paused_shows_as_answered(sim_defs):
    from coordinator.builder import build_tree
    from coordinator.clock import SimClock
    from coordinator.context import RunContext
    from coordinator.control import Controller
    from coordinator.language import load_tree
    from coordinator.runner import TreeRunner
    from coordinator.testing.inprocess import InProcessTransport
    from coordinator.testing.mocks import Mocks, succeed

    mocks = Mocks(sim_defs)
    mocks["navigation.go_to"].script(succeed(room="kitchen", delay=2.0))
    clock = SimClock()
    ctx = RunContext(InProcessTransport(mocks, clock), clock, sim_defs)
    tree_file = load_tree(GO, sim_defs)
    control = Controller(True)
    clock.call_later(0.5, lambda: control.submit({"command": "pause", "by": "/op"}))
    clock.call_later(10.0, lambda: control.submit({"command": "resume", "by": "/op"}))
    state = WatchState()
    seen = []

    class Paused(StateSink):
        def write(self, channel, text):
            super().write(channel, text)
            if json.loads(text)["type"] == "call_answer":
                seen.append(shown(render(state, 120, 30, now=9.5), 120))

    records = []

    class Records(Sink):
        def write(self, channel, text):
            records.append(json.loads(text))

    result = TreeRunner(build_tree(tree_file, ctx, {}), ctx, observers=[RunStream([Records(), Paused(state)]), control],
                        tree=tree_file, gate=control).run(60.0)
    assert result.succeeded
    answers = [r for r in records if r["type"] == "call_answer"]
    assert len(answers) == 1 and answers[0]["target"] == "navigation.go_to" and answers[0]["answer"] == "succeeded"
    end = next(r for r in records if r["type"] == "call_end" and r["target"] == "navigation.go_to")
    assert answers[0]["t"] < 3.0 <= 10.0 <= end["t"]
    line = next(line for line in seen[0].split("\n") if "navigation.go_to" in line)
    assert "answered (succeeded) at %.2fs, taken at next tick" % answers[0]["t"] in line, seen[0]
    assert "/ 30s" not in line


def test_plain_lines_go_out_in_run_time_order_though_their_records_came_on_several_topics():
    """Over ROS a tick's record can come after the calls that followed it (another topic): the plain
    watch printed ``[0.084s] cleanup …`` before ``[0.080s] SUCCESS look``. Lines now wait a moment for
    earlier ones; what is held when the watch ends is written then."""
    import time as _time

    from coordinator.watchview import TimeOrderedLines

    out = io.StringIO()
    lines = TimeOrderedLines(out, window=0.2)
    lines.write("run r1: fetch (19 nodes)\n")
    lines.write("[  0.079s] succeeded vision.find_object\n[  0.084s] cleanup   the cleanup failed\n")
    lines.write("[  0.080s] SUCCESS   look\n[  0.081s] write     ended = \"failed\"\n")
    assert out.getvalue() == ""                      # held for the window
    deadline = _time.monotonic() + 10
    while out.getvalue().count("\n") < 5 and _time.monotonic() < deadline:
        _time.sleep(0.05)                            # released by its own thread once the window is over
    assert out.getvalue().splitlines() == [
        "run r1: fetch (19 nodes)", "[  0.079s] succeeded vision.find_object", "[  0.080s] SUCCESS   look",
        "[  0.081s] write     ended = \"failed\"", "[  0.084s] cleanup   the cleanup failed"]
    lines.write("[  0.098s] end       FAILURE\n")
    lines.close()
    assert out.getvalue().splitlines()[-1] == "[  0.098s] end       FAILURE"
    # a record that comes after the end (another topic's) is written at once, never held for good
    lines.write("[  0.097s] call      speech.say {}\n")
    assert out.getvalue().splitlines()[-1] == "[  0.097s] call      speech.say {}"


def test_an_ended_run_is_not_shown_paused():
    """A breakpoint in a cleanup paused the run and it ended so: the header said PAUSED after the end."""
    from coordinator.watchstate import WatchState

    s = WatchState()
    s.apply({"v": 1, "type": "tree", "run": "r1", "t": 0.0, "name": "t", "nodes": [{"id": 0, "parent": None, "kind": "wait",
                                                                           "shape": "leaf", "name": "w"}]})
    s.apply({"type": "control", "run": "r1", "t": 1.0, "command": "pause", "ok": True, "answer": "paused",
             "paused": True})
    assert s.paused
    s.apply({"type": "end", "run": "r1", "t": 12.0, "status": "SUCCESS", "reason": "", "ticks": 3})
    assert not s.paused and not s.view()["paused"]
