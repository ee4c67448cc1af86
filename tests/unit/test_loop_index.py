"""``retry`` and ``repeat`` tell their child which attempt or run it is (``index:``), as ``for_each`` does:
a port of SMACH's "retry, but turn first from the second try on" needs it."""
from __future__ import annotations

import os

import pytest

from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from coordinator.testing import fail, succeed
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA, one_file_trees

DEFS = load_definitions([SIM_DIR, os.path.join(DATA, "modules_lang")])

TURN_BETWEEN_TRIES = """
  retry: 3
  index: attempt
  {delay}child:
    sequence:
      - selector:
          - check: attempt == 0
          - call: speech.say
            inputs: {{text: "attempt {{attempt + 1}}: let me look again"}}
      - call: navigation.go_to
        inputs: {{place: kitchen}}
"""


@pytest.fixture
def tree(tmp_path, bmtree_tree):
    return one_file_trees(tmp_path, bmtree_tree, DEFS)


def said(run):
    return [c.inputs["text"] for c in run.calls("speech.say")]


@pytest.mark.parametrize("delay", ["", "delay: 2\n  "])
def test_retry_writes_each_attempt_number_before_it_starts(tree, delay):
    t = tree(TURN_BETWEEN_TRIES.format(delay=delay))
    t.mocks["navigation.go_to"].script(fail("blocked"), fail("blocked"), succeed(room="kitchen"))
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == ["attempt 2: let me look again", "attempt 3: let me look again"]
    assert run.blackboard["attempt"] == 2
    if delay:   # the number changes when the next attempt starts, not when the delay begins
        say = run.calls("speech.say")
        gone = run.calls("navigation.go_to")
        assert [round(c.started - g.ended, 3) for c, g in zip(say, gone)] == [2.0, 2.0]


def test_a_retry_started_again_counts_from_zero(tree):
    t = tree("""
  repeat: 2
  child:
    retry: 2
    index: attempt
    child:
      sequence:
        - call: speech.say
          inputs: {text: "try {attempt}"}
        - call: navigation.go_to
          inputs: {place: kitchen}
""")
    t.mocks["navigation.go_to"].script(fail("blocked"), succeed(room="kitchen"), succeed(room="kitchen"))
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == ["try 0", "try 1", "try 0"]


def test_repeat_writes_each_run_number_and_while_may_read_it(tree):
    t = tree("""
  sequence:
    - repeat: 5
      index: run
      while: run < 3
      child:
        call: speech.say
        inputs: {text: "run {run}"}
    - repeat: 2
      index: n
      child:
        call: speech.say
        inputs: {text: "n {n}"}
    - check: run == 3 and n == 1
""")
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == ["run 0", "run 1", "run 2", "n 0", "n 1"]


def test_the_index_is_written_for_the_nodes_after_the_loop(tree):
    """The data-flow check knows the key: read after the loop (it ran at least once), no error."""
    t = tree("""
  sequence:
    - force_success:
        retry: 2
        index: tries
        child: {call: navigation.go_to, inputs: {place: kitchen}}
    - call: speech.say
      inputs: {text: "I tried {tries + 1} times"}
""")
    t.mocks["navigation.go_to"].script(fail("blocked"), fail("blocked"))
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == ["I tried 2 times"]


@pytest.mark.parametrize("loop", ["retry: 2", "repeat: 2"])
def test_an_index_that_is_no_key_is_refused_where_it_is(tmp_path, loop):
    path = tmp_path / "bad.yaml"
    path.write_text("format: 1\nroot:\n  %s\n  index: 3\n  child: {wait: 1}\n" % loop)
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), DEFS)
    assert [str(e).replace(str(path), "bad.yaml") for e in info.value.errors] == [
        "bad.yaml:4:10: 'index' must be a tree key (an identifier), got 3"]


def test_a_key_the_loop_does_not_write_is_still_an_error(tmp_path):
    """Without ``index:`` the key read is nobody's: the check says so (the option is what adds it)."""
    path = tmp_path / "bad.yaml"
    path.write_text("format: 1\nroot:\n  retry: 2\n  child: {check: attempt > 0}\n")
    with pytest.raises(TreeErrors) as info:
        load_tree(str(path), DEFS)
    assert "reads 'attempt', which no node writes" in str(info.value), str(info.value)


def test_the_language_reference_example_runs(tmp_path, bmtree_tree):
    """trees/README.md's ``retry`` with ``index:`` example, as written there."""
    from tests.unit.test_lang_parallel_include import readme_example

    path = tmp_path / "ref.yaml"
    path.write_text(readme_example("take `index: KEY`"))
    t = bmtree_tree(str(path), definitions=DEFS)
    t.mocks["vision.find_object"].script(fail("not seen"), succeed(position={"x": 1.0, "y": 2.0, "z": 0.0}))
    run = t.run()
    assert run.succeeded, run.reason
    assert said(run) == ["Let me look again (2 of 3)"]
