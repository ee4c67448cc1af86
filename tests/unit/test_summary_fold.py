"""A long run's summary counts the middle of its calls instead of listing them: a patrol of hundreds of calls
printed one line each, so its reason (printed above them) scrolled off the screen."""
from __future__ import annotations

import re

from coordinator.runner import summary_lines
from coordinator.testing import TreeTest, fail, succeed
from tests.unit.test_engine import tree

LOOP = """
root:
  sequence:
    - repeat: %d
      child:
        sequence:
          - call: speech.say
            inputs: {text: step}
          - selector:
              - call: navigation.go_to
                inputs: {place: door}
              - call: speech.say
                inputs: {text: door closed}
    - call: navigation.go_to
      inputs: {place: the end}
"""


def _run(tmp_path, rounds):
    t = TreeTest(tree(tmp_path, LOOP % rounds))
    t.mocks["speech.say"].script(succeed())
    t.mocks["navigation.go_to"].script(fail("blocked"))
    return t.run()


def _rows(lines):
    return [line for line in lines if line.startswith("  +")]


def test_a_long_run_lists_its_first_and_last_calls_the_failing_one_and_counts_the_rest(tmp_path):
    run = _run(tmp_path, 100)   # 301 calls
    lines = summary_lines(run.result, "patrol", "bmtree replay lists them from the run log")
    assert lines[2] == "reason: navigation.go_to failed: blocked", lines[:4]
    rows = _rows(lines)
    assert len(rows) == 40 and len(lines) < 50, lines
    folded = [line for line in lines if line.startswith("  …")]
    assert folded == ["  … 261 calls not listed (174 succeeded, 87 failed): bmtree replay lists them from the "
                      "run log"], folded
    assert lines[lines.index("calls:") + 11] == folded[0]   # after the first 10
    assert rows[-1].endswith('inputs {"place":"the end"}')   # the failing call, with its inputs
    starts = [float(re.match(r"  \+\s*([\d.]+)s", r).group(1)) for r in rows]
    assert starts == sorted(starts)


def test_a_short_run_lists_every_call(tmp_path):
    run = _run(tmp_path, 19)   # 58 calls
    lines = summary_lines(run.result, "patrol")
    assert len(_rows(lines)) == 58 and not [line for line in lines if line.startswith("  …")]


def test_a_call_in_the_middle_that_may_still_be_running_is_listed(tmp_path):
    run = _run(tmp_path, 100)
    middle = run.result.calls[150]
    middle.cancel_sent = True   # a cancel its module never answered
    lines = summary_lines(run.result, "patrol")
    assert len(_rows(lines)) == 41 and len([line for line in lines if line.startswith("  …")]) == 2
    assert any("may still be running: its module did not answer the cancel" in line for line in lines)
    assert "  … 140 calls not listed (93 succeeded, 47 failed)" in lines, lines
