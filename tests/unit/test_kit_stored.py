"""The test kit: values the Blackboard node held before the run (``Mocks.stored``), required tree
inputs, misspelt ``run.calls`` targets."""
from __future__ import annotations

import json
import os

import pytest

from comm.messages import BlackboardAnswer, BlackboardRequest
from coordinator.errors import UsageError
from coordinator.testing import MockError, TreeTest, succeed
from coordinator.testing import mocks as kit_mocks
from modules.search import default_definitions
from tests.conftest import TREES

RECALL_ROOM = """format: 1
name: go where it was seen
root:
  sequence:
    - recall: {room: %s}
      name: remember the room
    - call: speech.say
      inputs: {text: "it is in the {room}"}
"""


def tree(tmp_path, text: str, name: str = "t.yaml") -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def history(run, name: str, n: int):
    """What the run's Blackboard answers to a ``history`` request, newest first: (value, source)."""
    got = []
    bb = run.transport.blackboard
    bb._publish_answer = got.append
    bb.on_request(BlackboardRequest(var_names=[name], history=n).encode())
    answer = BlackboardAnswer.decode(got[0])
    return [(m.data, s) for m, s in zip(answer.msgs, answer.sources)]


def test_a_recall_of_a_value_stored_before_the_run_succeeds(tmp_path):
    path = tree(tmp_path, RECALL_ROOM % "vision/find_object/room")
    run = TreeTest(path).run()
    assert run.failed and "the Blackboard has no vision/find_object/room" in run.reason
    t = TreeTest(path)
    assert t.mocks.stored({"vision/find_object/room": "kitchen"}) is t.mocks
    run = t.run()
    assert run.succeeded, run.reason
    assert run.said() == ["it is in the kitchen"] and run.blackboard["room"] == "kitchen"


def test_the_runs_own_results_are_newer_than_the_stored_values(tmp_path):
    path = tree(tmp_path, """format: 1
root:
  sequence:
    - call: vision.find_object
      inputs: {object: cup}
    - recall: {room: vision/find_object/room, any: room}
""")
    t = TreeTest(path)
    t.mocks.stored({"vision/find_object/room": "kitchen"}).stored({"vision/find_object/room": "hall"})
    t.mocks["vision.find_object"].succeed(success=True, room="bedroom")
    run = t.run()
    assert run.succeeded and run.blackboard["room"] == run.blackboard["any"] == "bedroom"
    values = history(run, "vision/find_object/room", 5)
    assert [v for v, _ in values] == ["bedroom", "hall", "kitchen"]
    stamps = [s["stamp"] for _, s in values]
    assert stamps[2] < stamps[1] < 0 <= stamps[0]   # stored before the run started (at 0)
    assert [(s["basic_mod"], s["function"]) for _, s in values] == [("vision", "find_object")] * 3
    assert values[0][1]["call_id"] and values[1][1]["call_id"] is None


def test_plain_and_qualified_names_are_found_as_on_the_blackboard(tmp_path):
    # `room` is an output of three functions, all text: stored as no particular function's output
    t = TreeTest(tree(tmp_path, RECALL_ROOM % "room"))
    t.mocks.stored({"room": "kitchen"})
    run = t.run()
    assert run.succeeded and run.said() == ["it is in the kitchen"]
    assert history(run, "room", 1)[0][1]["basic_mod"] is None
    t = TreeTest(tree(tmp_path, RECALL_ROOM % "vision/find_object/room", "q.yaml"))
    t.mocks.stored({"room": "kitchen"})
    run = t.run()
    assert run.failed and "the Blackboard has no vision/find_object/room" in run.reason
    # `text` only speech.listen has: stored as its output, found by either name
    t = TreeTest(tree(tmp_path, RECALL_ROOM % "speech/listen/text", "l.yaml"))
    t.mocks.stored({"text": "garage"})
    assert t.run().said() == ["it is in the garage"]


BAROMETER = {
    "Basic Module": "barometer", "Brief Description": "two readings", "Hardware Required": [],
    "Functions": [
        {"Name": "read", "Exec-condition": "", "Description": "", "Input-params": [],
         "Output-params": [{"Name": "level", "Data-type": "std_msgs/Float64", "Description": ""}]},
        {"Name": "count", "Exec-condition": "", "Description": "", "Input-params": [],
         "Output-params": [{"Name": "level", "Data-type": "std_msgs/Int32", "Description": ""}]}],
}


