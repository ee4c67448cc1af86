"""Coverage of a tree that was loaded but never run (its scenario file is invalid, its tests ended before
``t.run()``): one line saying so, not every node "never ran"."""
from __future__ import annotations

import os

from coordinator.cli import main as bmtree
from coordinator.testing import Coverage, TreeTest
from tests.conftest import TREES

GOOD = "tree: %s\nscenarios:\n  - name: ok\n    mocks:\n      vision.find_object: {succeed: {success: true}}\n"
# valid up to its second scenario: the first one's TreeTest loads the tree, then the file is refused
INVALID = "tree: %s\nscenarios:\n  - name: fine\n  - name: typo\n    mokcs: {}\n"


def _report(out: str) -> str:
    return out.split("bmtree tree coverage\n", 1)[1]


def test_the_tree_of_an_invalid_scenario_file_is_said_once(tmp_path, capsys):
    good, bad = tmp_path / "good.yaml", tmp_path / "bad.yaml"
    good.write_text(GOOD % os.path.join(TREES, "find_apple.yaml"))
    bad.write_text(INVALID % os.path.join(TREES, "greet_guest.yaml"))
    assert bmtree(["test", "--coverage", str(good), str(bad)]) == 2
    captured = capsys.readouterr()
    assert "unknown scenario key 'mokcs'" in captured.err
    report = _report(captured.out)
    greet = [line for line in report.splitlines() if "greet_guest.yaml" in line]
    assert greet == ["trees/greet_guest.yaml: did not run: no scenario or test of it ran (an invalid scenario file, "
                     "or a test that ended before t.run()); its 10 nodes are not counted"], report
    assert "trees/find_apple.yaml: 7 of 9 nodes ran" in report
    assert "trees/find_apple.yaml:33: call 'say I could not find it' never ran" in report   # a tree that ran: each node


def test_a_tree_another_file_ran_is_reported_node_by_node(tmp_path, capsys):
    good, bad = tmp_path / "good.yaml", tmp_path / "bad.yaml"
    good.write_text(GOOD % os.path.join(TREES, "find_apple.yaml"))
    bad.write_text(INVALID % os.path.join(TREES, "find_apple.yaml"))
    assert bmtree(["test", "--coverage", str(bad), str(good)]) == 2
    report = _report(capsys.readouterr().out)
    assert "did not run" not in report and "trees/find_apple.yaml: 7 of 9 nodes ran" in report


def test_the_kits_coverage_of_a_tree_never_run():
    cov = Coverage()
    t = TreeTest(os.path.join(TREES, "find_apple.yaml"), coverage=cov)   # e.g. a test that failed at its script
    report = cov.report()
    assert "trees/find_apple.yaml: did not run: no scenario or test of it ran" in report, report
    assert "trees/search_room.yaml: did not run" in report and "never ran" not in report   # its include too
    t.run()
    report = cov.report()
    assert "did not run" not in report and "trees/find_apple.yaml: 7 of 9 nodes ran" in report, report
    # a tree whose nodes a visitor of an older caller (not told which tree) reached did run
    cov2 = Coverage()
    cov2.add_tree(t.tree)
    cov2.reached.update(cov.reached)
    assert "did not run" not in cov2.report()
