"""The block YAML reader: where it answers, the same values, types and positions as libyaml's."""
from __future__ import annotations

import glob
import math
import os
import random
from typing import Any, List, Optional

import pytest

from coordinator.errors import TreeErrors
from coordinator.yamlblock import read_block
from coordinator.yamlsrc import LList, LMap, load_yaml, load_yaml_libyaml
from tests.conftest import ROOT


def _difference(a: Any, b: Any, path: str = "$") -> Optional[str]:
    """Where two loaded documents differ (value, type, order or any position), or None."""
    if type(a) is not type(b):
        return "%s: %r is not %r" % (path, type(a), type(b))
    if isinstance(a, LMap):
        for what in ("pos", "key_pos", "val_pos"):
            if getattr(a, what) != getattr(b, what):
                return "%s: %s %r != %r" % (path, what, getattr(a, what), getattr(b, what))
        if list(a) != list(b):
            return "%s: keys %r != %r" % (path, list(a), list(b))
        return next((d for d in (_difference(a[k], b[k], "%s.%s" % (path, k)) for k in a) if d), None)
    if isinstance(a, LList):
        if (a.pos, a.item_pos, len(a)) != (b.pos, b.item_pos, len(b)):
            return "%s: positions or length differ" % path
        return next((d for d in (_difference(x, y, "%s[%d]" % (path, i)) for i, (x, y) in enumerate(zip(a, b))) if d),
                    None)
    if isinstance(a, float) and math.isnan(a) and math.isnan(b):
        return None
    return None if a == b else "%s: %r != %r" % (path, a, b)


def _agrees(text: str) -> bool:
    """True if the block reader took the text (then it must agree with libyaml exactly)."""
    fast = read_block(text, "t.yaml")
    if fast is None:
        return False
    reference = load_yaml_libyaml(text, "t.yaml")   # raises if the block reader accepted bad YAML
    difference = _difference(fast, reference)
    assert difference is None, "%s\n---\n%s" % (difference, text)
    return True


TREE = """format: 1
# a comment
name: 'it''s'     # quoted, with a comment
root:
  sequence:
    memory: false
    children:
    - check: answer == "yes"
      name: first
    -   wait: 1.5
    - set:
        on: yes
        n: -3
        x: .nan
        null: ~
        list:
          - 0x1f
          - "a b"
          - a, b ]
"""


def test_a_plain_block_tree_is_read_as_libyaml_reads_it():
    assert _agrees(TREE)
    data = load_yaml(TREE, "t.yaml")
    assert data["name"] == "it's" and str(data.val_pos["name"]) == "t.yaml:3:8"  # inside the quote
    item = data["root"]["sequence"]["children"][2]["set"]
    assert item[True] is True and item[None] is None   # YAML 1.1: the key "on" is true and item["list"] == [31, "a b", "a, b ]"]
    assert str(data["root"]["sequence"]["children"].item_pos[1]) == "t.yaml:10:9"


@pytest.mark.parametrize("text", [
    "a: {b: 1}\n", "a: [1, 2]\n", "a: &x 1\nb: *x\n", "a: !!str 1\n", "a: |\n  text\n", "a:\n", "a: 1\na: 2\n",
    "a: b\n  c\n", "a: x: y\n", "a:\tb\n", "---\na: 1\n", "a: 2024-01-02\n", "a: 'open\n", "a: \"esc\\n\"\n",
    "a: 1\n b: 2\n", "- a\nb: 1\n", "just text\n", "", "a: b #c\n  - d\n", "<<: {a: 1}\n", "? a\n: b\n",
])
def test_anything_else_is_left_to_libyaml(text):
    assert read_block(text, "t.yaml") is None


def test_errors_keep_libyaml_positions():
    with pytest.raises(TreeErrors, match="t.yaml:3:1: duplicate key 'a'"):
        load_yaml("# c\na: 1\na: 2\n", "t.yaml")


def test_every_yaml_file_of_the_repository():
    paths = [p for p in glob.glob(os.path.join(ROOT, "**", "*.yaml"), recursive=True) if "/." not in p]
    taken = 0
    for path in paths:
        with open(path, encoding="utf-8", errors="replace") as fh:
            taken += _agrees(fh.read())
    assert taken >= 10


_KEYS = ["a", "name", "x_1", "yes", "1", "null", "true", "a.b", "a/b", "k-2", "1.5", "Z"]
_VALUES = ["b", "leaf 0", "'true'", "'it''s'", "''", '""', '"x y"', "1", "-1", "-.5", ".inf", ".nan", "0x1f",
           "1_000", "yes", "null", "~", "a, b", "x]", "it's", 'say "hi"', "é ü", "a - b", "x # c", "'q' # c",
           "a   ", "[a]", "&x y", "a:b", "a#b", "12:30", "2024-01-02", "|", "- x"]


def _document(rng: random.Random, depth: int = 0, indent: int = 0, out: Optional[List[str]] = None) -> List[str]:
    """Random block YAML: nested mappings and sequences, comments, blank lines, odd indents."""
    out = [] if out is None else out
    is_map = rng.random() < 0.6
    pad = " " * indent
    for _ in range(rng.randint(1, 4)):
        if rng.random() < 0.1:
            out.append(rng.choice(["", "   ", pad + "# c"]))
        key = rng.choice(_KEYS)
        spaces = rng.choice([" ", " ", "   "])
        if depth < 4 and rng.random() < 0.35:
            out.append(pad + ("" if is_map else "-" + spaces) + key + ":")
            below = indent + (0 if is_map else 1 + len(spaces))
            _document(rng, depth + 1, below + rng.choice([0, 1, 2, 2, 4]), out)
        elif is_map:
            out.append(pad + key + ": " + rng.choice(_VALUES))
        else:
            out.append(pad + "-" + spaces + rng.choice([key + ": ", ""]) + rng.choice(_VALUES))
    return out


def test_random_documents_and_mutations():
    rng = random.Random(11)
    taken = 0
    for _ in range(3000):
        lines = _document(rng)
        if rng.random() < 0.3:
            i = rng.randrange(len(lines))
            lines[i] = rng.choice([" " + lines[i], lines[i][1:], lines[i] + ": x", lines[i] + " #"])
        taken += _agrees("\n".join(lines) + rng.choice(["", "\n"]))
    assert taken > 300


def test_a_big_tree_read_in_chunks():
    leaves = "".join("      - check: 'n > %d'  # leaf\n        name: leaf %d\n\n" % (i, i) for i in range(1500))
    text = "format: 1\nroot:\n  sequence:\n    memory: false\n    children:\n" + leaves + "name: big\n"
    assert len(text) > 10 * 8192   # many chunks
    assert _agrees(text)
    assert _agrees(text.replace("leaf 700\n", "leaf 700\n# the middle\n"))
    assert read_block(text.replace("leaf 900\n", "leaf 900\n   odd: indent\n"), "t.yaml") is None
