"""A running ``retry``'s attempt, shown as a ``for_each``'s item is: on its line in the terminal, beside
the node of a pending call under it, in the ``--plain`` lines and on the page (the server's
``progress``), and between attempts that it waits its delay; a retry's runs are called attempts, a
repeat's runs. The records are those of a real run of the auditor's serve_breakfast (no ROS)."""
from __future__ import annotations

import io
import json

from coordinator.watchstate import WatchState, fill
from coordinator.watchtext import pending_text, where_text
from coordinator.watchview import LinePrinter, tree_lines

RUN = "20261126-170510-93521f"
NODES = [(0, None, "sequence", "serve breakfast"), (1, 0, "for_each", "fetch each item"),
         (2, 1, "parallel", "drive while listening for stop"), (3, 2, "retry", "go to the item (retrying)"),
         (4, 3, "call", "drive to the item"), (5, 2, "wait_event", "wait for stop"),
         (6, 1, "retry", "find the item (retrying)"), (7, 6, "call", "look for the item"),
         (8, 0, "repeat", "three laps"), (9, 8, "call", "lap")]


def tree():
    return {"v": 1, "type": "tree", "run": RUN, "t": 0.0, "name": "serve_breakfast", "control": True,
            "blackboard": {}, "nodes": [{"id": i, "parent": p, "kind": k, "name": n,
                                         "shape": "leaf" if k in ("call", "wait_event") else "decorator"}
                                        for i, p, k, n in NODES]}


def tick(n, t, changes, **more):
    return dict({"v": 1, "type": "tick", "run": RUN, "n": n, "t": t, "changes": changes}, **more)


def lines(state, now):
    return [t.plain for t in tree_lines(state, 40, now)]


def line_of(state, now, name):
    return next(line for line in lines(state, now) if name in line)


def feed(records):
    s, out = WatchState(), io.StringIO()
    p = LinePrinter(out)
    for rec in records:
        s.apply(rec)
        p.record(rec, s)
    return s, out


START = [tree(), tick(1, 0.03, [[4, "RUNNING"], [3, "RUNNING"], [5, "RUNNING"], [2, "RUNNING"], [1, "RUNNING"],
                               [0, "RUNNING"]], loops=[[1, 1, 3]]),
         {"v": 1, "type": "call_start", "run": RUN, "t": 0.031, "call_id": "c1", "target": "navigation.go_to",
          "node": 4, "inputs": {"place": "kitchen"}, "timeout": 40}]
FIRST_FAILED = [{"v": 1, "type": "call_end", "run": RUN, "t": 0.034, "call_id": "c1", "target": "navigation.go_to",
                 "node": 4, "status": "failed", "error": "path blocked by a chair", "outputs": {}, "answer": "failed",
                 "duration": 0.003},
                # its delay: the child failed and was reset, the retry runs on without it
                tick(2, 0.0356, [[4, "FAILURE", "navigation.go_to failed: path blocked by a chair"], [4, "INVALID"]])]
SECOND = [tick(3, 1.04, [[4, "RUNNING"]]),
          {"v": 1, "type": "call_start", "run": RUN, "t": 1.041, "call_id": "c2", "target": "navigation.go_to",
           "node": 4, "inputs": {"place": "kitchen"}, "timeout": 40}]


