"""What the run's control answers say of single nodes, shown on them: a breakpoint set (``●``), a node a
breakpoint holds (``RUNNING (held at breakpoint)``, not a working node, until the run goes on), an outcome
forced by control (``SUCCESS (forced)``), in the terminal, the ``--plain`` lines and the page's data; and
how long a running ``wait`` has waited. The records are as a ``--control`` run sends them (no ROS)."""
from __future__ import annotations

import io
import json

from coordinator.watchstate import WatchState, fill
from coordinator.watchview import LinePrinter, tree_lines

RUN = "20261126-180000-abcdef"
NODES = [(0, None, "sequence", "errand"), (1, 0, "call", "go to the kitchen"), (2, 0, "call", "arrived"),
         (3, 0, "wait", "wait 6s"), (4, 0, "call", "done"), (5, 0, "call", "speech.say"), (6, 0, "call", "speech.say")]


def tree():
    return {"v": 1, "type": "tree", "run": RUN, "t": 0.0, "name": "go", "control": True, "blackboard": {},
            "nodes": [{"id": i, "parent": p, "kind": k, "name": n, "shape": "sequence" if k == "sequence" else "leaf"}
                      for i, p, k, n in NODES]}


def tick(n, t, changes):
    return {"v": 1, "type": "tick", "run": RUN, "n": n, "t": t, "changes": changes}


def control(t, command, ok=True, paused=False, by="/bmtree_control_1", answer="", **args):
    return {"v": 1, "type": "control", "run": RUN, "t": t, "command": command, "args": args, "ok": ok,
            "answer": answer, "by": by, "paused": paused}


def line(state, name, now=None):
    return next(t.plain for t in tree_lines(state, 40, now) if name in t.plain)


def feed(state, out, records):
    p = LinePrinter(out)
    for rec in records:
        state.apply(rec)
        p.record(rec, state)


def test_a_breakpoint_is_marked_and_the_node_it_holds_is_not_shown_working():
    s, out = WatchState(), io.StringIO()
    feed(s, out, [tree(), tick(1, 0.1, [[1, "RUNNING"], [0, "RUNNING"]]),
                  control(1.0, "break", answer="will pause before 'arrived' starts", node="arrived"),
                  control(1.5, "pause", paused=True)])
    assert line(s, "arrived") == "  - ● arrived"
    # the breakpoint holds it: the tick says RUNNING (its parent waits), the control answer says why
    # (the tick may come first: another topic)
    feed(s, out, [tick(2, 5.0, [[1, "SUCCESS"], [2, "RUNNING"]]),
                  control(5.0, "breakpoint", by="bmtree", paused=True, answer="paused before 'arrived' starts",
                          node="arrived")])
    assert line(s, "arrived") == "  * ● arrived  RUNNING (held at breakpoint)"
    assert s.progress(2) is None
    view = json.loads(json.dumps(s.view()))
    assert view["notes"] == {"2": "held at breakpoint"} and view["breaks"] == [2] and view["words"]["2"] == "RUNNING"
    # a late watch knows it from the snapshot
    late = WatchState()
    late.apply(tree())
    late.apply(json.loads(json.dumps(s.snapshot())))
    assert line(late, "arrived") == "  * ● arrived  RUNNING (held at breakpoint)"
    # resumed: it starts at the next tick (the tick may come before the control answer), a working node then
    s.apply(tick(3, 9.2, [[5, "RUNNING"]]))
    assert line(s, "arrived") == "  * ● arrived  RUNNING (held at breakpoint)"   # (a tick before the resume)
    s.apply(tick(4, 9.6, [[6, "RUNNING"]]))
    s.apply(control(9.5, "resume", answer="resumed"))
    assert line(s, "arrived") == "  * ● arrived  RUNNING" and s.view()["notes"] == {}
    s.apply(control(10.0, "clear", answer="breakpoint on 'arrived' cleared", node="arrived"))
    assert line(s, "arrived") == "  * arrived  RUNNING"


def test_a_step_lets_the_held_node_start_and_an_older_runs_snapshot_says_it_from_its_control_answers():
    s = WatchState()
    for rec in (tree(), tick(1, 0.1, [[0, "RUNNING"], [2, "RUNNING"]]),
                control(0.1, "breakpoint", by="bmtree", paused=True, answer="paused before 'arrived' starts",
                        node="arrived")):
        s.apply(rec)
    old = json.loads(json.dumps(s.snapshot()))
    for key in ("breaks", "held", "forcing", "forced", "since", "attempts", "waits", "changed_t"):
        del old[key]   # a snapshot of a bmtree before them
    late = WatchState()
    late.apply(tree())
    late.apply(old)
    assert late.note(2) == "held at breakpoint" and 2 in late.breaks
    for state in (s, late):
        state.apply(control(3.0, "step", paused=True, answer="one tick"))
        assert state.note(2) == "held at breakpoint"
        state.apply(tick(2, 3.01, [[3, "RUNNING"]]))
        assert state.note(2) == ""


def test_a_forced_outcome_is_marked_whichever_comes_first_and_until_the_node_runs_again():
    s, out = WatchState(), io.StringIO()
    feed(s, out, [tree(), tick(1, 0.1, [[0, "RUNNING"], [4, "RUNNING"]]),
                  control(1.0, "force", answer="'done' will end in SUCCESS the next time it is ticked", node="done",
                          outcome="SUCCESS"),
                  tick(2, 1.01, [[4, "SUCCESS"], [3, "RUNNING"]])])
    assert line(s, "done") == "  + done  SUCCESS (forced)"
    assert "[  1.010s] SUCCESS   done (forced)" in out.getvalue()
    assert s.view()["notes"] == {"4": "forced"}
    # its tick before the control answer (another topic)
    s2 = WatchState()
    for rec in (tree(), tick(1, 0.1, [[0, "RUNNING"], [1, "RUNNING"]]),
                tick(2, 1.01, [[1, "FAILURE", "forced to FAILURE by control"], [0, "FAILURE"]]),
                control(1.0, "force", answer="'go to the kitchen' will end in FAILURE ...", node="go to the kitchen",
                        outcome="FAILURE")):
        s2.apply(rec)
    assert line(s2, "go to the kitchen") == "  x go to the kitchen  FAILURE (forced)  forced to FAILURE by control"
    # reset by py_trees, still its forced outcome; run again, its next outcome is its own
    s.apply(tick(3, 2.0, [[4, "INVALID"]]))
    assert line(s, "done") == "  + done  was SUCCESS (forced)"
    s.apply(tick(4, 3.0, [[4, "RUNNING"]]))
    s.apply(tick(5, 4.0, [[4, "SUCCESS"]]))
    assert line(s, "done") == "  + done  SUCCESS"


def test_a_shared_name_is_marked_on_the_node_its_id_names_and_a_wait_says_how_long_it_has_waited():
    s = WatchState()
    s.apply(tree())
    s.apply(control(0.5, "break", answer="will pause before 'speech.say@6' starts", node="speech.say@6"))
    assert s.breaks == {6}
    s.apply(control(0.6, "clear", answer="breakpoint on 'speech.say' cleared", node="speech.say"))
    assert s.breaks == set()
    s.apply(tick(1, 2.0, [[0, "RUNNING"], [3, "RUNNING"]]))
    assert line(s, "wait 6s", now=5.25) == "  * wait 6s  RUNNING  waited 3.2 s"
    assert fill(s.view()["progress"]["3"], 4.0) == "waited 2.0 s"
    assert "progress" not in s.snapshot() and s.snapshot()["since"] == {"0": 2.0, "3": 2.0}
