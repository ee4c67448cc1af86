"""``expect`` compares values normalised to their ROS types, and only the fields listed; the
scenario file's values are checked against the definitions before anything runs."""
from __future__ import annotations

import io
import json
import os

import genpy
import pytest
import yaml

from comm.rostypes import to_message
from coordinator.cli import main as bmtree
from coordinator.context import plain
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runstream import RunStream
from coordinator.scenariogen import write_scenario
from coordinator.testing import TreeTest
from coordinator.testing import scenario as scenarios
from coordinator.testing.expected import difference, legacy_times
from coordinator.testing.scenario import calls_diff, run_scenario_file
from coordinator.watchstate import WatchState
from modules.search import default_definitions
from tests.conftest import TREES

ARM = {
    "Basic Module": "arm", "Brief Description": "an arm", "Hardware Required": [],
    "Functions": [
        {"Name": "pick", "Exec-condition": "", "Description": "pick an object before a deadline",
         "Input-params": [{"Name": "object", "Data-type": "std_msgs/String", "Description": ""},
                          {"Name": "deadline", "Data-type": "std_msgs/Time", "Description": ""}],
         "Output-params": [{"Name": "picked_at", "Data-type": "std_msgs/Time", "Description": ""}]},
        {"Name": "show_pattern", "Exec-condition": "", "Description": "LEDs",
         "Input-params": [{"Name": "pattern", "Data-type": "std_msgs/UInt8MultiArray", "Description": ""}],
         "Output-params": []},
        {"Name": "place", "Exec-condition": "", "Description": "place what it holds",
         "Input-params": [{"Name": "pose", "Data-type": "geometry_msgs/Pose", "Description": ""}],
         "Output-params": [{"Name": "placed", "Data-type": "geometry_msgs/Pose", "Description": ""}]}],
    "Events": [{"Name": "objectDropped", "Description": "it fell",
                "Event-params": [{"Name": "object", "Data-type": "std_msgs/String", "Description": ""},
                                 {"Name": "when", "Data-type": "std_msgs/Time", "Description": ""}]}],
}

TREE = """format: 1
name: arm
root:
  sequence:
    - call: arm.pick
      inputs: {object: cup, deadline: {secs: 100, nsecs: 0}}
      outputs: {picked_at: picked_at}
    - call: arm.show_pattern
      inputs: {pattern: {data: [255, 0, 255]}}
    - call: arm.place
      inputs: {pose: {position: {x: 0.5, y: 0.1, z: 0.2}, orientation: {w: 1.0}}}
      outputs: {placed: placed}
    - set: {note: {room: kitchen, shelf: 2}}
"""


@pytest.fixture
def arm(tmp_path):
    path = tmp_path / "arm.json"
    path.write_text(json.dumps(ARM))
    (tmp_path / "arm.yaml").write_text(TREE)
    return str(path)


def scenario(tmp_path, body, tree="arm.yaml"):
    f = tmp_path / "s.scenarios.yaml"
    f.write_text("tree: %s\nscenarios:\n%s" % (tree, body))
    return str(f)


def run(path, arm):
    out = io.StringIO()
    results = run_scenario_file(path, default_definitions([arm]), out)
    return results, out.getvalue()


# times and byte arrays --------------------------------------------------------------------------------
@pytest.mark.parametrize("deadline", ["{secs: 100, nsecs: 0}", "{secs: 100}", "100", "100.0", "'100000000000'"])
@pytest.mark.parametrize("pattern", ["[255, 0, 255]", "/wD/", "\"/wD/\""])
def test_a_time_and_a_byte_array_match_in_every_form_the_tree_takes(tmp_path, arm, deadline, pattern):
    path = scenario(tmp_path, "  - expect:\n      calls:\n"
                              "        - arm.pick: {object: cup, deadline: %s}\n"
                              "        - arm.show_pattern: {pattern: {data: %s}}\n"
                              "        - arm.place\n" % (deadline, pattern))
    results, out = run(path, arm)
    assert results == [True], out


