"""Two mistakes of a team coming from SMACH that ``bmtree check`` now explains: an include path written from
the working folder (it is relative to the including file), and ``outputs:`` written in the remapping's
order (tree key: output)."""
from __future__ import annotations

import os

import pytest

from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from modules.definition import load_definitions
from modules.sim import SIM_DIR

DEFS = load_definitions([SIM_DIR])


def _errors(path):
    with pytest.raises(TreeErrors) as e:
        load_tree(str(path), DEFS)
    return [str(x) for x in e.value.errors]


def test_an_include_written_from_the_working_folder_says_what_to_write(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    os.mkdir("trees")
    with open("trees/ask.yaml", "w") as fh:
        fh.write("format: 1\nname: ask\nroot:\n  wait: 1\n")
    with open("trees/main.yaml", "w") as fh:
        fh.write("format: 1\nname: main\nroot:\n  sequence:\n    - include: trees/ask.yaml\n    - include: nothere.yaml\n")
    assert _errors("trees/main.yaml") == [
        "trees/main.yaml:5:16: cannot read trees/trees/ask.yaml: No such file or directory (an include's path is "
        "relative to the folder of the file that includes it, trees/: write ask.yaml)",
        "trees/main.yaml:6:16: cannot read trees/nothere.yaml: No such file or directory"]


def test_outputs_in_the_remapping_order_say_the_mapping_the_other_way(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  sequence:\n    - call: speech.listen\n      inputs: {seconds: 5}\n"
                    "      outputs: {guest_name: text}\n    - wait_event: vision.personSeen\n      outputs: {who: persn}\n")
    assert [e.replace(str(path), "t.yaml") for e in _errors(path)] == [
        "t.yaml:6:17: speech.listen has no output 'guest_name'; outputs maps output name → tree key: did you mean "
        "{text: guest_name}?",
        "t.yaml:8:17: vision.personSeen has no event param 'who' (event params: person, position)"]
