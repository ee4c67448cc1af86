"""YAML with positions, read from libyaml's events: the same values as PyYAML's safe loader."""
from __future__ import annotations

import re

import pytest
import yaml

from comm.textfile import read_text, text_pos
from coordinator import yamlsrc
from coordinator.errors import TreeErrors
from coordinator.yamlsrc import MAX_NODES, load_value, load_yaml

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
    expected = yaml.safe_load(TEXT)
    assert expected["list"][4] == "1e3"
    expected["list"][4] = 1000.0   # a number, as YAML 1.2 and JSON read it (PyYAML's YAML 1.1 wants 1.0e3)
    assert data == expected
    assert data["copy"] is data["base"] and data["more"] is data["list"]
    assert data["tagged"] == "5" and data["empty"] is None


@pytest.mark.parametrize("text,value", [
    ("5e-1", 0.5), ("-2E3", -2000.0), ("+1e+2", 100.0), (".5e1", 5.0), ("1.5e-3", 0.0015), ("1e", "1e"),
    ("'5e-1'", "5e-1"), ("e5", "e5"), ("1_0e1", "1_0e1"),
])
def test_exponents_without_a_dot_are_numbers(text, value):
    """``--set x=5e-1`` gave text, which a float input refused only when its call was built, mid-run."""
    assert load_value(text, "--set x") == value and type(load_value(text, "--set x")) is type(value)


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
    ("a: *nothing\n", "1:4: found undefined alias 'nothing' (an alias *NAME must come after its anchor &NAME)"),
    ("a: &x [1, *x]\n", "1:11: alias *x is inside the node anchored &x: a value cannot contain itself"),
    ("a: &x {b: [*x]}\n", "1:12: alias *x is inside the node anchored &x"),
    ("a: 1\n---\nb: 2\n", "expected a single document"),
    ("a: [1\n", "YAML syntax error"),
    ("a: !!python/object:os.system x\n", "YAML syntax error"),
    ("[" * 500 + "]" * 500, "nested too deeply"),
    ("a: !!bool x\n", "1:4: cannot read 'x' as tag:yaml.org,2002:bool"),      # KeyError inside PyYAML
    ("a: !!int ''\n", "1:4: cannot read '' as tag:yaml.org,2002:int"),        # IndexError inside PyYAML
])
def test_bad_yaml_is_a_positioned_error(text, message):
    with pytest.raises(TreeErrors, match=re.escape(message)):
        load_yaml(text, "t.yaml")


def test_every_scalar_counts_toward_the_node_limit_and_only_aliases_are_blamed_for_aliases():
    flat = "[" + "1," * MAX_NODES + "1]"   # plain scalars alone: no alias to blame
    with pytest.raises(TreeErrors) as info:
        load_yaml(flat, "t.yaml")
    (error,) = info.value.errors
    assert error.message == "the document has more than %d YAML nodes" % MAX_NODES
    assert error.pos == ("t.yaml", 1, 2 * MAX_NODES)   # the list and 200,000 scalars: the last one crosses it
    bomb = "".join("a%d: &a%d [%s]\n" % (i, i, ", ".join(["*a%d" % (i - 1) if i else "x"] * 10)) for i in range(8))
    with pytest.raises(TreeErrors, match="expands to more than %d YAML nodes through its aliases" % MAX_NODES):
        load_yaml(bomb, "t.yaml")


@pytest.mark.parametrize("text,where,message", [
    ('format: 1\nname: x\nroot: {call: speech.say, inputs: {text: "a\x01b"}}\n', "t.yaml:3:43",
     "YAML error: unacceptable character #x0001: control characters are not allowed"),
    ("é: ü\n# ok\nb: c\x00d\n", "t.yaml:3:5", "YAML error: unacceptable character #x0000: control characters "
                                             "are not allowed"),
    ("a: 1\nb: x\udcff\n", "t.yaml:2:5", "not UTF-8 text: byte 0xff"),   # an undecodable command-line byte
])
def test_bad_characters_are_one_line_at_their_line_and_column(text, where, message):
    with pytest.raises(TreeErrors) as info:
        load_yaml(text, "t.yaml")
    assert str(info.value) == "%s: %s" % (where, message)


def test_text_over_the_size_cap_is_refused_before_parsing(monkeypatch):
    monkeypatch.setattr(yamlsrc, "MAX_BYTES", 100)
    with pytest.raises(TreeErrors, match="t.yaml:1:1: the document is larger than"):
        load_yaml("a: [" + "1, " * 50 + "]", "t.yaml")


def test_read_text_reads_no_more_than_the_cap_and_refuses_devices(tmp_path):
    small = tmp_path / "t.yaml"
    small.write_bytes(b"a" * 100)
    assert read_text(str(small), limit=100) == "a" * 100
    with pytest.raises(OSError, match="larger than 99 bytes"):
        read_text(str(small), limit=99)
    with pytest.raises(OSError, match="not a regular file"):
        read_text("/dev/zero")
    small.write_bytes(b"a: 1\nb: \xc3\x28\n")
    with pytest.raises(UnicodeDecodeError) as info:
        read_text(str(small))
    assert text_pos(info.value.object, info.value.start) == (2, 4)


def test_load_value_gives_plain_containers_with_the_same_limits():
    value = load_value("{a: &x [1, {b: 2}], c: *x}", "--set v")
    assert value == {"a": [1, {"b": 2}], "c": [1, {"b": 2}]}
    assert type(value) is dict and type(value["a"]) is list and type(value["a"][1]) is dict
    assert value["c"] is value["a"]   # aliases share, as with yaml.safe_load
    deep = load_value("[" * 300 + "]" * 300, "--set v")
    for _ in range(299):
        deep = deep[0]
    assert deep == []
    with pytest.raises(TreeErrors, match="nested too deeply"):
        load_value("[" * 500 + "]" * 500, "--set v")


@pytest.mark.parametrize("text,where,says", [
    # a key indented less than the list item it belongs to (the audit's m4.yaml)
    ("format: 1\nroot:\n  sequence:\n    - call: speech.say\n      inputs: {text: hi}\n  - call: speech.say\n",
     "t.yaml:6:3", "did not find expected key (in the mapping that starts at line 3, column 3): check the "
                   "indentation of this line and the one before"),
    # a key indented one column short of the item's keys
    ("root:\n  - call: speech.say\n    inputs: {text: hi}\n   name: x\n",
     "t.yaml:4:4", "did not find expected '-' indicator (in the list that starts at line 2, column 3): check "
                   "the indentation of this line and the one before: every item of a list starts with '- '"),
    # a key indented deeper than the keys above it
    ("root:\n  call: speech.say\n  name: x\n    inputs: {text: hi}\n",
     "t.yaml:4:11", "mapping values are not allowed in this context: a ': ' inside a value that is not quoted, "
                    "or a key indented deeper than the keys above it"),
    ("root:\n  name: note: hi\n", "t.yaml:2:13", "quote the value"),
    ("root:\n\tsequence: []\n", "t.yaml:2:1", "a tab: YAML indents with spaces only"),
    ("root:\n  call: speech.say\n  inputs: {text: $people[0]}\n", "t.yaml:3:25",
     "did not find expected ',' or '}': inside { } or [ ], a value holding [ ] or { } must be quoted"),
])
def test_common_yaml_syntax_errors_say_what_to_fix(text, where, says):
    with pytest.raises(TreeErrors) as info:
        load_yaml(text, "t.yaml")
    (error,) = info.value.errors
    assert str(error).startswith(where + ": YAML syntax error: ") and says in error.message, str(error)