def test_a_different_time_or_byte_array_says_so_readably(tmp_path, arm):
    path = scenario(tmp_path, "  - expect:\n      calls:\n"
                              "        - arm.pick: {deadline: {secs: 101, nsecs: 0}}\n"
                              "        - arm.show_pattern: {pattern: {data: [255, 0]}}\n"
                              "        - arm.place\n")
    results, out = run(path, arm)
    assert results == [False]
    assert "    call 1 (arm.pick): input deadline is {'secs': 100, 'nsecs': 0}, expected {'secs': 101, 'nsecs': 0}\n" in out
    assert "    call 2 (arm.show_pattern): input pattern.data is [255, 0, 255], expected [255, 0]\n" in out
    # times on the diff's lines as {secs, nsecs}, never as nanoseconds in text
    assert '      + arm.pick {"deadline": {"secs": 100, "nsecs": 0}, "object": "cup"}\n' in out
    assert '      - arm.pick {"deadline": {"secs": 101, "nsecs": 0}}\n' in out
    assert "100000000000" not in out


def test_a_diff_has_no_equal_lines_marked_changed(tmp_path, arm):
    # the same calls as the run made, one more expected: the made ones are "=" lines, never a "+" and
    # a "-" line saying the same thing
    path = scenario(tmp_path, "  - expect:\n      calls:\n"
                              "        - arm.pick: {object: cup, deadline: {secs: 100, nsecs: 0}}\n"
                              "        - arm.show_pattern: {pattern: {data: [255, 0, 255]}}\n"
                              "        - arm.place: {pose: {position: {x: 0.5}}}\n"
                              "        - arm.place\n")
    results, out = run(path, arm)
    assert results == [False]
    diff = [line.strip()[:2] for line in out.splitlines() if line.strip()[:2] in ("= ", "+ ", "- ")]
    assert diff == ["= ", "= ", "= ", "- "], out


def test_expected_values_compare_normalised_in_the_python_api():
    pattern = to_message("std_msgs/UInt8MultiArray", {"data": [255, 0, 255]})
    for want in ([255, 0, 255], b"\xff\x00\xff", "/wD/"):
        assert difference({"data": want}, pattern) is None, want
    deadline = to_message("std_msgs/Time", {"secs": 100, "nsecs": 0}, allow_scalar=True)
    for want in ({"secs": 100, "nsecs": 0}, 100, "100000000000"):
        assert difference(want, deadline) is None, want
    assert difference({"secs": 100, "nsecs": 1}, deadline).said("input deadline") == (
        "input deadline is {'secs': 100, 'nsecs': 0}, expected {'secs': 100, 'nsecs': 1}")
    assert difference("tomorrow", deadline).why.startswith("is no std_msgs/Time: ")
    # calls_diff takes the written forms too
    call = type("Call", (), {"target": "arm.pick", "messages": {"deadline": deadline},
                             "inputs": {"deadline": plain(deadline)}})()
    assert calls_diff([{"arm.pick": {"deadline": {"secs": 100, "nsecs": 0}}}], [call]) == [
        '  = arm.pick {"deadline": {"secs": 100, "nsecs": 0}}']
    assert scenarios.ExpectedCall({"arm.pick": {"deadline": "100000000000"}}).matches(call)


def test_plain_makes_a_time_secs_and_nsecs():
    assert plain(genpy.Time(100, 5)) == {"secs": 100, "nsecs": 5}
    assert plain(to_message("std_msgs/Duration", {"secs": -1, "nsecs": 5}, allow_scalar=True)) == {
        "secs": -1, "nsecs": 5}
    assert plain(to_message("std_msgs/Header", {"stamp": {"secs": 3}})) == {
        "seq": 0, "stamp": {"secs": 3, "nsecs": 0}, "frame_id": ""}
    assert plain(to_message("std_msgs/String", "x", allow_scalar=True)) == "x"


def test_legacy_nanosecond_texts_become_secs_and_nsecs_only_at_times():
    assert legacy_times("std_msgs/Time", "100000000005") == {"secs": 100, "nsecs": 5}
    assert legacy_times("std_msgs/Duration", "-999999995") == {"secs": -1, "nsecs": 5}
    assert legacy_times("std_msgs/String", "100000000000") == "100000000000"
    assert legacy_times("std_msgs/Header", {"stamp": "3000000000", "frame_id": "7"}) == {
        "stamp": {"secs": 3, "nsecs": 0}, "frame_id": "7"}


# partial messages -------------------------------------------------------------------------------------
def test_only_the_fields_listed_inside_an_input_are_compared(tmp_path, arm):
    path = scenario(tmp_path, "  - name: x only\n    expect:\n      calls: [arm.pick, arm.show_pattern, "
                              "arm.place: {pose: {position: {x: 0.5}}}]\n"
                              "  - name: nothing listed\n    expect:\n      calls: [arm.pick, arm.show_pattern, "
                              "arm.place: {pose: {}}]\n"
                              "  - name: another x\n    expect:\n      calls: [arm.pick, arm.show_pattern, "
                              "arm.place: {pose: {position: {x: 0.4}, orientation: {w: 1.0}}}]\n"
                              "  - name: the whole\n    expect:\n      calls: [arm.pick, arm.show_pattern, "
                              "arm.place: {pose: {position: {x: 0.5, y: 0.1, z: 0.2}, orientation: "
                              "{x: 0, y: 0, z: 0, w: 1}}}]\n")
    results, out = run(path, arm)
    assert results == [True, True, False, True], out
    assert "    call 3 (arm.place): input pose.position.x is 0.5, expected 0.4\n" in out


