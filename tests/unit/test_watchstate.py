"""WatchState and the terminal view from hand-made run-stream records: catch-up from a
snapshot, halted leaves, folding around the running branch, lines cut to the width."""
from __future__ import annotations

import io
import json

from rich.console import Console

from coordinator.watchsinks import SnapshotSink
from coordinator.watchstate import WatchState
from coordinator.watchview import LinePrinter, render, tree_lines


def tree_record(run="r1", leaves=3, groups=1):
    nodes = [{"id": 0, "parent": None, "kind": "sequence", "shape": "sequence", "name": "root"}]
    for g in range(groups):
        gid = len(nodes)
        nodes.append({"id": gid, "parent": 0, "kind": "sequence", "shape": "sequence", "name": "group %d" % g})
        for k in range(leaves):
            nodes.append({"id": len(nodes), "parent": gid, "kind": "call", "shape": "leaf", "name": "leaf %d.%d" % (g, k)})
    return {"v": 1, "type": "tree", "run": run, "t": 0.0, "name": "t", "blackboard": {"x": 1}, "nodes": nodes}


def shown(group):
    buf = io.StringIO()
    Console(file=buf, width=80, no_color=True).print(group)
    return buf.getvalue()


def test_halted_leaf_shows_as_halted_and_a_reset_one_as_not_ticked():
    s = WatchState()
    s.apply(tree_record())
    s.apply({"type": "tick", "run": "r1", "n": 1, "t": 0.1, "changes": [[0, "RUNNING"], [1, "RUNNING"], [2, "RUNNING"]]})
    s.apply({"type": "tick", "run": "r1", "n": 2, "t": 0.2, "changes": [[2, "INVALID"], [3, "SUCCESS"]]})
    assert s.label(2) == "HALTED" and s.label(3) == "SUCCESS" and s.label(4) == ""
    out = io.StringIO()
    p = LinePrinter(out)
    p.record({"type": "tick", "run": "r1", "n": 2, "t": 0.2, "changes": [[2, "INVALID"]]}, s)
    assert "HALTED    leaf 0.0" in out.getvalue()


def test_a_late_watcher_catches_up_from_the_snapshot_and_ignores_older_ticks():
    sink = SnapshotSink(publish=lambda text: None)
    live = sink.state
    for rec in [tree_record(),
                {"type": "tick", "run": "r1", "n": 1, "t": 0.1, "changes": [[0, "RUNNING"], [1, "RUNNING"], [2, "RUNNING"]]},
                {"type": "call_start", "run": "r1", "t": 0.1, "call_id": "c1", "target": "m.f", "node": 2,
                 "inputs": {}, "timeout": 5},
                {"type": "write", "run": "r1", "t": 0.2, "key": "x", "value": 7}]:
        sink.write("any", json.dumps(rec))
    late = WatchState()
    late.apply(tree_record())
    late.apply(json.loads(json.dumps(live.snapshot())))
    assert late.caught_up and late.label(2) == "RUNNING" and late.blackboard == {"x": 7}
    assert list(late.pending) == ["c1"] and late.pending["c1"]["timeout"] == 5
    late.apply({"type": "tick", "run": "r1", "n": 1, "t": 0.1, "changes": [[2, "FAILURE"]]})  # already in it
    assert late.label(2) == "RUNNING"
    late.apply({"type": "tick", "run": "r1", "n": 2, "t": 0.3, "changes": [[2, "SUCCESS"]]})
    assert late.label(2) == "SUCCESS"
    late.apply({"type": "tick", "run": "other", "n": 9, "t": 0.3, "changes": [[2, "FAILURE"]]})
    assert late.label(2) == "SUCCESS"
    late.apply_text("not json {")  # ignored, never raises
    late.apply({"type": "tick", "run": "r1", "n": 3, "changes": [["bad"]]})
    assert late.label(2) == "SUCCESS"


