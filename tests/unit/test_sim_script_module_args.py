"""``bmtree run --sim --module DEF.json=SCRIPT.yaml``: a scripted stand-in for a module not written yet, its
script checked against the definition before anything starts (``SCRIPT:LINE:COLUMN``, exit 2)."""
from __future__ import annotations

import json

import pytest

from coordinator.cli import main
from coordinator.usermodule import user_module

ARM = {"Basic Module": "arm", "Brief Description": "", "Hardware Required": [], "Functions": [
    {"Name": "grasp", "Exec-condition": "", "Description": "",
     "Input-params": [{"Name": "object", "Data-type": "std_msgs/String", "Description": ""}],
     "Output-params": [{"Name": "holding", "Data-type": "std_msgs/Bool", "Description": ""}]}]}
TREE = "format: 1\nroot:\n  call: arm.grasp\n  inputs: {object: cup}\n"


@pytest.fixture
def arm(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "arm.json").write_text(json.dumps(ARM))
    (tmp_path / "t.yaml").write_text(TREE)
    return tmp_path


def test_a_yaml_after_the_definition_is_a_scripted_stand_in(arm):
    (arm / "arm.yaml").write_text("module: arm\nfunctions:\n  grasp:\n    - fail: slipped\n")
    um = user_module("arm.json=arm.yaml")
    assert um.script == str(arm / "arm.yaml") and um.executable is None and um.class_spec == ""
    assert um.definition.name == "arm" and um.definition_path == str(arm / "arm.json")


@pytest.mark.parametrize("script, said", [
    ("module: arms\nfunctions: {}\n", "arm.yaml:1:9: no module 'arms' in the definitions (did you mean 'arm'?)"),
    ("module: arm\nfunctions:\n  grap: [{fail: x}]\n",
     "arm.yaml:3:3: module 'arm' has no function 'grap' (did you mean 'grasp'?)"),
    ("module: arm\nfunctions:\n  grasp: [{succeed: {holdin: true}}]\n",
     "arm.yaml:3:22: arm.grasp has no output 'holdin' (did you mean 'holding'?)"),
])
def test_a_wrong_script_is_said_where_it_is_before_anything_starts(arm, capsys, script, said):
    (arm / "arm.yaml").write_text(script)
    assert main(["run", "--sim", "--module", "arm.json=arm.yaml", "t.yaml"]) == 2
    out = capsys.readouterr()
    assert out.err.startswith(said) and "Traceback" not in out.err, out.err
    assert "starting the simulated robot" not in out.out + out.err


def test_a_missing_script_is_one_line(arm, capsys):
    assert main(["run", "--sim", "--module", "arm.json=nope.yaml", "t.yaml"]) == 2
    assert capsys.readouterr().err == "error: --module arm.json=nope.yaml: no such file nope.yaml\n"
