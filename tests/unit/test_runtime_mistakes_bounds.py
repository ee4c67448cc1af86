"""A tree author's mistakes that only show when running fail the node that made them, with why, and the
cleanup runs: a value that doubles or nests itself in a loop (``set: {xs: [$xs, $xs]}``), a value nested
too deep to write as text, and counts and durations too large to mean anything (a loop of 1e300 runs, a
wait of 1e300 s). Before, the first spun (exponential time and memory writing it), the second raised
RecursionError out of the run, the third ran (nearly) for ever."""
from __future__ import annotations

import re

import pytest
import yaml

from coordinator.cli import main as bmtree
from coordinator.testing.kit import TreeTest

TREE = """format: 1
name: t
inputs:
  x: {default: 1}
  l: {default: [1, 2]}
root:
  sequence:
    - set: {xs: $l}
%s
cleanup:
  call: speech.say
  inputs: {text: bye}
"""


def _run(tmp_path, sim_defs, node, **inputs):
    path = tmp_path / "t.yaml"
    path.write_text(TREE % node)
    return TreeTest(str(path), definitions=sim_defs, inputs=inputs).run()


@pytest.mark.parametrize("node,reason", [
    ("    - repeat: 22\n      child: {set: {xs: [$xs, $xs]}}",
     "set xs: the value would hold more than 2097152 elements and characters"),
    ("    - repeat: 150\n      child: {set: {xs: [$xs]}}\n    - check: 'len(str(xs)) > 0'",
     "set xs: the value would nest more than 100 levels deep"),
    ("    - repeat: 150\n      child: {set: {xs: {a: $xs}}}\n    - call: speech.say\n      inputs: {text: '{xs}'}",
     "set xs: the value would nest more than 100 levels deep"),
], ids=["doubling", "nesting-list", "nesting-mapping"])
def test_a_value_growing_in_a_loop_fails_the_set_that_builds_it(tmp_path, sim_defs, node, reason):
    run = _run(tmp_path, sim_defs, node)
    assert run.failed and run.reason.startswith(reason), run.reason
    assert run.cleanup_status == "SUCCESS"


def test_a_value_given_too_deep_to_write_as_text_fails_the_node():
    deep = []
    for _ in range(600):
        deep = [deep]
    from coordinator.expr import Expr, ExprError

    with pytest.raises(ExprError, match="nests more than 100 levels deep, too deep to write as text"):
        Expr.parse("str(l)").value({"l": deep}.__getitem__)


@pytest.mark.parametrize("x", [1e300, 10 ** 20, 1000000001])
@pytest.mark.parametrize("node,reason", [
    ("    - retry: $x\n      child: {fail: nope}", "count of retry $x is %s, more than 1000000000"),
    ("    - repeat: $x\n      child: {set: {y: 1}}", "count of repeat $x is %s, more than 1000000000"),
    ("    - wait: $x", "duration of wait $x is %g seconds, more than a year"),
    ("    - timeout: $x\n      child: {wait: 100}", "duration of timeout $x is %g seconds, more than a year"),
    ("    - call: speech.say\n      inputs: {text: hi}\n      timeout: $x",
     "timeout of call $x is %g seconds, more than a year"),
    ("    - retry: 2\n      delay: $x\n      child: {fail: nope}", "delay of retry $x is %g seconds, more than a year"),
], ids=["retry", "repeat", "wait", "timeout", "call-timeout", "delay"])
def test_a_count_or_duration_too_large_fails_the_node_at_once(tmp_path, sim_defs, node, reason, x):
    run = _run(tmp_path, sim_defs, node, x=x)
    said = ("1e+300" if x == 1e300 else "1e+20" if x == 10 ** 20 else str(x)) if "count" in reason else x
    assert run.failed and (reason % said) in run.reason, run.reason
    assert run.duration == 0 and run.cleanup_status == "SUCCESS"


@pytest.mark.parametrize("node,where,message", [
    ("    - retry: 10000000000\n      child: {wait: 1}", "9:14", "count of retry is 10000000000, more than 1000000000"),
    ("    - repeat: $(100000 * 100000)\n      child: {wait: 1}", "9:15",
     "count of repeat is 10000000000, more than 1000000000"),
    ("    - wait: 1.0e+12", "9:13", "duration of wait is 1e+12 seconds, more than a year (31536000 s)"),
    ("    - call: speech.say\n      inputs: {text: hi}\n      timeout: 1.0e+12", "11:16",
     "timeout of call is 1e+12 seconds, more than a year"),
], ids=["retry", "repeat-expression", "wait", "call-timeout"])
def test_bmtree_check_says_a_count_or_duration_too_large(tmp_path, capsys, node, where, message):
    path = tmp_path / "t.yaml"
    path.write_text(TREE % node)
    assert bmtree(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert re.search(r"^%s:%s: %s" % (re.escape(str(path)), where, re.escape(message)), err, re.M), err


def test_the_largest_count_and_a_year_are_still_taken(tmp_path, capsys):
    path = tmp_path / "t.yaml"
    path.write_text(TREE % "    - retry: 1000000000\n      child: {wait: 1800}\n    - wait: 31536000")
    assert bmtree(["check", str(path)]) == 0, capsys.readouterr().err
    assert yaml.safe_load(path.read_text())["format"] == 1