def test_a_long_tree_folds_then_windows_around_the_running_branch():
    s = WatchState()
    s.apply(tree_record(leaves=6, groups=4))  # 29 nodes
    s.apply({"type": "tick", "run": "r1", "n": 1, "t": 0.1,
             "changes": [[0, "RUNNING"], [1, "SUCCESS"], [8, "SUCCESS"], [15, "RUNNING"], [19, "RUNNING"]]})
    folded = [t.plain for t in tree_lines(s, 12)]
    assert len(folded) <= 12
    assert any("group 0" in line and "(+6 folded)" in line for line in folded)
    assert any("leaf 2.3" in line and "RUNNING" in line for line in folded)
    tiny = [t.plain for t in tree_lines(s, 5)]
    assert len(tiny) <= 5 and any("leaf 2.3" in line for line in tiny) and "more" in tiny[0] + tiny[-1]


def test_render_fits_the_terminal_and_cuts_long_lines():
    s = WatchState()
    s.apply(tree_record(leaves=6, groups=4))
    s.apply({"type": "write", "run": "r1", "t": 0.2, "key": "note", "value": "x" * 500})
    for k in range(30):
        s.apply({"type": "call_end", "run": "r1", "t": k, "call_id": "c%d" % k, "target": "m.f",
                 "status": "succeeded", "duration": 0.1})
    text = shown(render(s, 80, 24))
    lines = text.rstrip("\n").split("\n")
    assert len(lines) <= 24 and all(len(line) <= 80 for line in lines)
    assert "call log (" in text and "tree blackboard" in text and "pending calls: none" in text


def test_records_before_the_tree_are_kept_until_it_comes():
    sink = SnapshotSink(publish=lambda text: None)
    sink.write("tree", json.dumps(tree_record()))
    sink.write("status", json.dumps({"type": "tick", "run": "r1", "n": 1, "t": 0.1, "changes": [[0, "RUNNING"], [2, "RUNNING"]]}))
    late = WatchState()
    late.apply(json.loads(json.dumps(sink.state.snapshot())))  # the snapshot topic answered first
    assert not late.nodes
    late.apply(tree_record())
    assert late.caught_up and late.label(2) == "RUNNING"


def test_a_snapshot_held_back_by_the_interval_is_published_when_it_ends():
    """The engine may not tick again for a long time (a long call runs): the latched snapshot
    must catch up with the last tick anyway, not stay at the one before."""
    import threading

    published = []
    got = threading.Event()

    def publish(text):
        published.append(json.loads(text))
        got.set()

    sink = SnapshotSink(publish=publish, interval=0.2)
    sink.write("tree", json.dumps(tree_record()))
    sink.flush()                                    # published at once: nothing before it
    assert [p["n"] for p in published] == [0]
    got.clear()
    sink.write("tick", json.dumps({"type": "tick", "run": "r1", "n": 1, "t": 0.1, "changes": [[2, "RUNNING"]]}))
    sink.flush()                                    # too soon: held back...
    assert [p["n"] for p in published] == [0]
    assert got.wait(10)                             # ...and published when the interval ends
    assert [p["n"] for p in published] == [0, 1] and published[-1]["status"]["2"] == "RUNNING"
    sink.close()
    assert published[-1]["n"] == 1 and len(published) == 3


def test_notices_and_control_answers_show_beside_module_events_and_survive_a_snapshot():
    sink = SnapshotSink(publish=lambda text: None)
    live = sink.state
    records = [tree_record(),
               {"type": "event", "run": "r1", "t": 0.5, "module": "people", "event": "lostPerson",
                "params": {"name": "Ana"}},
               {"type": "notice", "run": "r1", "t": 1.0, "what": "master_down",
                "text": "the ROS master at http://robot:11311/ does not answer"},
               {"type": "control", "run": "r1", "t": 1.5, "command": "force", "ok": False, "by": "/op",
                "args": {"node": "leaf 0.1", "outcome": "MAYBE"}, "answer": "an outcome is SUCCESS or FAILURE"}]
    out = io.StringIO()
    printer = LinePrinter(out)
    for rec in records:
        live.apply(rec)
        printer.record(rec, live)
    lines = out.getvalue()
    assert "event     people.lostPerson {\"name\":\"Ana\"}" in lines
    assert "[  1.000s] notice    the ROS master at http://robot:11311/ does not answer" in lines
    assert ("[  1.500s] control   force 'leaf 0.1' MAYBE by /op: refused: an outcome is SUCCESS or FAILURE"
            in lines)
    late = WatchState()
    late.apply(tree_record())
    late.apply(live.snapshot())
    text = shown(render(late, 120, 40))
    assert "people.lostPerson" in text and "does not answer" in text and "refused: an outcome" in text


