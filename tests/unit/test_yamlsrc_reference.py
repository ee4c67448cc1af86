"""The fast event loop of ``load_yaml`` against its contract written plainly (a recursive walk).

Both read libyaml's events and resolve scalars with PyYAML's safe loader; the loader's loop is
tuned for speed, the reference here for reading. They must agree on every value, type, key order
and position, and refuse the same documents with the same message, on every YAML file of the
repository and on random documents (block and flow, anchors, aliases, merges, tags, quotes).
"""
from __future__ import annotations

import glob
import math
import os
import random
from typing import Any, Dict, List, Optional, Tuple

import pytest
import yaml

from coordinator.errors import Pos, TreeErrors
from coordinator.yamlsrc import LList, LMap, load_yaml
from coordinator.yamlsrc import _Builder as yamlsrc_loader
from tests.conftest import ROOT

_MERGE = object()


class _Refused(Exception):
    """The reference refuses the document with this position and message."""

    def __init__(self, pos: Pos, message: str):
        super().__init__("%s: %s" % (pos, message))


def _reference(text: str, file: str) -> Any:
    """One document as ``load_yaml`` must read it (without its size and depth limits)."""
    loader = yamlsrc_loader(text)   # PyYAML's safe loader, with YAML 1.2's 5e-1 as a number
    anchors: Dict[str, Any] = {}
    open_anchors: List[Any] = []  # of the collections being read, innermost last

    def pos(mark: Any, quoted: bool = False) -> Pos:
        return Pos(file, mark.line + 1, mark.column + 1 + quoted)

    def node(event: Any) -> Tuple[Any, Pos]:
        if isinstance(event, yaml.AliasEvent):
            if event.anchor not in anchors:
                if event.anchor in open_anchors:
                    raise _Refused(pos(event.start_mark), "alias *%s is inside the node anchored &%s: a value "
                                                          "cannot contain itself" % (event.anchor, event.anchor))
                raise _Refused(pos(event.start_mark), "found undefined alias %r (an alias *NAME must come after "
                                                      "its anchor &NAME)" % event.anchor)
            return anchors[event.anchor], pos(event.start_mark)
        if isinstance(event, yaml.ScalarEvent):
            value: Any = event.value
            if event.tag is None and event.implicit[0]:
                tag = loader.resolve(yaml.ScalarNode, value, event.implicit)
                if tag == "tag:yaml.org,2002:merge":
                    value = _MERGE
                elif tag != "tag:yaml.org,2002:str":
                    value = loader.construct_object(yaml.ScalarNode(tag, value, event.start_mark), deep=True)
            elif event.tag not in (None, "!", "tag:yaml.org,2002:str"):
                value = loader.construct_object(yaml.ScalarNode(event.tag, value, event.start_mark), deep=True)
            value_at = pos(event.start_mark, event.style in ("'", '"'))
        elif isinstance(event, yaml.CollectionStartEvent) and event.tag not in (
                None, "tag:yaml.org,2002:map", "tag:yaml.org,2002:seq") and not event.implicit:
            raise _Refused(pos(event.start_mark), "YAML tag %r is not allowed here (only plain mappings, sequences "
                                                  "and scalars)" % event.tag)
        elif isinstance(event, yaml.SequenceStartEvent):
            value, value_at = LList(), pos(event.start_mark)
            value.pos, value.item_pos = value_at, []
            open_anchors.append(event.anchor)
            while not loader.check_event(yaml.SequenceEndEvent):
                item, item_at = node(loader.get_event())
                value.append(item)
                value.item_pos.append(item_at)
            loader.get_event()
            open_anchors.pop()
        elif isinstance(event, yaml.MappingStartEvent):
            open_anchors.append(event.anchor)
            value = mapping(event)
            open_anchors.pop()
            value_at = value.pos
        else:
            raise AssertionError("unexpected event %r" % event)
        if event.anchor is not None:
            anchors[event.anchor] = value
        return value, value_at

    def mapping(event: Any) -> LMap:
        out = LMap()
        out.pos, out.key_pos, out.val_pos = pos(event.start_mark), {}, {}
        merges = []
        while not loader.check_event(yaml.MappingEndEvent):
            key, key_at = node(loader.get_event())
            if isinstance(key, (dict, list)):
                raise _Refused(key_at, "a mapping key must be a scalar")
            value, value_at = node(loader.get_event())
            if key is _MERGE:
                merges.append((value, key_at))
            elif key in out:
                raise _Refused(key_at, "duplicate key %r" % (key,))
            else:
                out[key], out.key_pos[key], out.val_pos[key] = value, key_at, value_at
        loader.get_event()
        for merged, at in merges:   # after the mapping's own keys, never overriding one
            for src in merged if isinstance(merged, list) else [merged]:
                if not isinstance(src, LMap):
                    raise _Refused(at, "'<<' merges a mapping or a list of mappings")
                for k in src:
                    if k in out:
                        raise _Refused(out.key_pos[k], "duplicate key %r" % (k,))
                    out[k], out.key_pos[k], out.val_pos[k] = src[k], src.key_pos[k], src.val_pos[k]
        return out

    try:
        loader.get_event()
        if loader.check_event(yaml.StreamEndEvent):
            return None
        loader.get_event()
        value = node(loader.get_event())[0]
        loader.get_event()
        if not loader.check_event(yaml.StreamEndEvent):
            raise _Refused(pos(loader.get_event().start_mark),
                           "expected a single document in the stream, found another one")
        return value
    finally:
        loader.dispose()