def test_a_running_retry_shows_its_attempt_and_its_delay_as_a_for_each_its_item():
    s, out = feed(START)
    assert line_of(s, 0.5, "fetch each item").endswith("RUNNING  item 1 of 3")
    assert line_of(s, 0.5, "go to the item").endswith("RUNNING  attempt 1")
    s, out = feed(START + FIRST_FAILED)
    # between attempts: it waits its delay (the stream does not say how long: how long so far)
    assert line_of(s, 0.4356, "go to the item").endswith("RUNNING  waiting 0.4 s before attempt 2"), lines(s, 0.4356)
    assert "attempt   go to the item (retrying): waiting its delay before attempt 2" in out.getvalue()
    s, out = feed(START + FIRST_FAILED + SECOND)
    assert line_of(s, 2.0, "go to the item").endswith("RUNNING  attempt 2")
    plain = out.getvalue().splitlines()
    assert "[  1.040s] attempt   go to the item (retrying): attempt 2" in plain, plain
    assert "[  0.030s] item      fetch each item: item 1 of 3" in plain, plain
    assert line_of(s, 2.0, "wait for stop").endswith("RUNNING  waited 2.0 s")  # since its tick at 0.03 s
    # the pending call says where it is: the item and the attempt
    assert where_text(s, 4) == "'drive to the item' (item 1 of 3, attempt 2)"
    assert "'drive to the item' (item 1 of 3, attempt 2)" in pending_text(s, s.pending["c2"], 2.0, 160, 16)
    # the page: the server's words, its seconds counted by the page
    view = json.loads(json.dumps(s.view()))
    assert view["progress"]["3"] == {"text": "attempt 2"} and view["progress"]["1"] == {"text": "item 1 of 3"}
    assert fill(view["progress"]["5"], 3.03) == "waited 3.0 s"   # (the wait_event beside it)


def test_a_retry_that_gives_up_says_attempt_and_a_late_watch_knows_the_attempt():
    s, out = feed(START + FIRST_FAILED + SECOND)
    late, caught = WatchState(), io.StringIO()
    printer = LinePrinter(caught)
    for rec in (tree(), json.loads(json.dumps(s.snapshot()))):
        late.apply(rec)
        printer.record(rec, late)
    assert line_of(late, 2.0, "go to the item").endswith("RUNNING  attempt 2")
    # --plain says where its loops are when it catches up
    assert "caught up at tick 3: " in caught.getvalue()
    assert "go to the item (retrying) RUNNING (attempt 2), " in caught.getvalue(), caught.getvalue()
    assert "fetch each item RUNNING (item 1 of 3), " in caught.getvalue(), caught.getvalue()
    failed = tick(4, 2.5, [[4, "FAILURE", "navigation.go_to failed: blocked"],
                           [3, "FAILURE", "failed in run 2 of 2"], [2, "FAILURE"]])
    for state in (s, late):
        state.apply(failed)
        assert line_of(state, 3.0, "go to the item").endswith("FAILURE  failed in attempt 2 of 2")
        assert state.view()["feedback"]["3"] == "failed in attempt 2 of 2"
    p = LinePrinter(out)
    p.record(failed, s)
    assert "[  2.500s] FAILURE   go to the item (retrying) (failed in attempt 2 of 2)" in out.getvalue()
    assert "in run 2 of 2" not in out.getvalue()


def test_a_retry_without_delay_and_the_attempt_count_the_run_would_send():
    """A retry without delay reruns its child at the next tick. When the run stream says a retry's attempt
    and count as it says a for_each's (a ``loops`` row) and when its next attempt starts (``waits``), the
    views say ``attempt 2 of 3`` and ``next attempt in 0.6 s``."""
    s, _ = feed([tree(), tick(1, 0.1, [[7, "RUNNING"], [6, "RUNNING"]]),
                 tick(2, 0.2, [[7, "FAILURE", "vision.find_object failed"], [7, "INVALID"]]),
                 tick(3, 0.21, [[7, "RUNNING"]])])
    assert s.progress(6) == {"text": "attempt 2"}
    s.apply(tick(4, 0.3, [[7, "FAILURE", "vision.find_object failed"], [7, "INVALID"]], loops=[[6, 3, 3]]))
    assert s.progress(6) == {"text": "attempt 3 of 3"}
    s.apply(tick(5, 0.4, [[7, "FAILURE", "x"], [7, "INVALID"]], waits=[[6, 1.0]]))
    assert fill(s.progress(6), 0.4) == "next attempt in 0.6 s (3 of 3)"
    # a repeat counts runs (when the stream says them)
    s.apply(tick(6, 0.5, [[9, "RUNNING"], [8, "RUNNING"]], loops=[[8, 2, 3]]))
    assert s.progress(8) == {"text": "run 2 of 3"}