def selector_record(run="r1"):
    """announce, then a selector: 'look for it' fails, 'ask a person' runs; 'never' is not ticked."""
    nodes = [{"id": 0, "parent": None, "kind": "sequence", "shape": "sequence", "name": "find the apple"},
             {"id": 1, "parent": 0, "kind": "call", "shape": "leaf", "name": "announce"},
             {"id": 2, "parent": 0, "kind": "selector", "shape": "selector", "name": "find it"},
             {"id": 3, "parent": 2, "kind": "call", "shape": "leaf", "name": "look for it"},
             {"id": 4, "parent": 2, "kind": "call", "shape": "leaf", "name": "ask a person"},
             {"id": 5, "parent": 0, "kind": "call", "shape": "leaf", "name": "never"}]
    return {"v": 1, "type": "tree", "run": run, "t": 0.0, "name": "ask_around", "blackboard": {}, "nodes": nodes}


SELECTOR_RUN = [
    {"type": "tick", "run": "r1", "n": 1, "t": 0.1, "changes": [[1, "RUNNING"], [0, "RUNNING"]]},
    {"type": "tick", "run": "r1", "n": 2, "t": 0.2, "changes": [[1, "SUCCESS"], [3, "RUNNING"], [2, "RUNNING"]]},
    {"type": "tick", "run": "r1", "n": 3, "t": 0.3,
     "changes": [[3, "FAILURE", "vision.find_object failed: not seen"], [4, "RUNNING"]]},
    # py_trees' selector (with memory) clears the children before the one it runs, a tick later
    {"type": "tick", "run": "r1", "n": 4, "t": 0.4, "changes": [[3, "INVALID"]]},
]


def test_a_node_reset_after_its_outcome_shows_it_faded_not_as_never_ticked():
    s = WatchState()
    s.apply(selector_record())
    for rec in SELECTOR_RUN:
        s.apply(rec)
    assert s.label(3) == "was FAILURE" and s.label(4) == "RUNNING" and s.label(5) == ""
    assert s.label(1) == "SUCCESS"
    text = shown(render(s, 100, 30))
    assert "x look for it  was FAILURE  vision.find_object failed: not seen" in text
    assert "- never" in [line.strip() for line in text.split("\n")]  # never ticked: no label
    # a late watcher gets it from the snapshot; the page's JSON has it
    late = WatchState()
    late.apply(selector_record())
    late.apply(json.loads(json.dumps(s.snapshot())))
    assert late.label(3) == "was FAILURE" and late.label(5) == "" and late.feedback[3].startswith("vision")
    assert s.view()["last"] == {"3": "FAILURE"}
    # Ctrl-C: the run stops the tree; the running leaf is HALTED, the finished ones keep their outcome
    s.apply({"type": "tick", "run": "r1", "n": 5, "t": 0.5,
             "changes": [[4, "INVALID"], [2, "INVALID"], [1, "INVALID"], [0, "INVALID"]]})
    assert s.label(4) == "HALTED" and s.label(2) == "HALTED" and s.label(1) == "was SUCCESS"
    assert s.label(3) == "was FAILURE" and s.label(5) == ""
    text = shown(render(s, 100, 30))
    assert "+ announce  was SUCCESS" in text and "~ ask a person  HALTED" in text and "- never" in text
    # ticked again (a retry, a repeat): its live status wins, and a new outcome replaces the old one
    s.apply({"type": "tick", "run": "r1", "n": 6, "t": 0.6, "changes": [[3, "RUNNING"]]})
    assert s.label(3) == "RUNNING" and not s.feedback[3]
    s.apply({"type": "tick", "run": "r1", "n": 7, "t": 0.7, "changes": [[3, "SUCCESS"], [3, "INVALID"]]})
    assert s.label(3) == "was SUCCESS"


