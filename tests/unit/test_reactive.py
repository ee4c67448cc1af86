"""Reactive composites (``memory: false``): a child that can be RUNNING before another that can is a check
error (it would restart that one every other tick: the audit's ~2,000 go_to calls in 3.5 s), and the
README's two ways to react while an action runs, run with the test kit."""
from __future__ import annotations

from typing import List

import pytest

from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from coordinator.testing import succeed
from modules.definition import load_definitions, parse_definition
from modules.sim import SIM_DIR
from tests.conftest import documented_reactions, one_file_trees

BATTERY = parse_definition({
    "Basic Module": "battery",
    "Brief Description": "The robot's battery.",
    "Hardware Required": [],
    "Functions": [
        {"Name": "level", "Exec-condition": "", "Description": "The charge left.", "Input-params": [],
         "Output-params": [{"Name": "percentage", "Data-type": "std_msgs/Float64", "Description": "0-100"}],
         "Concurrent": True},
    ],
    "Events": [
        {"Name": "low", "Description": "The charge fell below 20 %.",
         "Event-params": [{"Name": "percentage", "Data-type": "std_msgs/Float64", "Description": "0-100"}]},
    ],
}, "battery.json")
DEFS = dict(load_definitions([SIM_DIR]), battery=BATTERY)


@pytest.fixture
def tree(tmp_path, bmtree_tree):
    return one_file_trees(tmp_path, bmtree_tree, DEFS)


def errors(tmp_path, root: str, files=None) -> List[str]:
    for name, text in (files or {}).items():
        (tmp_path / name).write_text(text)
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n" + root)
    try:
        load_tree(str(path), DEFS)
    except TreeErrors as exc:
        return [str(e).replace(str(tmp_path) + "/", "") for e in exc.errors]
    return []


AUDIT = """  sequence:
    memory: false
    children:
      - {call: battery.level, outputs: {percentage: battery}}
      - check: 'battery > 20'
      - {call: navigation.go_to, name: drive, inputs: {place: kitchen}}
"""


def test_a_call_before_the_running_action_of_a_reactive_sequence_is_an_error_naming_both(tmp_path):
    assert errors(tmp_path, AUDIT) == [
        "t.yaml:6:10: sequence with memory: false (line 3) ticks its children again from the first on every tick: "
        "the call 'battery.level' at line 6 can be RUNNING (a call waits for its module's answer), so on the tick "
        "after it succeeds it starts again and halts the call 'drive' at line 8, which can be RUNNING too: that one "
        "is restarted on every other tick and never finishes. A memory: false sequence may hold one child that takes "
        "more than one tick, after all the others: before it, write only nodes that end in the tick they start "
        "(check, set, fail); make the call before this sequence (a sequence with memory: true, the default), or "
        "poll it beside the action in a parallel (see 'Reacting while an action runs' in trees/README.md)"]


def test_the_kit_shows_the_restarts_the_check_now_refuses(tmp_path, bmtree_tree):
    """What the audit's tree did (its memory: true twin loads; the run is built by hand from it): every
    other tick a new battery.level call, and the drive halted, at one simulated instant."""
    (tmp_path / "t.yaml").write_text("format: 1\nroot:\n" + AUDIT.replace("memory: false", "memory: true"))
    t = bmtree_tree(str(tmp_path / "t.yaml"), definitions=DEFS)
    t.tree.root.spec = type(t.tree.root.spec)(memory=False)
    t.mocks["battery.level"].succeed(percentage=80)
    ticks = []
    run = t.run(stop_when=lambda: "enough" if ticks.append(1) or len(ticks) > 20 else "")
    assert run.failed and run.duration == 0.0
    assert [c.status for c in run.calls("navigation.go_to")][:4] == ["halted"] * 4
    assert len(run.calls("battery.level")) >= 5


@pytest.mark.parametrize("root,line,said", [
    # a reactive selector: the first fallback, started again, halts the second
    ("  selector:\n    memory: false\n    children:\n      - call: battery.level\n"
     "      - call: navigation.go_to\n        inputs: {place: dock}\n",
     "t.yaml:6:9: selector with memory: false (line 3)",
     "the call 'battery.level' at line 6 can be RUNNING (a call waits for its module's answer), so once it has "
     "failed and the call 'navigation.go_to' at line 7 runs, it starts again and halts that one"),
    # a retry between attempts is RUNNING, even of a check
    ("  sequence:\n    memory: false\n    children:\n      - retry: 3\n        child: {check: 'true'}\n"
     "      - wait: 5\n",
     "t.yaml:6:9: sequence with memory: false (line 3)",
     "the retry 'retry x3' at line 6 can be RUNNING (a retry is RUNNING between its attempts), so on the tick "
     "after it succeeds it starts again and halts the wait 'wait 5s' at line 8"),
    # deeper down: the part that runs is named
    ("  sequence:\n    memory: false\n    children:\n      - sequence: [{check: 'true'}, {wait: 1}]\n"
     "        name: pause\n      - wait_event: battery.low\n",
     "t.yaml:6:9: sequence with memory: false (line 3)",
     "the sequence 'pause' at line 6 can be RUNNING (the wait 'wait 1s' at line 6: a wait waits its seconds), "
     "so on the tick after it succeeds it starts again and halts the wait_event 'battery.low' at line 8"),
])
def test_what_can_run_comes_from_the_kinds(tmp_path, root, line, said):
    (found,) = errors(tmp_path, root)
    assert found.startswith(line) and said in found, found


