"""``expect: calls`` may say how a call ended (``status:``, ``error:`` beside its ``module.function``):
a scenario, not only a pytest test, can assert that the follow was halted or the grasp failed."""
from __future__ import annotations

import textwrap

import pytest

from coordinator.cli import main as bmtree

TREE = """\
format: 1
root:
  sequence:
    - force_success:
        call: navigation.go_to
        inputs: {place: kitchen}
    - parallel:
        policy: one
        children:
          - wait: 1
          - call: navigation.go_to
            inputs: {place: hall}
"""
MOCKS = "    mocks:\n      navigation.go_to: [{fail: door locked}, {succeed: {}, delay: 5}]\n"


def _scenarios(tmp_path, expect_calls: str) -> str:
    (tmp_path / "t.yaml").write_text(TREE)
    f = tmp_path / "t.scenarios.yaml"
    f.write_text("tree: t.yaml\nscenarios:\n  - name: s\n" + MOCKS + "    expect:\n      calls:\n"
                 + textwrap.indent(textwrap.dedent(expect_calls), "        "))
    return str(f)


def _test(path, capsys):
    code = bmtree(["test", path])
    out = capsys.readouterr()
    assert "Traceback" not in out.err, out.err
    return code, out.out.splitlines()[1:-1], out.err


def test_statuses_and_error_text_that_hold_pass(tmp_path, capsys):
    path = _scenarios(tmp_path, """\
        - navigation.go_to: {place: kitchen}
          status: failed
          error: locked
        - navigation.go_to:
          status: halted
        """)
    code, lines, _ = _test(path, capsys)
    assert code == 0 and lines == [], lines


def test_an_ending_that_differs_is_said_with_the_made_calls_endings(tmp_path, capsys):
    path = _scenarios(tmp_path, """\
        - navigation.go_to: {place: kitchen}
          status: succeeded
          error: blocked
        - navigation.go_to:
          status: halted
        """)
    code, lines, _ = _test(path, capsys)
    assert code == 1
    assert [ln.strip() for ln in lines] == [
        'call 1 (navigation.go_to): it ended failed: door locked, expected succeeded; its error is "door locked", '
        'expected one containing "blocked"',
        "calls changed (- expected only, + made only, = both):",
        '+ navigation.go_to {"place": "kitchen"} (failed: door locked)',
        '- navigation.go_to {"place": "kitchen"} (succeeded, error containing "blocked")',
        "= navigation.go_to (halted)"], lines


def test_in_order_matches_a_call_by_its_ending_too(tmp_path, capsys):
    path = _scenarios(tmp_path, """\
        in_order:
          - navigation.go_to:
            status: halted
        """)
    assert _test(path, capsys)[0] == 0
    path = _scenarios(tmp_path, """\
        in_order:
          - navigation.go_to:
            status: succeeded
        """)
    code, lines, _ = _test(path, capsys)
    assert code == 1
    assert [ln.strip() for ln in lines[:3]] == [
        "calls in order: expected call 1 of 1, navigation.go_to (succeeded), not found from the start of the run",
        "call 1 (navigation.go_to): it ended failed: door locked, expected succeeded",
        "call 2 (navigation.go_to): it ended halted: halted by the tree, expected succeeded"], lines


@pytest.mark.parametrize("ending, error", [
    ("status: fialed", "9:19: status of an expected call is how it ended: one of succeeded, failed, rejected, "
                       "cancelled, timeout, halted, module_lost, got 'fialed' (did you mean 'failed'?)"),
    ("status: running", "9:19: status of an expected call is how it ended: one of succeeded, failed, rejected, "
                        "cancelled, timeout, halted, module_lost, got 'running'"),
    ("error: [x]", "9:18: error of an expected call is a text its error must contain (\"blocked\"), got ['x']"),
])
def test_a_bad_ending_is_an_error_of_the_file_where_it_is(tmp_path, capsys, ending, error):
    path = _scenarios(tmp_path, "- navigation.go_to: {place: kitchen}\n  %s\n" % ending)
    code, _, err = _test(path, capsys)
    assert code == 2
    assert "%s:%s" % (path, error) in err.splitlines(), err
