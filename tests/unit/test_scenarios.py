"""``bmtree test``: declarative YAML scenarios."""
from __future__ import annotations

import io
import os
import re
import subprocess
import sys

import pytest

from coordinator.cli import main as bmtree
from coordinator.testing.scenario import (
    DEFAULT_MAX_TICKS,
    DEFAULT_MAX_TICKS_PER_INSTANT,
    TickGuard,
    run_scenario_file,
)
from tests.conftest import ROOT, TREES

SCENARIOS = os.path.join(ROOT, "tests", "scenarios", "find_apple.scenarios.yaml")


def test_shipped_scenarios_pass(capsys):
    assert bmtree(["test", SCENARIOS]) == 0
    out = capsys.readouterr().out
    assert out.count("PASS") == 2 and out.rstrip().endswith("2 passed, 0 failed")


def test_failing_expectations_are_explained(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n  - name: wrong\n    mocks:\n      vision.find_object: {fail: blind}\n"
                 "    expect:\n      status: success\n      calls: [speech.say, navigation.go_to: {place: attic}]\n"
                 % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", str(f)]) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "status FAILURE, expected SUCCESS (look for the object: vision.find_object failed: " \
        "blind) at %s:19:9 in search_room(room=\"bedroom\", object=\"apple\")\n" % os.path.join(
            os.path.relpath(TREES), "search_room.yaml") in out, out
    assert "input place is 'living_room', expected 'attic'" in out and "0 passed, 1 failed" in out


def test_invalid_scenario_file(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n  - name: x\n    mokcs: {}\n" % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", str(f)]) == 2
    assert "s.yaml:4:5: unknown scenario key 'mokcs' (did you mean 'mocks'?)" in capsys.readouterr().err
    f.write_text("tree: %s\nscenarios:\n  - mocks:\n      speech.say: {succeed: {volume: 3}}\n"
                 % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", str(f)]) == 2
    assert "s.yaml:4:30: speech.say has no output 'volume' (its outputs: success)" in capsys.readouterr().err


# every scenario ends ------------------------------------------------------------------------------
# A loop whose runs end at once, started again at once for (nearly) ever: the simulated clock never
# moves. (A selector with memory: false over a repeat and a for_each that restart one another was the
# example before: bmtree check reports that one now, see coordinator/reactive.py.)
LIVELOCK = """format: 1
name: livelock
root:
  repeat: 1000000000
  child:
    sequence:
      - set: {x: a}
      - %s
"""


def _files(tmp_path, scenarios, leaf="set: {y: 1}"):
    (tmp_path / "livelock.yaml").write_text(LIVELOCK % leaf)
    f = tmp_path / "s.yaml"
    f.write_text("tree: livelock.yaml\nscenarios:\n" + scenarios)
    return str(f)


def test_a_livelock_at_one_simulated_instant_is_a_fail_naming_the_limit(tmp_path):
    path = _files(tmp_path, "  - name: spins\n    expect: {status: failure}\n")
    # a subprocess with a timeout: without the guard this run never ends
    out = subprocess.run([sys.executable, "-m", "coordinator", "test", path], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "Traceback" not in out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("FAIL %s: spins" % path)  # even though FAILURE was expected
    assert lines[1] == ("    stopped after %d ticks at simulated time 0 s without the clock advancing "
                        "(max_ticks_per_instant): a livelock, loops restarting at once? Raise the scenario key "
                        "'max_ticks_per_instant' if this tree needs more" % DEFAULT_MAX_TICKS_PER_INSTANT)
    assert lines[-1] == "0 passed, 1 failed"


def test_a_livelock_in_which_the_clock_creeps_hits_max_ticks(tmp_path):
    path = _files(tmp_path, "  - name: creeps\n    max_ticks: 2000\n", leaf="wait: 0.001")
    out = io.StringIO()
    assert run_scenario_file(path, out=out) == [False]
    assert "    stopped after 2000 ticks (max_ticks) at simulated time " in out.getvalue()
    assert "raise the scenario key 'max_ticks' if this tree needs more" in out.getvalue()
    assert DEFAULT_MAX_TICKS >= 100000


def test_the_tick_limits_are_scenario_keys(tmp_path):
    path = _files(tmp_path, "  - name: a few\n    max_ticks_per_instant: 50\n")
    out = io.StringIO()
    assert run_scenario_file(path, out=out) == [False]
    assert "stopped after 50 ticks at simulated time 0 s" in out.getvalue()


def test_many_ticks_at_one_instant_that_end_pass(tmp_path):
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n  for_each: %s\n  as: i\n  child:\n"
                    "    repeat: 90\n    child:\n      set: {y: $i}\n" % list(range(100)))
    f = tmp_path / "s.yaml"
    f.write_text("tree: t.yaml\nscenarios:\n  - name: 9000 ticks at 0 s\n    expect: {blackboard: {y: 99}}\n")
    out = io.StringIO()
    assert run_scenario_file(str(f), out=out) == [True], out.getvalue()
    f.write_text("tree: t.yaml\nscenarios:\n  - name: 9000 ticks at 0 s\n    max_ticks: 1000\n")
    assert run_scenario_file(str(f), out=out) == [False]


def test_max_duration_default_and_given(tmp_path):
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n  wait: 5000\n")
    f = tmp_path / "s.yaml"
    f.write_text("tree: t.yaml\nscenarios:\n"
                 "  - name: default\n    expect: {status: failure}\n"
                 "  - name: given, stop expected\n    max_duration: 10\n    expect: {status: failure}\n"
                 "  - name: given, success expected\n    max_duration: 10\n"
                 "  - name: raised\n    max_duration: 6000\n")
    out = io.StringIO()
    assert run_scenario_file(str(f), out=out) == [False, True, False, True], out.getvalue()
    text = out.getvalue()
    assert ("    stopped after 3600 simulated seconds, the default max_duration: the tree did not end; set the "
            "scenario key 'max_duration' to raise the limit (or to expect the stop)\n") in text
    assert "    status FAILURE, expected SUCCESS (stopped after 10 s while 'wait 5000s' was running)\n" in text
    assert "    the run reached the scenario's max_duration (10 s of simulated time); raise it" in text


def test_tick_guard_leaves_a_run_that_ends_alone(sim_defs):
    from coordinator.testing import TreeTest

    test = TreeTest(os.path.join(TREES, "find_apple.yaml"), definitions=sim_defs)
    ticks = test.run().result.ticks
    guard = TickGuard(max_ticks=ticks, max_ticks_per_instant=ticks)  # the last tick ends the run
    assert test.run(observers=[guard], stop_when=guard).succeeded and guard.hit == ""
    guard = TickGuard(max_ticks=ticks - 1)
    run = test.run(observers=[guard], stop_when=guard)
    assert run.failed and run.result.ticks == ticks - 1 and "stopped after %d ticks (max_ticks)" % (ticks - 1) in guard.hit


# the whole file is checked before anything runs ---------------------------------------------------------
def test_an_empty_scenario_list_and_a_missing_tree_are_errors(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: nosuch.yaml\nscenarios: []\n")
    assert bmtree(["test", str(f)]) == 2
    err = capsys.readouterr().err
    assert "%s:1:7: tree %s: no such file" % (f, tmp_path / "nosuch.yaml") in err
    assert "%s:2:12: scenarios is empty: write at least one scenario" % f in err
    f.write_text("tree: nosuch.yaml\nscenarios:\n  - name: x\n")
    assert bmtree(["test", str(f)]) == 2
    assert "%s:1:7: tree %s: no such file" % (f, tmp_path / "nosuch.yaml") in capsys.readouterr().err


def test_an_invalid_tree_is_reported_even_without_scenarios(tmp_path, capsys):
    (tmp_path / "bad.yaml").write_text("format: 1\nroot:\n  call: speech.sya\n")
    f = tmp_path / "s.yaml"
    f.write_text("tree: bad.yaml\nscenarios: []\n")
    assert bmtree(["test", str(f)]) == 2
    err = capsys.readouterr().err
    assert "bad.yaml:3:9: module 'speech' has no function 'sya'" in err and "scenarios is empty" in err


def test_every_scenario_is_checked_before_the_first_runs(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n"
                 "  - name: fine\n"
                 "  - name: typo\n    inputs: {objet: book}\n"
                 "  - name: not a mapping\n    expect: success\n"
                 "  - name: bad status\n    expect: {status: sucess}\n"
                 "  - name: bad calls\n    expect: {calls: [speech.say, {a.b: 1}]}\n"
                 "  - name: limit\n    max_ticks: 0\n" % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", str(f)]) == 2
    captured = capsys.readouterr()
    assert "PASS" not in captured.out and "FAIL" not in captured.out
    assert captured.err.splitlines() == [
        "%s:5:14: the tree declares no input 'objet' (did you mean 'object'?) (its inputs: object, rooms)" % f,
        "%s:7:13: expect is a mapping with status, calls, blackboard, reason, duration" % f,
        "%s:9:22: status is success or failure, got 'sucess' (did you mean 'success'?)" % f,
        "%s:11:21: calls is a list of module.function or {module.function: {input: value}}" % f,
        "%s:13:16: max_ticks must be a whole number >= 1, got 0" % f]


def test_a_required_input_a_scenario_does_not_give(tmp_path, capsys):
    (tmp_path / "t.yaml").write_text("format: 1\ninputs:\n  who: {}\nroot:\n  call: speech.say\n"
                                     "  inputs: {text: $who}\n")
    f = tmp_path / "s.yaml"
    f.write_text("tree: t.yaml\nscenarios:\n  - name: x\n  - name: y\n    inputs: {who: Ana}\n")
    assert bmtree(["test", str(f)]) == 2
    assert capsys.readouterr().err.strip() == "%s:3:5: the tree needs the input who: give it in 'inputs'" % f


def test_the_format_page_shows_the_shipped_file_and_every_key(tmp_path):
    from coordinator.testing import scenario

    with open(os.path.join(ROOT, "docs", "scenarios.md"), encoding="utf-8") as fh:
        doc = fh.read()
    blocks = re.findall(r"```yaml\n(.*?)```", doc, re.S)
    with open(SCENARIOS, encoding="utf-8") as fh:
        assert blocks[0] == fh.read()
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n%s" % (os.path.join(TREES, "find_apple.yaml"), blocks[1]))
    out = io.StringIO()
    assert run_scenario_file(str(f), out=out) == [True], out.getvalue()
    from coordinator.testing import scenariomocks

    for key in scenario._SCENARIO_KEYS + scenario._EXPECT_KEYS + scenariomocks._EVENT_KEYS + (
            "tree", "scenarios") + scenariomocks._OUTCOME_KEYS:
        assert "| `%s` |" % key in doc, key
    for default in (scenario.DEFAULT_MAX_DURATION, scenario.DEFAULT_MAX_TICKS, scenario.DEFAULT_MAX_TICKS_PER_INSTANT):
        assert "| `%g` |" % default in doc


def test_a_scenario_file_is_read_with_the_tree_files_limits(tmp_path, capsys):
    from coordinator.cli import main

    bad = tmp_path / "bad.scenarios.yaml"
    bad.write_bytes(b"tree: x.yaml\nscenarios:\n  - name: a\n    inputs: {s: \"\xff\"}\n")
    assert main(["test", "/dev/zero"]) == 2  # a device: refused, not read for ever
    assert main(["test", str(bad), "/dev/zero"]) == 2
    out = capsys.readouterr()
    assert out.out.splitlines()[-1] == "0 passed, 0 failed, 2 scenario files are not valid (above)"
    err = out.err
    assert "/dev/zero:1:1: cannot read /dev/zero: not a regular file" in err
    assert "%s:4:18: not UTF-8 text: byte 0xff" % bad in err


@pytest.mark.parametrize("scenario, says", [
    ("  - name: a\n    events: [{event: vision.personSeen, at: .nan}]\n",
     "4:45: at must be a number of seconds >= 0, got nan"),
    ("  - name: a\n    events: [{event: vision.personSeen, at: .inf}]\n",
     "4:45: at must be a number of seconds >= 0, got inf"),
    ("  - name: a\n    events: [{event: vision.personSeen, params: {5: 1}}]\n",
     "4:49: params is a mapping of name: value"),
    ("  - name: a\n    mocks: {5: {succeed: {}}}\n", "4:13: mocks: 5 is not a module.function"),
    ("  - name: {a: 1}\n", "3:11: name must be text, got {'a': 1}"),
    ("  - name: a\n    mocks: {speech.say: []}\n",
     "4:25: mocks.speech.say: an empty list of outcomes (leave the function out for the mock's default)"),
    ("  - name: a\n    mocks: {speech.say: {succeed: {}, delay: .nan}}\n",
     "4:25: delay must be a number of seconds from 0 to 86400 (a day), got nan"),
])
def test_a_scenario_value_of_the_wrong_kind_is_a_positioned_error(tmp_path, capsys, scenario, says):
    path = tmp_path / "s.scenarios.yaml"
    path.write_text("tree: %s\nscenarios:\n%s" % (os.path.join(TREES, "find_apple.yaml"), scenario))
    assert bmtree(["test", str(path)]) == 2
    err = capsys.readouterr().err
    assert "%s:%s" % (path, says) in err and "Traceback" not in err, err


# every problem of a file at once; expectations that say what went wrong -----------------------------------
def test_every_problem_of_a_scenario_is_reported_at_once(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n"
                 "  - name: three mistakes\n"
                 "    mocks:\n"
                 "      vision.find_object:\n"
                 "        succeed: {success: true, positon: {x: 1.0}}\n"
                 "      navigation.go_to: {succeed: {room: 5}}\n"
                 "    expect:\n"
                 "      stauts: success\n"
                 "    max_ticks: 0\n" % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", str(f)]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "%s:6:34: vision.find_object has no output 'positon' (did you mean 'position'?)" % f,
        "%s:7:42: navigation.go_to output 'room' takes text (std_msgs/String), got 5" % f,
        "%s:9:7: unknown expect key 'stauts' (did you mean 'status'?)" % f,
        "%s:10:16: max_ticks must be a whole number >= 1, got 0" % f]


def test_scenarios_are_checked_even_when_the_tree_is_invalid(tmp_path, capsys):
    (tmp_path / "bad.yaml").write_text("format: 1\nroot:\n  call: speech.sya\n")
    f = tmp_path / "s.yaml"
    f.write_text("tree: bad.yaml\nscenarios:\n  - name: x\n    mokcs: {}\n")
    assert bmtree(["test", str(f)]) == 2
    err = capsys.readouterr().err
    assert "bad.yaml:3:9: module 'speech' has no function 'sya'" in err
    assert "s.yaml:4:5: unknown scenario key 'mokcs' (did you mean 'mocks'?)" in err


def test_a_blackboard_key_never_written_is_said_so(tmp_path):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n  - name: typo\n    expect:\n      blackboard: {object_rom: kitchen}\n"
                 "  - name: unknown\n    expect:\n      blackboard: {zzz: 1}\n" % os.path.join(TREES, "find_apple.yaml"))
    out = io.StringIO()
    assert run_scenario_file(str(f), out=out) == [False, False]
    text = out.getvalue()
    assert ("    blackboard object_rom was never written in this run (expected 'kitchen') "
            "(did you mean 'object_room'?)\n") in text
    assert "    blackboard zzz was never written in this run (expected 1); written: attempts, object, " in text
    assert " is None, expected" not in text


def test_expect_reason_is_a_substring_of_the_runs_reason(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n"
                 "  - name: blind\n    mocks:\n      vision.find_object: {fail: camera covered}\n"
                 "    expect: {status: failure, reason: camera covered}\n"
                 "  - name: blind, another reason\n    mocks:\n      vision.find_object: {fail: camera covered}\n"
                 "    expect: {status: failure, reason: battery low}\n"
                 "  - name: succeeds\n    expect: {reason: battery low}\n" % os.path.join(TREES, "find_apple.yaml"))
    out = io.StringIO()
    assert run_scenario_file(str(f), out=out) == [True, False, False]
    text = out.getvalue()
    assert ("    reason 'look for the object: vision.find_object failed: camera covered' does not contain "
            "'battery low'\n") in text
    assert "    no reason (the run succeeded), expected one containing 'battery low'\n" in text
    f.write_text("tree: %s\nscenarios:\n  - expect: {reason: 5}\n" % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", str(f)]) == 2
    assert "s.yaml:3:22: reason is text that the run's reason must contain, got 5" in capsys.readouterr().err


# values stored before the run ---------------------------------------------------------------------
RECALLING = """format: 1
name: recalling
root:
  sequence:
    - recall: {room: vision/find_object/room, heard: text}
    - call: speech.say
      inputs: {text: "{heard}: the {room}"}
"""


def test_a_scenario_gives_what_the_blackboard_held_before_the_run(tmp_path, capsys):
    (tmp_path / "t.yaml").write_text(RECALLING)
    f = tmp_path / "s.yaml"
    f.write_text("tree: t.yaml\nscenarios:\n"
                 "  - name: nothing stored\n    expect: {status: failure, reason: the Blackboard has no}\n"
                 "  - name: stored\n    stored: {vision/find_object/room: kitchen, text: 'yes'}\n"
                 "    expect: {calls: [speech.say: {text: 'yes: the kitchen'}], blackboard: {room: kitchen}}\n"
                 "  - name: stored twice, the newer wins\n"
                 "    stored:\n      - {vision/find_object/room: kitchen, text: 'no'}\n"
                 "      - {vision/find_object/room: hall, text: 'yes'}\n"
                 "    expect: {calls: [speech.say: {text: 'yes: the hall'}]}\n")
    assert bmtree(["test", str(f)]) == 0, capsys.readouterr()
    assert capsys.readouterr().out.rstrip().endswith("3 passed, 0 failed")


def test_stored_names_and_values_are_checked_where_they_are_written(tmp_path, capsys):
    (tmp_path / "t.yaml").write_text(RECALLING)
    f = tmp_path / "s.yaml"
    f.write_text("tree: t.yaml\nscenarios:\n  - stored:\n"
                 "      vision/find_objet/room: kitchen\n"      # 4
                 "      vision/find_object/room: [1, 2]\n"      # 5
                 "      rooom: kitchen\n"                       # 6
                 "      room: kitchen\n"                        # 7: three functions, one type: fine
                 "  - stored: [kitchen]\n")                     # 8
    assert bmtree(["test", str(f)]) == 2
    err = capsys.readouterr().err
    assert "%s:4:7: stored 'vision/find_objet/room': module 'vision' has no function 'find_objet' (did you mean " \
           "'find_object'?)" % f in err
    assert "%s:5:32: stored 'vision/find_object/room': vision.find_object output 'room' takes text" % f in err
    assert "%s:6:7: stored 'rooom': no function of the definitions has an output 'rooom' (did you mean " \
           "'room'?)" % f in err
    assert "%s:8:13: stored is a mapping of Blackboard name" % f in err
    assert "s.yaml:7:" not in err and err.count("\n") == 4


def test_misspelt_outcome_keys_get_a_suggestion_at_the_key(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n  - mocks:\n      navigation.go_to: {fial: blocked}\n"
                 "      vision.find_object: {succeed: {success: true}, dealy: 2}\n" % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", str(f)]) == 2
    err = capsys.readouterr().err
    assert "%s:4:26: an outcome has one of succeed, fail, reject, hang, die (and optionally delay, ignores_cancel), got fial: 'fial' is " \
           "no key of an outcome (did you mean 'fail'?)" % f in err
    assert "%s:5:54: an outcome has one of succeed, fail, reject, hang, die (and optionally delay, ignores_cancel), got succeed, dealy: " \
           "'dealy' is no key of an outcome (did you mean 'delay'?)" % f in err


def test_the_format_page_says_exactly_what_a_missing_succeed_output_gets(tmp_path):
    from coordinator.testing import TreeTest

    with open(os.path.join(ROOT, "docs", "scenarios.md"), encoding="utf-8") as fh:
        doc = fh.read()
    assert "missing outputs get zero values" not in doc
    assert "a missing output gets its default, as with no script (`true` for a `std_msgs/Bool` output named " \
           "`success`, else the empty value of its type)" in doc
    t = TreeTest(os.path.join(TREES, "find_apple.yaml"))
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    t.mocks["vision.find_object"].succeed(room="kitchen")   # no success given: true, and the apple is seen
    outputs = t.run().calls("navigation.go_to")[0].outputs
    assert outputs["success"] is True and outputs["position"] == {"x": 0.0, "y": 0.0, "z": 0.0}


def test_bmtree_test_coverage_says_which_nodes_the_scenarios_reached(capsys):
    """Scenario users (no Python) get the coverage report pytest --bmtree-coverage gives."""
    path = os.path.join(ROOT, "tests", "scenarios", "find_apple.scenarios.yaml")
    assert bmtree(["test", "--coverage", path]) == 0
    out = capsys.readouterr().out
    assert "bmtree tree coverage" in out and "trees/find_apple.yaml: 9 of 9 nodes ran" in out, out
    assert "trees/find_apple.yaml:25: call 'approach the apple' reached SUCCESS; never FAILURE" in out, out
    assert bmtree(["test", path]) == 0 and "coverage" not in capsys.readouterr().out