def test_an_include_that_can_run_is_named_with_its_part_in_the_other_file(tmp_path):
    sub = "format: 1\nroot:\n  call: battery.level\n"
    (found,) = errors(tmp_path, "  sequence:\n    memory: false\n    children:\n      - include: sub.yaml\n"
                                "      - wait: 2\n", {"sub.yaml": sub})
    assert ("the include 'sub' at line 6 can be RUNNING (the call 'battery.level' at sub.yaml:3: a call waits for "
            "its module's answer)") in found


@pytest.mark.parametrize("children", [
    "[{check: 'true'}, {set: {a: 1}}, {fail: nope}, {call: battery.level}]",   # instant nodes before the last
    "[{call: battery.level}, {check: 'true'}]",       # nothing runs after it: no restart
    "[{retry: 1, child: {check: 'true'}}, {repeat: 1, child: {set: {a: 1}}}, {wait: 0}, "
    "{for_each: [a], as: x, child: {check: 'true'}}, {inverter: {check: 'false'}}, {wait: 3}]",
    "[{parallel: [{check: 'true'}, {set: {b: 2}}]}, {switch: 'x', cases: {x: {set: {c: 1}}}}, {wait: 3}]",
])
def test_nodes_that_end_in_their_tick_may_come_first(tmp_path, children):
    assert errors(tmp_path, "  sequence:\n    memory: false\n    children: %s\n" % children) == []
    assert errors(tmp_path, "  sequence:\n    children: [{call: battery.level}, {wait: 3}]\n") == []   # memory


# the README's "Reacting while an action runs" -----------------------------------------------------------
EVENT, POLL = documented_reactions()


def test_an_event_beside_the_action_halts_it(tree):
    t = tree(EVENT)
    t.mocks["navigation.go_to"].succeed(delay=30, success=True)
    t.mocks.event(4.0, "battery.low", percentage=15)
    run = t.run()
    assert run.failed and run.reason == "fail: battery low" and run.duration == pytest.approx(4.0)
    (drive,) = run.calls("navigation.go_to")
    assert drive.status == "halted"
    assert any(type(m).__name__ == "CancelRequest" for m in run.transport.sent)
    run = tree(EVENT).run()   # no event: the drive ends the parallel
    assert run.succeeded and [c.status for c in run.calls("navigation.go_to")] == ["succeeded"]


def test_a_polled_value_checked_beside_the_action_halts_it_once_false(tree):
    t = tree(POLL)
    t.mocks["battery.level"].script(*[succeed(percentage=p) for p in (80, 70, 60, 15)])
    t.mocks["navigation.go_to"].succeed(delay=30, success=True)
    run = t.run()
    assert run.failed and run.reason.startswith("check battery > 20: battery > 20 is false"), run.reason
    (drive,) = run.calls("navigation.go_to")   # started once, never restarted
    assert drive.status == "halted"
    assert len(run.calls("battery.level")) == 4 and run.duration == pytest.approx(2.0)


def test_the_polled_drive_ends_the_parallel_when_it_arrives(tree):
    t = tree(POLL)
    t.mocks["battery.level"].succeed(percentage=80)
    t.mocks["navigation.go_to"].succeed(delay=5.5, success=True)
    run = t.run()
    assert run.succeeded and run.duration == pytest.approx(5.5)
    assert [c.status for c in run.calls("navigation.go_to")] == ["succeeded"]
    assert 6 <= len(run.calls("battery.level")) <= 8


def test_a_reactive_selector_may_give_priority_to_a_guarded_branch(tmp_path):
    """ReactiveFallback's use: a higher priority that fails at once while its check is false, and takes over
    (halting the patrol on purpose) once it holds."""
    root = """  sequence:
    - set: {battery: 50}
    - selector:
        memory: false
        children:
          - sequence: [{check: 'battery < 20'}, {call: navigation.go_to, inputs: {place: dock}}]
          - call: navigation.go_to
            inputs: {place: kitchen}
"""
    assert errors(tmp_path, root) == []
    # the same guard in a reactive sequence restarts the later child after it succeeded: still an error
    (found,) = errors(tmp_path, root.replace("- selector:", "- sequence:"))
    assert found.startswith("t.yaml:8:13: sequence with memory: false (line 5)")


def test_a_selector_child_that_cannot_fail_is_said_to_keep_the_later_ones_from_running(tmp_path):
    """A wait_event without timeout never fails: the selector's later child never runs at all (not "once it
    has failed"); with a timeout it can fail, and the restart is the problem."""
    root = ("  selector:\n    memory: false\n    children:\n      - wait_event: battery.low\n"
            "      - call: navigation.go_to\n        inputs: {place: dock}\n")
    assert errors(tmp_path, root) == [
        "t.yaml:6:9: selector with memory: false (line 3) tries its next child only after one failed: the "
        "wait_event 'battery.low' at line 6 can be RUNNING (a wait_event waits for its event) and cannot fail (no "
        "timeout: it waits until the event comes), so the call 'navigation.go_to' at line 7 never runs. To run "
        "both at once and stop at the first that ends, write a parallel with policy: one; to give up waiting after "
        "a while, give the wait_event a timeout: (see 'Reacting while an action runs' in trees/README.md)"]
    (found,) = errors(tmp_path, root.replace("wait_event: battery.low", "{wait_event: battery.low, timeout: 5}"))
    assert "so once it has failed and the call 'navigation.go_to' at line 7 runs" in found, found
    (found,) = errors(tmp_path, root.replace("wait_event: battery.low", "{force_success: {call: battery.level}}"))
    assert "and cannot fail (force_success always succeeds), so the call 'navigation.go_to' at line 7 never " \
           "runs. To run both at once and stop at the first that ends, write a parallel with policy: one (see " in found
