"""Positions made on demand: the loader keeps libyaml's marks and events, readers always get a Pos."""
from __future__ import annotations

from coordinator.errors import Pos
from coordinator.language import Parser
from coordinator.treeast import TreeNode
from coordinator.yamlsrc import LList, LMap, load_yaml, settle

TEXT = "a: &x {'k': \"v\"}\nb:\n  - *x\n  - plain\n  - |\n    block\n? k2\n: !!str 'tagged'\nc: &y 'anchored'\n"


def test_every_position_read_is_a_pos_and_stays_the_same():
    data = load_yaml(TEXT, "t.yaml")
    assert data.pos == Pos("t.yaml", 1, 1)
    assert data["a"].key_pos["k"] == Pos("t.yaml", 1, 9)            # inside the quote
    assert data["a"].val_pos["k"] == Pos("t.yaml", 1, 14)
    assert data.val_pos["a"] == Pos("t.yaml", 1, 4)                 # a flow mapping (its anchor)
    assert data["b"].item_pos == [Pos("t.yaml", 3, 5), Pos("t.yaml", 4, 5), Pos("t.yaml", 5, 5)]
    assert data.key_pos["k2"] == Pos("t.yaml", 7, 3)
    assert data.val_pos["k2"] == Pos("t.yaml", 8, 4)                # a tag, then a quote: as ever
    assert data.val_pos["c"] == Pos("t.yaml", 9, 5)
    assert all(p.__class__ is Pos for m in (data, data["a"]) for d in (m.key_pos, m.val_pos) for p in d.values())
    assert data.key_pos is data.key_pos and data["b"].item_pos is data["b"].item_pos


def test_a_container_read_first_through_its_parent():
    data = load_yaml("x:\n  - {a: 1}\n", "t.yaml")
    assert data["x"].item_pos[0] == Pos("t.yaml", 2, 5)
    assert data["x"][0].pos == Pos("t.yaml", 2, 5) and data["x"][0].key_pos == {"a": Pos("t.yaml", 2, 6)}


def test_maps_and_lists_made_by_hand():
    m = LMap(a=1)
    m.pos, m.key_pos, m.val_pos = Pos("f", 1, 1), {"a": Pos("f", 1, 1)}, {"a": Pos("f", 1, 4)}
    assert (m.pos, m.key_pos["a"], m.val_pos["a"]) == (Pos("f", 1, 1), Pos("f", 1, 1), Pos("f", 1, 4))
    seq = LList([1])
    seq.pos, seq.item_pos = Pos("f", 2, 1), [Pos("f", 2, 3)]
    assert seq.item_pos == [Pos("f", 2, 3)] and seq.pos == Pos("f", 2, 1)
    assert getattr(LMap(), "pos", None) is None and getattr(LList(), "item_pos", None) is None
    assert settle(("f", 1, 2), "g") == ("f", 1, 2)


def test_setting_a_loaded_position_keeps_the_others():
    data = load_yaml("a: 1\nb: 'x'\n", "t.yaml")
    data.key_pos = dict(data.key_pos, a=Pos("u", 9, 9))
    assert data.val_pos["b"] == Pos("t.yaml", 2, 5) and data.key_pos["a"] == Pos("u", 9, 9)


def test_tree_nodes_read_their_positions_when_asked():
    p = Parser({}, lambda path: "format: 1\nroot:\n  sequence:\n    - check: '1 +'\n    - check: ''\n")
    p.load_file("t.yaml", None)
    assert [str(e) for e in p.errors] == ["t.yaml:4:18: bad expression: expected a value, found 'end of expression'",
                                          "t.yaml:5:15: check takes an expression string, e.g. 'answer == \"yes\"'"]
    p = Parser({}, lambda path: "format: 1\nroot:\n  sequence:\n    - 'check': 'x > 1'\n")
    leaf = p.load_file("t.yaml", None).root.children[0]
    assert (leaf.pos, leaf.value_pos) == (Pos("t.yaml", 4, 8), Pos("t.yaml", 4, 17))
    node = TreeNode("check", "c", Pos("f", 1, 1), value_pos=Pos("f", 1, 8))
    node.pos = Pos("f", 2, 1)
    assert (node.pos, node.value_pos) == (Pos("f", 2, 1), Pos("f", 1, 8))
