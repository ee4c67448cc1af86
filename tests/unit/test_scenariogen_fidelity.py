"""``bmtree replay RUN --scenario`` reproduces the run's outcome, or refuses to write what cannot: an answer
(a module's loss) the run's tree took after its call's timeout comes just before it; a run of a tree with
``cleanup:`` killed while root ran ends at its kill, without the cleanup; a run failed by the Blackboard node
or by a ``wait_event``'s lost module node is refused in one line; the run's reason is expected, robust to
call ids and measured times."""
from __future__ import annotations

import io
import json

import pytest
import yaml

from coordinator import scenariogen
from coordinator.cli import main as bmtree
from coordinator.runlog import RunLogError, RunLogWriter, read_log
from coordinator.runstream import RunStream
from coordinator.scenariogen import write_scenario
from coordinator.testing import TreeTest, die, fail, succeed
from coordinator.testing.scenario import run_scenario_file

LOOK = """format: 1
name: look
root:
  retry: 3
  name: look for anybody
  child:
    call: vision.find_person
    name: find somebody
    inputs: {name: ""}
    timeout: 10
"""

GONE = "node /bm_vision stopped (its process is gone)"
NEVER_SENT = ("no node of it connected to /bmtree/call/vision within 10s (node /bm_vision: restarting, or unable "
              "to reach this process?): the call was never sent")


def _records(log):
    with open(log) as fh:
        return [json.loads(line) for line in fh]


def _write(log, records):
    with open(log, "w") as fh:
        fh.write("".join(json.dumps(r) + "\n" for r in records))


def _recorded(tmp_path, text, sim_defs, script, name="tree.yaml"):
    path = tmp_path / name
    path.write_text(text)
    t = TreeTest(str(path), definitions=sim_defs)
    script(t.mocks)
    log = str(tmp_path / "run.jsonl")
    run = t.run(observers=[RunStream([RunLogWriter(log, fsync=False)], {"inputs": {}})])
    return log, run


def _scenario(tmp_path, log):
    out_path = str(tmp_path / "again.yaml")
    write_scenario(read_log(log), out_path)
    text = open(out_path).read()
    return out_path, text, yaml.safe_load(text)["scenarios"][0]


def _passes(out_path, sim_defs):
    out = io.StringIO()
    return run_scenario_file(out_path, sim_defs, out) == [True], out.getvalue()


# 1. a module lost after the coordinator's 10 s wait, under the call's timeout: 10 -----------------------------
@pytest.mark.parametrize("late", ["die", "fail"])
def test_an_answer_the_run_took_after_its_calls_timeout_comes_just_before_it(late, tmp_path, sim_defs):
    def script(m):
        if late == "die":
            m["vision.find_person"].script(die(GONE, delay=0.5), die(NEVER_SENT, delay=9.0),
                                           die(GONE + " and was not started again within 10s", delay=9.0))
        else:
            m["vision.find_person"].script(fail("nobody", delay=0.5), fail("camera late", delay=9.0))
    log, run = _recorded(tmp_path, LOOK, sim_defs, script)
    assert run.failed and len(run.calls()) == 3
    records = _records(log)
    ends = [r for r in records if r["type"] == "call_end"]
    for r, took in zip(ends[1:], (10.030799, 10.002209)):   # as the robot's run recorded them: after 10 s
        r["duration"] = took
    _write(log, records)
    out_path, text, scenario = _scenario(tmp_path, log)
    delays = [o["delay"] for o in scenario["mocks"]["vision.find_person"]]
    assert delays == [0.5, 9.999999, 9.999999]   # the timeout is 10: they end as in the run, not timed out
    assert "here they come just before it: vision.find_person #2 (after 10.0308s), vision.find_person #3 " \
           "(after 10.0022s)." in text
    ok, said = _passes(out_path, sim_defs)
    assert ok, said


def test_an_answer_in_time_keeps_its_time(tmp_path, sim_defs):
    log, _ = _recorded(tmp_path, LOOK, sim_defs,
                       lambda m: m["vision.find_person"].script(die(GONE, delay=9.5), succeed(person="Ana", delay=2)))
    _, text, scenario = _scenario(tmp_path, log)
    assert [o["delay"] for o in scenario["mocks"]["vision.find_person"]] == [9.5, 2.0]
    assert "just before it" not in text


