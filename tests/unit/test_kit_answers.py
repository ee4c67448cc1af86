"""What the pytest kit answers a test writer: an input the tree does not declare is an error (a typo ran
the default and the test passed without testing it); ``run.statuses(name)`` of a subtree included twice
names both nodes when they differ instead of answering for the first; a failed ``assert run.succeeded``
shows how the run ended and why."""
from __future__ import annotations

import os

import pytest

from coordinator.errors import UsageError
from coordinator.testing.kit import TreeTest

GO = """format: 1
name: go
inputs:
  place: {}
root:
  call: navigation.go_to
  name: drive
  inputs: {place: $place}
"""
TWICE = """format: 1
name: twice
inputs:
  first: {default: kitchen}
root:
  sequence:
    - include: go.yaml
      args: {place: $first}
    - force_success:
        include: go.yaml
        args: {place: bedroom}
"""


@pytest.fixture
def twice(tmp_path, sim_defs):
    (tmp_path / "go.yaml").write_text(GO)
    (tmp_path / "twice.yaml").write_text(TWICE)
    return str(tmp_path / "twice.yaml"), sim_defs


def test_an_input_the_tree_does_not_declare_is_refused_with_a_suggestion(twice):
    path, defs = twice
    with pytest.raises(UsageError) as e:
        TreeTest(path, definitions=defs, inputs={"frist": "hall"})
    assert str(e.value) == "%s declares no input 'frist' (did you mean 'first'?) (its inputs: first)" % path
    assert TreeTest(path, definitions=defs, inputs={"first": "hall"}).inputs == {"first": "hall"}


def test_statuses_of_a_name_two_included_nodes_share_names_both_when_they_differ(twice):
    path, defs = twice
    t = TreeTest(path, definitions=defs)
    t.mocks["navigation.go_to"].respond(lambda place: {"success": place == "kitchen", "room": place})
    run = t.run()
    assert run.succeeded
    with pytest.raises(KeyError) as e:
        run.statuses("drive")
    said = str(e.value)
    assert "2 nodes named 'drive' ran, through different statuses" in said
    assert "0: go.yaml:6:3 (in go(place=$first) at twice.yaml:7:7) ['RUNNING', 'SUCCESS']" in said, said
    assert "1: go.yaml:6:3 (in go(place=bedroom) at twice.yaml:10:9) ['RUNNING', 'FAILURE']" in said, said
    assert run.statuses("drive", 1) == ["RUNNING", "FAILURE"] and run.statuses("drive", 0) == ["RUNNING", "SUCCESS"]
    with pytest.raises(KeyError, match=r"nth is 0 to 1"):
        run.statuses("drive", 2)
    t.mocks["navigation.go_to"].respond(lambda place: {"success": True, "room": place})
    assert t.run().statuses("drive") == ["RUNNING", "SUCCESS"]   # the same for both: no question which


def test_a_failed_run_shows_its_reason_where_an_assert_prints_it(twice):
    path, defs = twice
    t = TreeTest(path, definitions=defs)
    t.mocks["navigation.go_to"].fail("blocked by a chair", delay=1.5)
    run = t.run()
    assert repr(run) == ("<TreeRun FAILURE in 1.50 s: drive: navigation.go_to failed: blocked by a chair "
                         "(at %s/go.yaml:6:3 in go(place=\"kitchen\"))>" % os.path.dirname(path)), repr(run)


def test_a_module_error_of_several_lines_keeps_its_summary_row_one_line(twice):
    from coordinator.runner import summary_lines

    path, defs = twice
    t = TreeTest(path, definitions=defs)
    t.mocks["navigation.go_to"].fail("planner failed:\n  joint 3 at its limit")
    lines = summary_lines(t.run().result, "twice")
    row = [line for line in lines if "navigation.go_to" in line and line.startswith("  +")]
    assert len(row) == 1 and "planner failed:\\n  joint 3 at its limit  inputs {\"place\":\"kitchen\"}" in row[0], lines
    assert lines[lines.index(row[0]) + 1:] == [], lines   # nothing of it spills onto a line of its own
