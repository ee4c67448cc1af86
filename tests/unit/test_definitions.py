"""Module definitions: schema, ROS type resolution, errors with JSON paths, the model's helpers."""
from __future__ import annotations

import json
import os
import shutil

import pytest
from geometry_msgs.msg import Point
from std_msgs.msg import Bool, String

from comm import FunctionResult, ProtocolError
from coordinator.cli import main as bmtree
from modules.definition import DefinitionError, load_definition, load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA, REFERENCE

BAD = os.path.join(DATA, "definitions_bad")
with open(os.path.join(BAD, "expected.json")) as _fh:
    EXPECTED = json.load(_fh)


def test_reference_definitions_load():
    defs = load_definitions([REFERENCE])
    assert set(defs) == {"DEMO_BM", "PYTHON_BM", "module_pf"}
    assert [f for f in defs["PYTHON_BM"].functions] == ["graspObject", "putObject", "goSafePos"]
    assert set(defs["module_pf"].events) == {"foundPerson", "lostPerson"}


def test_sim_definitions_cover_the_manuals_figure():
    defs = load_definitions([SIM_DIR])
    assert set(defs) == {"battery", "navigation", "vision", "speech"}
    assert {"go_to", "approach"} <= set(defs["navigation"].functions)
    assert {"find_object", "find_person"} <= set(defs["vision"].functions)
    assert defs["speech"].function("listen").output("text").rostype == "std_msgs/String"


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_broken_definition_gives_expected_error(name):
    path = os.path.join(BAD, name + ".json")
    with pytest.raises(DefinitionError) as info:
        load_definition(path)
    assert any(EXPECTED[name] in p for p in info.value.problems), info.value.problems
    assert all(p.startswith(path) for p in info.value.problems)


def test_directory_reports_every_error_and_duplicate_modules(tmp_path):
    for name in ("01_float_type", "05_duplicate_function"):
        shutil.copy(os.path.join(BAD, name + ".json"), tmp_path)
    shutil.copy(os.path.join(REFERENCE, "PYTHON_BM.json"), tmp_path / "a.json")
    shutil.copy(os.path.join(REFERENCE, "PYTHON_BM.json"), tmp_path / "b.json")
    with pytest.raises(DefinitionError) as info:
        load_definitions([str(tmp_path)])
    text = str(info.value)
    assert "'float' is not a ROS message type" in text and "duplicate function name 'grasp'" in text
    assert "b.json: Basic Module: duplicate module name 'PYTHON_BM' (also defined in" in text


def test_bmtree_modules_lists_and_reports(capsys):
    assert bmtree(["modules", REFERENCE]) == 0
    out = capsys.readouterr().out
    assert "graspObject(target_pos: geometry_msgs/Point, obj_radius: std_msgs/Float64)" in out
    assert "event lostPerson()" in out
    assert bmtree(["modules", BAD]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) >= len(EXPECTED)
    assert not any("Traceback" in line for line in err)


def test_build_call_accepts_yaml_friendly_values(sim_defs):
    fn = sim_defs["navigation"].function("go_to")
    call = fn.build_call({"place": "kitchen"})
    assert call.names == ["place"] and call.msgs == [String("kitchen")] and call.call_id
    with pytest.raises(ProtocolError, match="missing input 'place'"):
        fn.build_call({})
    with pytest.raises(ProtocolError, match=r"unknown input 'plac' \(did you mean 'place'\?\)"):
        fn.build_call({"place": "x", "plac": "y"})
    approach = sim_defs["navigation"].function("approach")
    with pytest.raises(ProtocolError) as info:
        approach.build_call({"target": {"x": "far"}})
    assert str(info.value) == ("navigation.approach: input 'target' (geometry_msgs/Point): field x takes a number "
                               "(float64), got 'far'")


def test_result_validation_against_definition():
    fn = load_definitions([REFERENCE])["PYTHON_BM"].function("putObject")
    fn.check_result(FunctionResult(["success", "final_pos"], [Bool(True), Point()]))
    with pytest.raises(ProtocolError, match="output 'final_pos' is std_msgs/Bool, the definition says"):
        fn.check_result(FunctionResult(["success", "final_pos"], [Bool(True), Bool(False)]))
    with pytest.raises(ProtocolError, match="missing output 'final_pos'"):
        fn.check_result(FunctionResult(["success"], [Bool(True)]))
    fn.check_result(FunctionResult([], [], status="failed", error="x"))  # failures carry no outputs


def test_a_key_written_twice_in_a_definition_is_an_error_not_the_last_one_silently(tmp_path):
    path = tmp_path / "dup.json"
    path.write_text('{"Basic Module": "g", "Brief Description": "", "Hardware Required": [], "Functions": '
                    '[{"Name": "open", "Name": "close", "Description": "", "Input-params": [], "Output-params": []}]}')
    with pytest.raises(DefinitionError) as info:
        load_definition(str(path))
    assert str(info.value) == "%s: invalid JSON: key 'Name' appears twice in one object" % path


def test_bmtree_modules_says_a_path_outside_the_working_directory_absolutely(tmp_path, capsys, monkeypatch):
    """A folder elsewhere was shown as ``../../tmp/…/arm.json``."""
    (tmp_path / "defs").mkdir()
    with open(os.path.join(REFERENCE, sorted(os.listdir(REFERENCE))[0])) as f:
        (tmp_path / "defs" / "m.json").write_text(f.read())
    (tmp_path / "work").mkdir()
    monkeypatch.chdir(tmp_path / "work")
    assert bmtree(["modules", str(tmp_path / "defs")]) == 0
    assert "(%s)" % (tmp_path / "defs" / "m.json") in capsys.readouterr().out
    monkeypatch.chdir(tmp_path)
    assert bmtree(["modules", "defs"]) == 0
    assert "(defs/m.json)" in capsys.readouterr().out