# 2. a tree with cleanup: killed (kill -9, no end record) while root ran ------------------------------------------
CLEANS = """format: 1
name: go
root:
  sequence:
    - call: speech.say
      inputs: {text: a}
    - call: navigation.go_to
      inputs: {place: kitchen}
    - call: speech.say
      inputs: {text: b}
cleanup:
  call: speech.say
  inputs: {text: "bye {ended}"}
"""


def test_a_run_killed_while_root_ran_ends_its_scenario_at_the_kill_without_the_cleanup(tmp_path, sim_defs):
    def script(m):
        m["speech.say"].succeed(delay=1.0)
        m["navigation.go_to"].succeed(room="kitchen", delay=5.0)
    log, run = _recorded(tmp_path, CLEANS, sim_defs, script)
    assert run.succeeded and len(run.calls()) == 4
    _write(log, [r for r in _records(log) if r["type"] != "end" and r["t"] <= 3.0])   # killed at 3 s
    out_path, text, scenario = _scenario(tmp_path, log)
    # its last tick: when the navigation started (a tick that changes nothing is not recorded)
    assert "max_duration" not in scenario and scenario["killed_at"] == pytest.approx(1.0)
    assert scenario["expect"] == {"status": "failure", "calls": [{"speech.say": {"text": "a"}},
                                                                 {"navigation.go_to": {"place": "kitchen"}}]}
    assert "# The run has no end (it was killed while root ran, before its cleanup): this ends at its" in text
    ok, said = _passes(out_path, sim_defs)
    assert ok, said


# 3. what a scenario cannot reproduce is refused --------------------------------------------------------------
RECALLS = """format: 1
name: bb
root:
  sequence:
    - call: speech.say
      inputs: {text: a}
    - recall: {room: vision/find_object/room}
      name: read the room
"""

WAITS = """format: 1
name: wev
root:
  wait_event: navigation.arrived
  name: wait to arrive
  timeout: 2
"""


@pytest.mark.parametrize("tree, why", [
    (RECALLS, "Blackboard node lost: node /blackboard stopped (its process is gone)"),
    (RECALLS, "the Blackboard node did not store the result of vision.find_object (call 0123456789abcdef) that "
              "wrote vision/find_object/room, so its value is an older one (was the Blackboard node restarted, or "
              "cut off from the module, while the call ran?)"),
    (RECALLS, "no answer from the Blackboard node within 5s"),
    (WAITS, "navigation's node is gone (node /bm_navigation stopped (its process is gone)): no navigation.arrived "
            "event can come"),
    (WAITS, "navigation's node was restarted (node /bm_navigation restarted): a navigation.arrived event may have "
            "been lost meanwhile"),
])
def test_a_run_failed_by_what_a_scenario_cannot_do_is_refused_in_one_line(tree, why, tmp_path, sim_defs, capsys):
    log, run = _recorded(tmp_path, tree, sim_defs, lambda m: None)
    assert run.failed
    records = _records(log)
    for r in records:   # as the robot's run failed: the Blackboard node, or navigation's node, lost
        for c in r.get("changes") or []:
            if c[1] == "FAILURE" and len(c) > 2:
                c[2] = why
        if r["type"] == "end":
            r["reason"] = "%s: %s" % ("read the room" if tree == RECALLS else "wait to arrive", why)
    _write(log, records)
    with pytest.raises(RunLogError) as err:
        write_scenario(read_log(log), str(tmp_path / "again.yaml"))
    said = str(err.value)
    node = "recall 'read the room'" if tree == RECALLS else "wait_event 'wait to arrive'"
    assert said.startswith("%s: the %s failed at " % (log, node)) and "\n" not in said, said
    assert ("because of the Blackboard node (%s); a scenario's Blackboard never goes down nor loses a result, so a "
            "scenario could not end the same way: make it from a run in which the Blackboard node stayed up" % why
            if tree == RECALLS else
            "because navigation's node was lost while it waited (%s); a scenario's module dies only during a call "
            "to it (die), unseen by a wait_event, so a scenario could not end the same way: make it from a run in "
            "which that node stayed up" % why) in said, said
    assert not (tmp_path / "again.yaml").exists()
    assert bmtree(["replay", log, "--scenario", str(tmp_path / "again.yaml")]) == 2
    printed = capsys.readouterr()
    assert "Traceback" not in printed.err and printed.err.count("\n") == 1 and said in printed.err, printed.err