def test_only_the_fields_listed_of_a_blackboard_value_are_compared(tmp_path, arm):
    path = scenario(tmp_path, "  - name: partial\n    mocks:\n"
                              "      arm.place: {succeed: {placed: {position: {x: 0.5, y: 0.1}}}}\n"
                              "      arm.pick: {succeed: {picked_at: {secs: 7, nsecs: 0}}}\n"
                              "    expect:\n      blackboard:\n"
                              "        placed: {position: {x: 0.5}}\n"
                              "        picked_at: {secs: 7, nsecs: 0}\n"
                              "        note: {room: kitchen}\n"
                              "  - name: wrong\n    mocks:\n"
                              "      arm.place: {succeed: {placed: {position: {x: 0.5, y: 0.1}}}}\n"
                              "    expect:\n      blackboard:\n"
                              "        placed: {position: {y: 0.2}}\n"
                              "        note: {floor: 1}\n"
                              "        picked_at: 3\n")
    results, out = run(path, arm)
    assert results == [True, False], out
    assert "    blackboard placed.position.y is 0.1, expected 0.2\n" in out
    assert "    blackboard note.floor is not there (expected 1)\n" in out
    assert "    blackboard picked_at is {'secs': 0, 'nsecs': 0}, expected 3\n" in out


def test_a_one_field_message_on_the_blackboard_still_compares_as_its_value(tmp_path):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n  - mocks:\n      vision.find_object:\n"
                 "        succeed: {success: true, position: {x: 8.6, y: 2.3, z: 0.9}, room: kitchen}\n"
                 "    expect:\n      blackboard: {object_room: kitchen, object_position: {x: 8.6}}\n"
                 "  - mocks:\n      vision.find_object:\n"
                 "        succeed: {success: true, position: {x: 8.6, y: 2.3, z: 0.9}, room: kitchen}\n"
                 "    expect:\n      blackboard: {object_room: hall, object_position: {z: 1.0}}\n"
                 % os.path.join(TREES, "find_apple.yaml"))
    out = io.StringIO()
    assert run_scenario_file(str(f), out=out) == [True, False], out.getvalue()
    assert "    blackboard object_room is 'kitchen', expected 'hall'\n" in out.getvalue()
    assert "    blackboard object_position.z is 0.9, expected 1.0\n" in out.getvalue()


# the file's values against the definitions -----------------------------------------------------------
def test_expected_calls_events_and_outcomes_are_checked_against_the_definitions(tmp_path, arm, capsys):
    path = scenario(tmp_path, "  - name: bad\n"
                              "    mocks:\n"
                              "      arm.place: {fail: 3}\n"
                              "      arm.pick: [{reject: }, {hang: false}]\n"
                              "    events:\n"
                              "      - {event: arm.objectDroped, params: {object: cup}}\n"
                              "      - {event: arm.objectDropped, after: arm.plase, params: {object: cup, when: 0}}\n"
                              "      - {event: arm.objectDropped, nth: 2, params: {object: cup, when: 0}}\n"
                              "      - {event: arm.objectDropped, after: arm.place, nth: 0, params: {object: cup, when: 0}}\n"
                              "    expect:\n"
                              "      calls:\n"
                              "        - arm.pick: {objet: cup}\n"
                              "        - arm.pick: {deadline: soon}\n"
                              "        - arm.pik\n"
                              "        - arm.place: {pose: {positon: {x: 1}}}\n"
                              "        - speech.say: {volume: 3}\n")
    assert bmtree(["test", "--modules", arm, path]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "%s:5:25: fail takes the reason as text (fail: blocked by a chair), got 3" % path,
        "%s:6:27: reject takes the reason as text (reject: blocked by a chair), got None" % path,
        "%s:6:37: hang takes true, got False" % path,
        "%s:8:17: no event 'arm.objectDroped' in the definitions (did you mean 'arm.objectDropped'?)" % path,
        "%s:9:43: after is the module.function whose call the event follows: module 'arm' has no function "
        "'plase' (did you mean 'place'?)" % path,
        "%s:10:41: nth counts the calls of the function 'after' names: give 'after' too" % path,
        "%s:11:59: nth must be a whole number >= 1, got 0" % path,
        "%s:14:22: arm.pick has no input 'objet' (did you mean 'object'?)" % path,
        "%s:15:32: arm.pick input 'deadline' takes seconds, {secs, nsecs} or now (std_msgs/Time), got 'soon'" % path,
        "%s:16:11: expected call: module 'arm' has no function 'pik' (did you mean 'pick'?)" % path,
        "%s:17:29: arm.place input 'pose' (geometry_msgs/Pose) has no field 'positon' (did you mean "
        "'position'?)" % path,
        "%s:18:24: speech.say has no input 'volume' (its inputs: text)" % path]


