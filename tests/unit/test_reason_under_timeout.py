"""The run's reason of a call that failed by itself under an unnamed ``timeout`` does not begin with
"timeout 40s:", which reads as if the time ran out; a timeout that did run out still says so."""
from __future__ import annotations

import os

import pytest

from coordinator.testing import fail
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA, one_file_trees

DEFS = load_definitions([SIM_DIR, os.path.join(DATA, "modules_lang")])


@pytest.fixture
def tree(tmp_path, bmtree_tree):
    return one_file_trees(tmp_path, bmtree_tree, DEFS)


def test_a_call_failing_under_a_timeout_is_named_by_itself(tree):
    t = tree("  timeout: 40\n  child: {call: navigation.go_to, inputs: {place: kitchen}}\n")
    t.mocks["navigation.go_to"].script(fail("blocked"))
    run = t.run()
    assert run.failed and run.reason == "navigation.go_to failed: blocked", run.reason


def test_a_named_ancestor_still_says_where(tree):
    t = tree("  sequence:\n    - timeout: 40\n      child:\n        sequence:\n          name: fetch\n"
             "          children:\n            - {call: navigation.go_to, inputs: {place: kitchen}}\n")
    t.mocks["navigation.go_to"].script(fail("blocked"))
    run = t.run()
    assert run.failed and run.reason == "fetch: navigation.go_to failed: blocked", run.reason


def test_a_timeout_that_ran_out_says_so(tree):
    t = tree("  timeout: 1\n  child: {wait: 5}\n")
    run = t.run()
    assert run.failed and run.reason == "timeout 1s: timed out after 1s while 'wait 5s' was running", run.reason
