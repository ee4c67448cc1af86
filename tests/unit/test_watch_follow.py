"""``watch --follow`` from one run to the next, with the run stream's topics arriving in any order
(ROS orders messages per connection, not across topics): the next run's records that come before its
``tree`` are kept and shown after it, a ``snapshot`` never drops a newer record that came before it,
and ``--plain`` says the next run's header before its lines and its catching up once (no ROS)."""
from __future__ import annotations

import io
import json

from coordinator.watchstate import WatchState
from coordinator.watchview import LinePrinter, TimeOrderedLines

NODES = [{"id": 0, "parent": None, "kind": "sequence", "shape": "sequence", "name": "errand"},
         {"id": 1, "parent": 0, "kind": "call", "shape": "leaf", "name": "greet"},
         {"id": 2, "parent": 0, "kind": "call", "shape": "leaf", "name": "drive"}]


def tree(run, t=0.0):
    return {"v": 1, "type": "tree", "run": run, "t": t, "name": "errand_%s" % run[-1], "pid": 1, "started": 1.7e9,
            "control": True, "blackboard": {}, "nodes": NODES}


def start(run, cid, t, node=1, target="speech.say"):
    return {"v": 1, "type": "call_start", "run": run, "t": t, "call_id": cid, "target": target, "node": node,
            "inputs": {"text": "hello"}, "timeout": 30}


def end_of_call(run, cid, t, duration, node=1, target="speech.say"):
    return {"v": 1, "type": "call_end", "run": run, "t": t, "call_id": cid, "target": target, "node": node,
            "status": "succeeded", "error": "", "outputs": {"success": True}, "answer": "succeeded",
            "duration": duration}


def tick(run, n, t, changes):
    return {"v": 1, "type": "tick", "run": run, "n": n, "t": t, "changes": changes}


def snapshot(run, n, t, tick_t, status=None, pending=(), calls=(), ncalls=0):
    return {"v": 1, "type": "snapshot", "sv": 1, "run": run, "t": t, "n": n, "tick_t": tick_t,
            "status": dict(status or {}), "halted": [], "feedback": {}, "last": {}, "pending": list(pending),
            "calls": list(calls), "ncalls": ncalls, "events": [], "control": [], "blackboard": {}, "written": [],
            "paused": False, "end": None}


def finished(run, t):
    return {"v": 1, "type": "end", "run": run, "t": t, "status": "SUCCESS", "reason": "", "duration": t, "ticks": 3,
            "calls": 1}


RUN_A, RUN_B = "20261126-170510-aaaaaa", "20261126-170621-bbbbbb"


def first_run_ended(state, take=None):
    for rec in (tree(RUN_A), tick(RUN_A, 1, 0.01, [[0, "RUNNING"], [1, "RUNNING"]]),
                start(RUN_A, "a1", 0.002), end_of_call(RUN_A, "a1", 0.02, 0.018),
                tick(RUN_A, 2, 37.5, [[1, "SUCCESS"], [2, "SUCCESS"]]), tick(RUN_A, 3, 37.8, [[0, "SUCCESS"]]),
                finished(RUN_A, 37.868)):
        (take or state.apply)(rec)
    assert state.end is not None


def test_a_snapshot_that_comes_after_a_newer_call_end_does_not_bring_the_call_back():
    """The greeting answered at 0.010 s, its leaf took it at tick 2; the snapshot of tick 1 (t 0.012, the call
    pending) came after that call_end, on its own topic: it must not make the call pending again (the page
    showed speech.say pending at '23.07s / 30s' and missing from the call log)."""
    s = WatchState()
    s.apply(tree(RUN_B))
    s.apply(start(RUN_B, "b1", 0.002))
    s.apply(end_of_call(RUN_B, "b1", 0.010, 0.008))
    s.apply(snapshot(RUN_B, 1, 0.012, 0.011, {"0": "RUNNING", "1": "RUNNING"}, pending=[start(RUN_B, "b1", 0.002)]))
    assert s.caught_up and s.pending == {}, s.pending
    assert [c["call_id"] for c in s.calls] == ["b1"] and s.calls_total == 1
    view = s.view()
    assert view["pending"] == [] and [c["call_id"] for c in view["calls"]] == ["b1"]
    # and the records the snapshot holds that come after it are not applied twice
    s.apply(start(RUN_B, "b1", 0.002))
    s.apply(tick(RUN_B, 1, 0.011, [[0, "RUNNING"], [1, "RUNNING"]]))
    assert s.pending == {} and s.tick == 1


