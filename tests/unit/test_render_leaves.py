"""``bmtree render``: a leaf's main argument is on its label when its name does not say it — a
``fail``'s text, a ``set``'s values, a ``wait_event``'s ``where:`` — cut to the label's length, as a
call's inputs are."""
from __future__ import annotations

from coordinator.cli import _label_cases, offline_tree
from coordinator.render import MAX_DETAIL, tree_graph
from tests.unit.test_lang_fail_where import DEFS

TREE = """format: 1
name: r
inputs:
  who: {default: Ana}
root:
  sequence:
    - set: {count: 0, place: $who}
    - set: {count: 1}
      name: reset
    - check: "count < 3"
    - wait_event: arm.fault
      where: "code > 2"
      outputs: {code: code}
    - wait_event: arm.fault
    - fail: "the arm has a problem (code {code})"
    - fail: "gave up on {who} after trying every room of the house twice over"
      name: give up
"""


def _labels(tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text(TREE)
    tree, root = offline_tree(str(path), DEFS)
    graph = tree_graph(tree.name, root, _label_cases(root))
    return {n.get_name().strip('"'): n.get_label().strip('"') for n in graph.get_nodes()
            if isinstance(n.get_label(), str)}


def test_render_shows_a_fail_leafs_text_bounded(tmp_path):
    labels = _labels(tmp_path)
    assert labels["fail"] == "fail\\n'the arm has a problem (code {code})'"
    named = labels["give up"].split("\\n")
    assert named[0] == "give up" and named[1].startswith("fail · 'gave up on {who} after")
    assert len(named[1]) == MAX_DETAIL and named[1].endswith("…")


def test_render_shows_a_sets_values_and_a_wait_events_where(tmp_path):
    labels = _labels(tmp_path)
    assert labels["set count, place"] == "set count, place\\ncount: 0, place: $who"
    assert labels["reset"] == "reset\\nset count · count: 1"
    assert labels["arm.fault"] == "arm.fault\\nwhere: code > 2"
    assert labels["arm.fault*2"] == "arm.fault"           # no where: nothing more to say
    assert labels["check count < 3"] == "check count < 3"  # its name says its expression already