def test_the_line_printer_prints_each_outcome_once_and_no_line_for_a_reset():
    """The printer's lines are a log: the failure has its line when it happens; the reset a tick
    later is no new outcome (a line per reset would double a selector's or a repeat's output)."""
    s = WatchState()
    out = io.StringIO()
    printer = LinePrinter(out)
    for rec in [selector_record()] + SELECTOR_RUN:
        s.apply(rec)
        printer.record(rec, s)
    text = out.getvalue()
    assert "FAILURE   look for it (vision.find_object failed: not seen)" in text
    assert text.count("look for it") == 2  # RUNNING, FAILURE


def test_the_run_view_is_titled_for_the_run_and_its_clock_moves_between_records():
    """``bmtree run`` shows the view as ``bmtree run TREE``; a long call makes no record until it
    ends, so the header's clock is the wall-clock-advanced time, like the pending call's elapsed."""
    s = WatchState()
    s.apply(selector_record())
    for rec in SELECTOR_RUN:
        s.apply(rec)
    s.apply({"type": "call_start", "run": "r1", "t": 0.3, "call_id": "c1", "target": "navigation.go_to",
             "node": 4, "inputs": {"place": "kitchen"}, "timeout": 20})
    head = shown(render(s, 100, 30, now=2.9, title="bmtree run")).split("\n")
    assert head[0].startswith("bmtree run ask_around  t=2.9s  tick 4"), head[0]
    assert any("navigation.go_to" in line and "2.6s / 20s" in line for line in head)
    assert shown(render(s, 100, 30)).startswith("bmtree watch ask_around  t=0.4s")
    s.apply({"type": "end", "run": "r1", "t": 3.0, "status": "SUCCESS", "duration": 3.0, "ticks": 5})
    assert "t=3.0s" in shown(render(s, 100, 30, now=9.0, title="bmtree run")).split("\n")[0]  # ended: its time
    waiting = WatchState()
    assert "t=0.0s" in shown(render(waiting, 100, 30, now=5.0)).split("\n")[0]  # no run yet: no clock


def long_run(keys=8, calls=7):
    """Like the audit's long_errand at 200x50: a 19-node tree, one pending call, some keys and calls."""
    s = WatchState()
    s.apply(dict(tree_record(leaves=8, groups=2), blackboard={"key%d" % k: k for k in range(keys)}))
    s.apply({"type": "tick", "run": "r1", "n": 1, "t": 0.1, "changes": [[0, "RUNNING"], [1, "SUCCESS"], [10, "RUNNING"],
                                                                       [11, "RUNNING"]]})
    s.apply({"type": "call_start", "run": "r1", "t": 0.1, "call_id": "p", "target": "navigation.go_to", "node": 11,
             "inputs": {}, "timeout": 30})
    for k in range(calls):
        s.apply({"type": "call_end", "run": "r1", "t": 0.01 * k, "call_id": "c%d" % k, "target": "speech.say",
                 "status": "succeeded", "duration": 0.001})
    return s


def test_lines_the_tree_leaves_unused_go_to_the_panels_it_would_cut():
    s = long_run(keys=8, calls=7)
    text = shown(render(s, 200, 50, "q quit"))
    assert " of " not in text, text  # nothing cut: "tree blackboard (6 of 8)" had 9 empty lines below
    assert all("key%d = %d" % (k, k) in text for k in range(8)) and text.count("speech.say") == 7
    # crowded: whatever is cut, the screen is full (no line left empty) and fits
    s = long_run(keys=30, calls=40)
    lines = shown(render(s, 200, 50, "q quit")).rstrip("\n").split("\n")
    assert len(lines) == 50 and all(line.strip() for line in lines), "\n".join(lines)
    assert lines[-1] == "q quit"
    cut = [line for line in lines if " of " in line]
    assert any(line.startswith("tree blackboard (") for line in cut) and any(line.startswith("call log (") for line in cut)
    small = shown(render(s, 80, 24, "q quit")).rstrip("\n").split("\n")
    assert len(small) == 24 and all(len(line) <= 80 for line in small)


