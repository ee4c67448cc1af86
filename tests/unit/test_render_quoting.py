"""``bmtree render``: any name draws (quotes and backslashes escaped in ids and labels, graphviz
reads the file), and a wide tree renders in time linear in its size (py_trees' ``dot_tree`` looked
every name up among all the names before it and made repeats unique with one more ``*`` each)."""
from __future__ import annotations

import shutil
import subprocess
import time

import pytest

from coordinator.cli import _label_cases, offline_tree
from coordinator.cli import main as bmtree
from coordinator.render import tree_graph

QUOTED = r"""format: 1
name: 'q"t\'
root:
  sequence:
    name: 'say "hi" \ back\'
    children:
      - wait: 1
        name: 'a "quoted" one'
      - wait: 1
        name: 'ends in a backslash\'
      - wait: 1
        name: 'wait 1s*2'
      - wait: 1
      - wait: 1
"""


def test_names_with_quotes_and_backslashes_are_escaped(tmp_path):
    tree = tmp_path / "q.yaml"
    tree.write_text(QUOTED)
    dot = tmp_path / "q.dot"
    assert bmtree(["render", str(tree), "-o", str(dot)]) == 0
    text = dot.read_text()
    assert text.startswith('digraph "q\\"t\\\\" {\n'), text
    root = '"say \\"hi\\" \\\\ back\\\\"'
    assert '\n%s [label="say \\"hi\\" \\\\ back\\\\\\nsequence", shape=box' % root in text, text
    assert '\n"a \\"quoted\\" one" [label="a \\"quoted\\" one\\nwait 1s", shape=ellipse' in text, text
    assert '\n%s -> "ends in a backslash\\\\";\n' % root in text, text
    # repeats: *2, *3 (a node named like one of them keeps its name, the repeat takes the next number)
    assert ['"wait 1s*2"', '"wait 1s"', '"wait 1s*3"'] == [
        line.split(" -> ")[1].rstrip(";") for line in text.splitlines() if " -> \"wait 1s" in line], text
    if shutil.which("dot"):   # graphviz reads it (it refused the file before: a syntax error)
        done = subprocess.run(["dot", "-Tsvg", str(dot)], capture_output=True)
        assert done.returncode == 0, done.stderr
        assert b"say &quot;hi&quot; \\ back\\</text>" in done.stdout


def test_a_wide_tree_renders_in_linear_time_and_size(tmp_path, sim_defs):
    n = 5000
    tree = tmp_path / "wide.yaml"
    tree.write_text("format: 1\nname: wide\nroot:\n  sequence:\n    children:\n" + "      - wait: 1\n" * n)
    t, root = offline_tree(str(tree), sim_defs)
    start = time.monotonic()
    text = tree_graph(t.name, root, _label_cases(root)).to_string()
    took = time.monotonic() - start
    assert text.count("\n\"sequence\" -> ") == n
    assert '"wait 1s*%d"' % n in text and "**" not in text
    assert len(text) < 200 * n   # each repeat's id grew by a '*': 25 MB for these 5000
    assert took < 20, took       # about 0.3 s; minutes before


@pytest.mark.parametrize("names", [["x", "x", "x*2", "x"], ["x*2", "x", "x"]])
def test_ids_stay_unique_whatever_the_names(names):
    from coordinator.render import _Ids

    ids = _Ids()
    given = [ids.new(name) for name in names]
    assert len(set(given)) == len(given)
