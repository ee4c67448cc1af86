"""WatchState and the terminal view from hand-made run-stream records: catch-up from a
snapshot, halted leaves, folding around the running branch, lines cut to the width."""
from __future__ import annotations

import io
import json

from rich.console import Console

from coordinator.watchstate import SnapshotSink, WatchState
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