def test_stored_names_and_values_are_checked_against_the_definitions(tmp_path):
    from modules.definition import load_definitions

    t = TreeTest(os.path.join(TREES, "find_apple.yaml"))
    for name, said in (("vision/find_objet/room", "module 'vision' has no function 'find_objet' (did you mean "
                                                  "'find_object'?)"),
                       ("vison/find_object/room", "no module 'vison' in the definitions (did you mean 'vision'?)"),
                       ("vision/find_object/rooom", "vision.find_object has no output 'rooom' (did you mean 'room'?)"),
                       ("rooom", "no function of the definitions has an output 'rooom' (did you mean 'room'?)"),
                       ("vision/room", "a Blackboard name is 'output' or 'module/function/output'")):
        with pytest.raises(kit_mocks.StoredNameError) as info:
            t.mocks.stored({name: "kitchen"})
        assert str(info.value).startswith("stored %r: %s" % (name, said)), str(info.value)
    # a misfit in the words of a scripted output's
    with pytest.raises(MockError) as scripted:
        t.mocks["vision.find_object"].succeed(room=[1, 2])
    with pytest.raises(MockError) as stored:
        t.mocks.stored({"vision/find_object/room": [1, 2], "success": "very"})
    said = str(scripted.value).split("output 'room' ", 1)[1]
    assert "stored 'vision/find_object/room': vision.find_object output 'room' " + said in str(stored.value)
    assert "stored 'success': " in str(stored.value)   # every problem at once
    assert t.mocks.stored_values == []                  # and nothing stored
    # a plain name whose outputs have several types: accepted when the value fits one of them only
    path = tmp_path / "barometer.json"
    path.write_text(json.dumps(BAROMETER))
    defs = dict(default_definitions(), **load_definitions([str(path)]))
    t = TreeTest(os.path.join(TREES, "find_apple.yaml"), definitions=defs)
    t.mocks.stored({"level": 2.5})
    assert [e[:3] for e in t.mocks.stored_values[0]] == [("barometer", "read", "level")]
    with pytest.raises(kit_mocks.StoredNameError) as info:
        t.mocks.stored({"level": 3})
    assert ("stored 'level': the value fits outputs named 'level' of 2 types (std_msgs/Float64, std_msgs/Int32): "
            "give 'module/function/output' (candidates: barometer/read/level (std_msgs/Float64), "
            "barometer/count/level (std_msgs/Int32))") == str(info.value)


def test_required_tree_inputs_are_asked_for_when_the_test_is_made():
    path = os.path.join(TREES, "search_room.yaml")
    with pytest.raises(UsageError) as info:
        TreeTest(path)
    said = str(info.value)
    assert said.startswith(path + ": tree input 'room' must be given: bmtree_tree(path, inputs={'room': ...})")
    assert "scenario's inputs: {room: ...}" in said
    t = TreeTest(path, inputs={"room": "kitchen"})
    assert t.run().succeeded
    t.inputs = {}
    with pytest.raises(UsageError, match="inputs=\\{'room': ...\\}"):
        t.run()


def test_a_misspelt_call_target_is_an_error_not_an_empty_list():
    t = TreeTest(os.path.join(TREES, "find_apple.yaml"))
    t.mocks["vision.find_object"].script(succeed(success=True, position={"x": 1.0}))
    run = t.run()
    with pytest.raises(KeyError, match="no function 'navigation.goto' in the module definitions "
                                       "\\(did you mean 'navigation.go_to'\\?\\)"):
        run.calls("navigation.goto")
    with pytest.raises(KeyError, match="no function 'gripper.close' .*modules: battery, navigation, speech, vision"):
        run.calls("gripper.close")
    assert run.calls("navigation.where_am_i") == []       # known, never called
    assert len(run.calls("navigation.go_to")) == 1
    with pytest.raises(KeyError, match="did you mean 'approach the apple'"):
        run.statuses("approach the aple")