def test_a_recall_that_failed_as_a_scenario_fails_too_is_not_refused(tmp_path, sim_defs):
    log, run = _recorded(tmp_path, RECALLS, sim_defs, lambda m: None)
    assert run.failed and "the Blackboard has no vision/find_object/room" in run.reason
    out_path, _, scenario = _scenario(tmp_path, log)
    assert scenario["expect"]["reason"] == run.reason
    ok, said = _passes(out_path, sim_defs)
    assert ok, said


# 4. the run's reason is expected -----------------------------------------------------------------------------
BOOM = """format: 1
name: boom
root:
  sequence:
    - call: speech.say
      inputs: {text: a}
    - call: vision.find_object
      name: read the sensor
      inputs: {object: cup}
"""

BOOM_CHANGED = BOOM.replace("""    - call: vision.find_object
      name: read the sensor
      inputs: {object: cup}
""", """    - force_success:
        call: vision.find_object
        name: read the sensor
        inputs: {object: cup}
    - fail: a totally different reason
""")


def test_the_runs_reason_is_expected_and_a_tree_failing_for_another_fails_the_scenario(tmp_path, sim_defs):
    log, run = _recorded(tmp_path, BOOM, sim_defs,
                         lambda m: m["vision.find_object"].fail("KeyError: 2.0 (probe.py:8 in boom)", delay=0.1))
    assert run.reason == "read the sensor: vision.find_object failed: KeyError: 2.0 (probe.py:8 in boom)"
    out_path, _, scenario = _scenario(tmp_path, log)
    assert scenario["expect"]["reason"] == run.reason
    ok, said = _passes(out_path, sim_defs)
    assert ok, said
    (tmp_path / "tree.yaml").write_text(BOOM_CHANGED)   # same calls, same status: another reason
    ok, said = _passes(out_path, sim_defs)
    assert not ok and "    reason 'fail: a totally different reason' does not contain " \
                      "'read the sensor: vision.find_object failed: KeyError: 2.0 (probe.py:8 in boom)'\n" in said, said


FORCED = """format: 1
name: forced
root:
  force_failure:
    call: speech.say
    name: ask to step closer
    inputs: {text: "closer, please"}
"""


def test_a_reason_with_a_measured_time_is_expected_around_it(tmp_path, sim_defs):
    log, run = _recorded(tmp_path, FORCED, sim_defs, lambda m: m["speech.say"].succeed(delay=0.0035))
    assert run.reason.endswith("[succeeded in 0.004s]"), run.reason
    records = _records(log)
    for r in records:   # the robot's run took 3.1 ms
        if r["type"] == "end":
            r["reason"] = r["reason"].replace("0.004s", "0.003s")
    _write(log, records)
    out_path, _, scenario = _scenario(tmp_path, log)
    assert scenario["expect"]["reason"] == [run.reason[:-len("0.004s]")], "]"]
    ok, said = _passes(out_path, sim_defs)
    assert ok, said
    assert scenariogen.expected_reason("x (call 0123456789abcdef) y") == ["x (call ", ") y"]
    assert scenariogen.expected_reason("no answer within 10s") == "no answer within 10s"


def test_a_reason_in_pieces_must_hold_them_in_order(tmp_path, sim_defs, capsys):
    (tmp_path / "tree.yaml").write_text(BOOM)
    f = tmp_path / "s.yaml"
    base = ("tree: tree.yaml\nscenarios:\n  - name: %s\n    mocks: {vision.find_object: {fail: camera covered}}\n"
            "    expect: {status: failure, reason: %s}\n")
    f.write_text(base % ("in order", '["read the sensor: ", "failed: ", "covered"]')
                 + base.split("scenarios:\n")[1] % ("out of order", '["covered", "read the sensor"]'))
    out = io.StringIO()
    assert run_scenario_file(str(f), sim_defs, out) == [True, False], out.getvalue()
    assert ("    reason 'read the sensor: vision.find_object failed: camera covered' does not contain 'covered', "
            "'read the sensor' in this order: 'read the sensor' not found after 'covered'\n") in out.getvalue()
    for bad in ("[]", '["a", 5]', '["a", ""]'):
        f.write_text(base % ("bad", bad))
        assert bmtree(["test", str(f)]) == 2
        assert "s.yaml:5:39: reason as a list holds the texts the run's reason must contain, in this order (at " \
               "least one, none empty), got " in capsys.readouterr().err
