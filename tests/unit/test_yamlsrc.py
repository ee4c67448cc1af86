"""YAML with positions, read from libyaml's events: the same values as PyYAML's safe loader."""
from __future__ import annotations

import pytest
import yaml

from coordinator.errors import TreeErrors
from coordinator.yamlsrc import load_yaml

TEXT = """
base: &b {x: 1.0, y: -2, ok: yes, none: ~, when: 2024-01-02}
list: &l [a, 'b', "c", 0x10, 1e3, .inf, true, null]
copy: *b
more: *l
merged:
  <<: [*b, {z: 3}]
  name: m
tagged: !!str 5
empty:
multi: |
  two
  lines
"""


def test_values_match_the_safe_loader_and_aliases_share():
    data = load_yaml(TEXT, "t.yaml")
    assert data == yaml.safe_load(TEXT)
    assert data["copy"] is data["base"] and data["more"] is data["list"]
    assert data["tagged"] == "5" and data["empty"] is None


def test_a_merge_then_a_list_in_the_same_mapping():
    data = load_yaml("a: &x {k: 1}\nb:\n  <<: *x\n  list: [1, {m: 2}]\n", "t.yaml")
    assert data["b"] == {"k": 1, "list": [1, {"m": 2}]}
    assert data["b"].val_pos["list"] == ("t.yaml", 4, 9)


def test_positions_of_keys_values_items_and_quoted_scalars():
    data = load_yaml(TEXT, "t.yaml")
    assert data.key_pos["list"] == ("t.yaml", 3, 1)
    assert data.val_pos["list"] == ("t.yaml", 3, 7)
    assert str(data["list"].item_pos[1]) == "t.yaml:3:15"        # inside the quote
    assert data["merged"].key_pos["x"] == data["base"].key_pos["x"]  # a merged key keeps where it was written


@pytest.mark.parametrize("text,message", [
    ("a: 1\na: 2\n", "2:1: duplicate key 'a'"),
    ("a: &x {k: 1}\nb:\n  <<: *x\n  k: 2\n", "duplicate key 'k'"),
    ("? [a]\n: 1\n", "1:3: a mapping key must be a scalar"),
    ("a: *nothing\n", "found undefined alias"),
    ("a: 1\n---\nb: 2\n", "expected a single document"),
    ("a: [1\n", "YAML syntax error"),
    ("a: !!python/object:os.system x\n", "YAML syntax error"),
    ("[" * 500 + "]" * 500, "nested too deeply"),
    ("a: !!bool x\n", "1:4: cannot read 'x' as tag:yaml.org,2002:bool"),      # KeyError inside PyYAML
    ("a: !!int ''\n", "1:4: cannot read '' as tag:yaml.org,2002:int"),        # IndexError inside PyYAML
])
def test_bad_yaml_is_a_positioned_error(text, message):
    with pytest.raises(TreeErrors, match=message.replace("[", r"\[")):
        load_yaml(text, "t.yaml")
