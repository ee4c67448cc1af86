"""Tree coverage says which nodes were halted (a parallel's other children, a timeout's child), not only
which succeeded or failed: "the follow was stopped by the stop word" is a path a test should reach."""
from __future__ import annotations

from coordinator.cli import main as bmtree

TREE = """format: 1
root:
  parallel:
    policy: one
    children:
      - {name: short, wait: 1}
      - {name: go, call: navigation.go_to, inputs: {place: kitchen}}
"""


def test_a_halted_node_is_said_so_in_the_coverage(tmp_path, capsys):
    (tmp_path / "t.yaml").write_text(TREE)
    f = tmp_path / "t.scenarios.yaml"
    f.write_text("tree: t.yaml\nscenarios:\n  - name: halted\n    mocks:\n      navigation.go_to: "
                 "[{succeed: {}, delay: 5}]\n")
    assert bmtree(["test", "--coverage", str(f)]) == 0
    lines = [ln.strip().replace(str(tmp_path / "t.yaml"), "t.yaml") for ln in capsys.readouterr().out.splitlines()]
    assert "t.yaml:7: call 'go' reached RUNNING, then halted; never SUCCESS, FAILURE" in lines, lines
    assert "t.yaml:6: wait 'short' reached SUCCESS; never FAILURE" in lines, lines