def test_a_cut_blackboard_shows_the_most_recently_written_keys():
    s = long_run(keys=30, calls=40)
    for k, key in enumerate(["key3", "zeta", "alpha"]):  # newest last; "key3" existed, "zeta"/"alpha" are new
        s.apply({"type": "write", "run": "r1", "t": 1.0 + k, "key": key, "value": "new %d" % k})
    text = shown(render(s, 80, 24))
    heading = next(line for line in text.split("\n") if line.startswith("tree blackboard ("))
    assert heading.endswith(", last written)"), heading
    shown_keys = [line.split(" = ")[0].strip() for line in text.split("\n") if " = " in line]
    assert shown_keys and set(shown_keys) <= {"key3", "zeta", "alpha", "key29", "key28"}, shown_keys
    assert shown_keys == sorted(shown_keys) and "alpha" in shown_keys  # newest kept, shown in name order
    # a late watcher keeps the order of the writes through the snapshot
    late = WatchState()
    late.apply(dict(tree_record(leaves=8, groups=2), blackboard={"key%d" % k: k for k in range(30)}))
    late.apply(json.loads(json.dumps(s.snapshot())))
    assert late.written[-3:] == ["key3", "zeta", "alpha"] and late.blackboard["key3"] == "new 0"
    # the same run's tree again (latched, re-sent) does not undo a write
    late.apply(dict(tree_record(leaves=8, groups=2), blackboard={"key%d" % k: k for k in range(30)}))
    assert late.blackboard["key3"] == "new 0" and late.written[-1] == "alpha"


def test_the_latched_end_that_overtakes_the_last_ticks_is_printed_after_them():
    """The end is latched and written at once, the ticks are queued on another topic: the end could
    arrive first, and `watch --plain` printed it before the tree's last changes."""
    s = WatchState()
    out = io.StringIO()
    p = LinePrinter(out)

    def take(rec):
        s.apply(rec)
        p.record(rec, s)

    take(tree_record())
    take({"type": "tick", "run": "r1", "n": 1, "t": 0.1, "changes": [[0, "RUNNING"], [2, "RUNNING"]]})
    take({"type": "end", "run": "r1", "t": 0.2, "status": "FAILURE", "reason": "leaf 0.0 failed", "ticks": 2})
    take({"type": "tick", "run": "r1", "n": 2, "t": 0.2, "changes": [[2, "FAILURE"], [0, "FAILURE"]]})
    lines = out.getvalue().splitlines()
    assert [line[11:] for line in lines[-3:]] == ["FAILURE   leaf 0.0", "FAILURE   root",
                                                  "end       FAILURE: leaf 0.0 failed"], lines
    # an end whose last tick never comes is printed when the watch finishes
    p2 = LinePrinter(out)
    p2.record({"type": "end", "run": "r1", "t": 0.3, "status": "SUCCESS", "ticks": 9}, s)
    before = out.getvalue()
    p2.finish()
    assert "end       SUCCESS" not in before.splitlines()[-1] and out.getvalue().endswith("end       SUCCESS\n")


def test_records_that_come_before_the_tree_are_printed_with_their_names_after_it():
    """Topics are not ordered among them: a watch that joined (or came back after a link drop) got ticks
    before the tree, and `watch --plain` printed `RUNNING   1`, a node's id, before `run …`."""
    s = WatchState()
    out = io.StringIO()
    p = LinePrinter(out)

    def take(rec):
        s.apply(rec)
        p.record(rec, s)

    take({"type": "tick", "run": "r1", "n": 1, "t": 0.1, "changes": [[0, "RUNNING"], [2, "RUNNING"]]})
    take({"type": "call_start", "run": "r1", "t": 0.1, "call_id": "c1", "target": "m.f", "inputs": {"x": 1}})
    assert out.getvalue() == ""
    take(tree_record())
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("run r1: ") and [line[11:] for line in lines[1:]] == [
        "RUNNING   root", "RUNNING   leaf 0.0", 'call      m.f {"x":1}'], lines