def test_follow_shows_the_next_run_with_its_records_that_came_before_its_tree():
    """A --follow watch: the first run has ended; the next run's call start and end and its snapshot of
    tick 1 (the call still pending in it) come before its tree record. Once shown, the call has ended."""
    s = WatchState()
    first_run_ended(s)
    for rec in (start(RUN_B, "b1", 0.002), end_of_call(RUN_B, "b1", 0.010, 0.008),
                snapshot(RUN_B, 1, 0.012, 0.011, {"0": "RUNNING", "1": "RUNNING"}, pending=[start(RUN_B, "b1", 0.002)]),
                tick(RUN_B, 1, 0.011, [[0, "RUNNING"], [1, "RUNNING"]])):
        s.apply(rec)
        assert s.run == RUN_A and s.end is not None  # kept aside: nothing of the next run is applied to the first
    s.apply(tree(RUN_B))
    assert s.run == RUN_B and s.end is None and s.tick == 1
    assert s.pending == {} and [c["call_id"] for c in s.calls] == ["b1"], (s.pending, s.calls)
    assert s.label(1) == "RUNNING"


def test_a_short_run_whose_end_comes_before_its_tree_is_shown_whole():
    s = WatchState()
    first_run_ended(s)
    for rec in (start(RUN_B, "b1", 0.002), tick(RUN_B, 1, 0.01, [[0, "RUNNING"], [1, "RUNNING"]]),
                end_of_call(RUN_B, "b1", 0.010, 0.008), finished(RUN_B, 0.05),
                tick(RUN_B, 2, 0.02, [[1, "SUCCESS"], [2, "SUCCESS"], [0, "SUCCESS"]])):
        s.apply(rec)
    s.apply(tree(RUN_B))
    assert s.run == RUN_B and s.end is not None and s.end["run"] == RUN_B and s.label(0) == "SUCCESS"


def test_plain_follow_says_the_next_runs_header_first_and_its_catching_up_once():
    """--plain --follow: the next run's header came only after its first long call ended (its lines, at
    0.0x s, were put before it: the header had no time of its own but the previous run's last), the new run's
    first records came under the previous run's end, and 'caught up at tick 0' was said twice."""
    out = io.StringIO()
    lines_out = TimeOrderedLines(out, window=0.3)
    s = WatchState()
    p = LinePrinter(lines_out)

    def take(rec):
        s.apply(rec)
        p.record(rec, s)

    first_run_ended(s, take)
    # the next run: its snapshot (on connecting) and its first records come before its latched tree
    for rec in (snapshot(RUN_B, 0, 0.0, 0.0), start(RUN_B, "b1", 0.002), tree(RUN_B), snapshot(RUN_B, 0, 0.0, 0.0),
                tick(RUN_B, 1, 0.01, [[0, "RUNNING"], [1, "RUNNING"]]), end_of_call(RUN_B, "b1", 0.019, 0.017),
                start(RUN_B, "b2", 0.02, node=2, target="navigation.go_to"),
                tick(RUN_B, 2, 0.021, [[1, "SUCCESS"], [2, "RUNNING"]])):
        take(rec)
    lines_out.close()
    lines = out.getvalue().splitlines()
    head = next(k for k, line in enumerate(lines) if line.startswith("run %s:" % RUN_B))
    a_end = next(k for k, line in enumerate(lines) if "] end " in line)
    assert head == a_end + 1, lines  # nothing of the next run before its header
    after = lines[head + 1:]
    assert [line for line in lines if "caught up" in line] == [after[0]], lines
    assert after[0].startswith("[  0.000s] caught up at tick 0")
    said = "\n".join(after)
    for text in ('call      speech.say {"text":"hello"}', "RUNNING   greet", "succeeded speech.say",
                 "call      navigation.go_to", "RUNNING   drive"):
        assert said.count(text) == 1, (text, lines)


def test_the_snapshot_a_run_sends_holds_its_newer_fields_and_a_late_watch_reads_them():
    """(A snapshot is the run's own WatchState: what a late watch catches up from.)"""
    s = WatchState()
    first_run_ended(s)
    snap = json.loads(json.dumps(s.snapshot()))
    late = WatchState()
    late.apply(tree(RUN_A))
    late.apply(snap)
    assert late.end is not None and late.calls_total == 1 and late.label(0) == "SUCCESS"