def test_a_number_as_a_reason_in_text_is_fine(tmp_path, arm):
    path = scenario(tmp_path, "  - mocks:\n      arm.place: {fail: \"404\"}\n    expect:\n"
                              "      status: failure\n      reason: \"failed: 404\"\n")
    results, out = run(path, arm)
    assert results == [True], out


# scenarios written from runs with times --------------------------------------------------------------
def _record(tmp_path, arm, old=False):
    defs = default_definitions([arm])
    t = TreeTest(str(tmp_path / "arm.yaml"), definitions=defs)
    t.mocks["arm.pick"].succeed(picked_at={"secs": 7, "nsecs": 5})
    t.mocks.event(0.0, "arm.objectDropped", object="cup", when={"secs": 8, "nsecs": 0})
    log = str(tmp_path / "run.jsonl")
    t.run(observers=[RunStream([RunLogWriter(log, fsync=False)], {"inputs": {}, "modules": [arm]})])
    if old:  # as run logs recorded a std_msgs/Time before {secs, nsecs}: nanoseconds in text
        text = open(log).read()
        for new, was in (('{"secs":100,"nsecs":0}', '"100000000000"'), ('{"secs":7,"nsecs":5}', '"7000000005"'),
                         ('{"secs":8,"nsecs":0}', '"8000000000"')):
            assert new in text, new
            text = text.replace(new, was)
        open(log, "w").write(text)
    return log


@pytest.mark.parametrize("old", [False, True], ids=["new log", "old log"])
def test_a_scenario_from_a_run_with_times_writes_them_readably_and_passes(tmp_path, arm, old):
    log = _record(tmp_path, arm, old)
    out_path = str(tmp_path / "replayed.yaml")
    write_scenario(read_log(log), out_path)
    text = open(out_path).read()
    assert "deadline: {secs: 100, nsecs: 0}" in text and "picked_at: {secs: 7, nsecs: 5}" in text, text
    assert "when: {secs: 8, nsecs: 0}" in text and "000000" not in text, text
    results, out = run(out_path, arm)
    assert results == [True], out
    if old:  # the file itself, as bmtree wrote it from old logs: still passes
        data = yaml.safe_load(text)
        sc = data["scenarios"][0]
        sc["expect"]["calls"][0]["arm.pick"]["deadline"] = "100000000000"
        sc["mocks"]["arm.pick"][0]["succeed"]["picked_at"] = "7000000005"
        sc["events"][0]["params"]["when"] = "8000000000"
        with open(out_path, "w") as fh:
            fh.write("# Written by 'bmtree replay x --scenario'\n" + yaml.safe_dump(data, sort_keys=False))
        results, out = run(out_path, arm)
        assert results == [True], out


@pytest.mark.parametrize("old", [False, True], ids=["new log", "old log"])
def test_replay_shows_a_run_with_times_old_or_new(tmp_path, arm, old, capsys):
    log = _record(tmp_path, arm, old)
    assert bmtree(["replay", log]) == 0
    assert bmtree(["replay", log, "--at", "0"]) == 0
    out = capsys.readouterr().out
    assert "arm.pick" in out and "Traceback" not in out
    assert ('  picked_at = "7000000005"\n' if old else '  picked_at = {"secs": 7, "nsecs": 5}\n') in out, out
    state = WatchState()  # what bmtree watch (and replay --web) build from the same records
    for line in open(log):
        state.apply_text(line)
    assert state.blackboard["picked_at"] == ("7000000005" if old else {"secs": 7, "nsecs": 5})
    assert state.end["status"] == "SUCCESS" and json.dumps(state.view())
    assert ('"100000000000"' if old else '"secs":100') in open(log).read()