def _difference(a: Any, b: Any, path: str = "$") -> Optional[str]:
    """Where two loaded documents differ (value, type, key order or any position), or None."""
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


def _agree(text: str) -> str:
    """How both read the text: 'read' (the same document), 'refused' (the same message) or 'error'."""
    try:
        expected = _reference(text, "t.yaml")
    except _Refused as exc:
        with pytest.raises(TreeErrors) as got:
            load_yaml(text, "t.yaml")
        assert str(got.value) == str(exc), text
        return "refused"
    except (yaml.YAMLError, ValueError, TypeError, AttributeError, OverflowError, LookupError):  # refused by libyaml or PyYAML
        with pytest.raises(TreeErrors):
            load_yaml(text, "t.yaml")
        return "error"
    difference = _difference(load_yaml(text, "t.yaml"), expected)
    assert difference is None, "%s\n---\n%s" % (difference, text)
    return "read"


def test_every_yaml_file_of_the_repository():
    paths = [p for p in glob.glob(os.path.join(ROOT, "**", "*.y*ml"), recursive=True) if "/." not in p]
    outcomes = []
    for path in paths:
        with open(path, encoding="utf-8", errors="replace") as fh:
            outcomes.append(_agree(fh.read()))
    assert len(paths) >= 20 and outcomes.count("read") >= 20


@pytest.mark.parametrize("text", [
    "a: &x {k: 1}\nb:\n  <<: *x\n  j: 2\n", "a: &x {k: 1}\nb:\n  <<: [*x, {m: 2}]\n  k: 3\n", "<<: 1\n",
    "a: &x [1]\n? *x\n: 2\n", "a: &x 1\na: &x 2\nb: *x\n", "a: 1\n---\nb: 2\n", "a: |\n  text\n  more\nb: >-\n  folded\n",
    "# c\n'q': \"d\\n\"   # c\n", "- ! 7\n- !!str 5\n- !!int '9'\n- !!timestamp x\n", "a: &s [*s]\n", "",
    "--- 1\n", "&r {a: *r}\n", "x: !!set {a, b}\n", "on: off\n1.5: ~\n",
])
def test_particular_documents(text):
    _agree(text)


_KEYS = ["a", "name", "yes", "1", "null", "'q'", '"x y"', "<<", "on", "1.5", "~", "!!str 3", "&a0 k", "*a0", "a"]
_SCALARS = ["a", "leaf 1", "'q'", "'it''s'", '"d\\n"', '"x y"', "1", "-2.5", "0x1f", "1_000", ".inf", ".nan", "~",
            "null", "yes", "On", "2024-01-02", "12:30", "!!str 5", "! 7", "!!int '9'", "!!float 1", "''",
            "!!binary aGk=", "é ü", "a - b", "!!bool x", "!!timestamp x", "true", "=", "0o17", "+1"]


def _value(rng: random.Random, depth: int, indent: int, flow: bool) -> str:
    """Random YAML text for a value after 'key: ' or '- ' (a block collection starts a new line)."""
    anchor = "&a%d " % rng.randrange(3) if rng.random() < 0.15 else ""
    r = rng.random()
    if r < 0.08:
        return "*a%d" % rng.randrange(3)
    if depth < 4 and r < 0.4:
        if flow or r < 0.2:
            items = [_value(rng, depth + 1, indent, True) for _ in range(rng.randint(0, 3))]
            if rng.random() < 0.5:
                return anchor + "[" + ", ".join(items) + "]"
            return anchor + "{" + ", ".join("%s: %s" % (rng.choice(_KEYS), v) for v in items) + "}"
        return anchor.rstrip() + _block(rng, depth + 1, indent + rng.choice([1, 2, 4]))
    return anchor + rng.choice(_SCALARS)


def _block(rng: random.Random, depth: int, indent: int) -> str:
    pad = " " * indent
    if rng.random() < 0.4:
        return "".join("\n%s- %s" % (pad, _compact(rng, depth, indent + 2) if rng.random() < 0.3 else
                                     _value(rng, depth, indent + 2, False)) for _ in range(rng.randint(1, 3)))
    return "".join("\n%s%s: %s" % (pad, rng.choice(_KEYS), _value(rng, depth, indent, False))
                   for _ in range(rng.randint(1, 4)))


def _compact(rng: random.Random, depth: int, indent: int) -> str:
    """A mapping begun on its sequence item's line ('- check: x' then 'name: y' below), as trees are written."""
    return ("\n" + " " * indent).join("%s: %s" % (rng.choice(_KEYS), _value(rng, depth + 1, indent, False))
                                      for _ in range(rng.randint(1, 3)))


def test_random_documents():
    rng = random.Random(11)
    outcomes = [_agree(_block(rng, 0, 0)[1:] + "\n") for _ in range(3000)]
    assert outcomes.count("read") > 600 and outcomes.count("refused") > 100 and outcomes.count("error") > 100
