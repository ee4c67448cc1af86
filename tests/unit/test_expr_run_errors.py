"""What Python refuses on the values a run holds fails the node that worked the expression out, never the
run (an audit crashed a live run with round(nan), and spun one for ever squaring a number in a loop)."""
from __future__ import annotations

import pytest

from coordinator.testing.kit import TreeTest

TREE = """format: 1
name: t
inputs:
  x: {default: 1.0}
root:
  sequence:
    - set: {y: $x}
    - %s
cleanup:
  call: speech.say
  inputs: {text: bye}
"""


@pytest.mark.parametrize("x,node,reason", [
    (".nan", "check: 'round(y) > 0'", "cannot convert float NaN to integer"),
    (".inf", "check: 'round(y) > 0'", "cannot convert float infinity to integer"),
    ("1" + "0" * 400, "check: 'y / 3 > 0'", "the result is too large"),
    ("3", "repeat: 40\n      child: {set: {y: '$(y * y)'}}", "more than a number may have (308)"),
])
def test_the_node_fails_with_the_reason_and_the_cleanup_runs(tmp_path, sim_defs, x, node, reason):
    path = tmp_path / "t.yaml"
    path.write_text(TREE % node)
    t = TreeTest(str(path), definitions=sim_defs, inputs={"x": __import__("yaml").safe_load(x)})
    run = t.run()
    assert run.failed and reason in run.reason, run.reason
    assert run.cleanup_status == "SUCCESS"
