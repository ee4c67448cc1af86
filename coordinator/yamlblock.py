"""A fast reader for the plain block YAML that tree files are written in, with positions.

libyaml hands every key and value to Python as an event object (six per leaf of a tree), and
building those events costs more than the rest of loading a tree. Tree files use a small part
of YAML: block mappings and sequences, one scalar per line, plain or simply quoted. This reader
takes exactly that part, line by line, and gives the same values and positions as
``coordinator.yamlsrc``'s libyaml reader. On anything else (flow collections, anchors, tags,
multi-line or escaped scalars, empty values, tabs, duplicate keys, errors of any kind) it
answers None, and the caller reads the text with libyaml, which also gives the error messages.
"""
from __future__ import annotations

import re
from typing import Any, Dict, Iterator, List, Optional, Tuple

import yaml

from coordinator.errors import Pos
from coordinator.yamlsrc import LList, LMap

__all__ = ["read_block"]

# One line of block YAML, or group 8 (a line this reader does not take): 1 all before the value,
# 2 before the key, 3 the indent, 4 a simple key; the value 5 single-quoted, 6 double-quoted
# without escapes, or 7 a plain scalar that cannot be anything else: no indicator first ('-' only
# before a number), no ':' or '#' inside; then maybe a comment.
_LINE = re.compile(
    r"^(?:((( *)(?:-(?: +|$))?)(?:([A-Za-z0-9_][A-Za-z0-9_./-]{0,999}):(?: +|$))?)"
    r"""(?:('[^'\n]*(?:''[^'\n]*)*')|("[^"\\\n]*")|((?:-(?=[0-9.])|[^-?:,\[\]{}#&*!|>'"%@` \n])[^:# \n]*(?: +[^:# \n]+)*))?"""
    r" *(?:(?<![^ \n])#.*)?$|(.+))", re.M)
# characters libyaml reads as printable and not as a line break; anything else goes to libyaml
_ODD = re.compile("[^\n\x20-\x7e\u00a0-\u2027\u202a-\ud7ff\ue000-\ufefe\uff00-\ufffd\U00010000-\U0010ffff]")
_STR = "tag:yaml.org,2002:str"
_CONSTRUCTED = ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float", "tag:yaml.org,2002:bool",
                "tag:yaml.org,2002:null")
# resolved and constructed as by the loader of coordinator.yamlsrc (its implicit types, its constructors);
# scalar resolution and construction keep no state, so one instance serves every thread
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)("")
# a plain scalar starting otherwise is a string: no resolver is asked (with a resolver for any
# first character, every scalar is resolved)
_TYPED = frozenset(_LOADER.yaml_implicit_resolvers) if None not in _LOADER.yaml_implicit_resolvers else None
_VALUES: Dict[str, Any] = {}   # plain text that may have a type -> its value (keys and words repeat)
_MAX_DEPTH = 100
_MAX_LINES = 50000
_CHUNK = 8192   # characters of text read by the line pattern at once
_new = tuple.__new__


class _Other(Exception):
    """Not the simple block YAML this reader takes: read with libyaml."""


def _plain(text: str) -> Any:
    """A plain scalar's value, resolved as PyYAML's safe loader resolves it (strings and numbers,
    booleans and null; any other type is left to libyaml)."""
    tag = _LOADER.resolve(yaml.ScalarNode, text, (True, False))
    if tag == _STR:
        value: Any = text
    elif tag in _CONSTRUCTED:
        try:
            value = _LOADER.yaml_constructors[tag](_LOADER, yaml.ScalarNode(tag, text))
        except Exception:   # e.g. an int of more digits than Python converts: libyaml's reader reports it
            raise _Other()
    else:
        raise _Other()
    if len(text) <= 64 and len(_VALUES) < 4096:
        _VALUES[text] = value
    return value


def _chunks(text: str) -> Iterator[List[Tuple[str, ...]]]:
    """The rows of ``_LINE`` for every line, a few hundred lines at a time (one list for all the
    lines of a big tree would be the largest allocation of a load, in fresh memory)."""
    start, size, lines = 0, len(text), 0
    while True:
        end = text.find("\n", start + _CHUNK) if start + _CHUNK < size else -1
        if end < 0:
            end = size
        rows = _LINE.findall(text, start, end)
        lines += len(rows)
        if len(rows) != text.count("\n", start, end) + 1 or lines > _MAX_LINES:
            raise _Other()
        yield rows
        if end == size:
            return
        start = end + 1


def _read(text: str, file: str) -> Any:
    """The document: one pass over the lines, the enclosing containers on a stack."""
    new_pos, PosT, values, plain, empty, typed = _new, Pos, _VALUES, _plain, _Other, _TYPED  # noqa: N806
    stack: List[Any] = []
    # the open container (a mapping with its key and value positions, or a sequence with its
    # items'), the column of its keys or of its '-', and a key whose value is the block below
    # (at first the root: ``obj`` is None)
    obj: Any = None
    is_map = False
    col = -1
    kpos: Any = None
    vpos: Any = None
    items: Any = None
    pending: Any = None
    pending_at: Any = None
    root: Any = None
    line_no = 0
    for rows in _chunks(text):
        for before_value, before_key, indent_s, key_text, single, double, bare, bad in rows:
            line_no += 1
            if bare:
                value: Any = bare
                if bare[0] in typed:
                    value = values.get(bare, empty)
                    if value is empty:
                        value = plain(bare)
                value_at: Any = new_pos(PosT, (file, line_no, len(before_value) + 1))
            elif single:
                value = single[1:-1].replace("''", "'")
                value_at = new_pos(PosT, (file, line_no, len(before_value) + 2))
            elif double:
                value = double[1:-1]
                value_at = new_pos(PosT, (file, line_no, len(before_value) + 2))
            elif key_text:
                value = empty                # the value is the block below
            elif bad or before_key != indent_s:
                raise _Other()               # not this reader's YAML, or a lone '-'
            else:
                continue                     # blank, or a comment
            indent = len(indent_s)
            key_col = len(before_key)
            dash = key_col != indent
            if key_text:
                key = key_text
                if key_text[0] in typed:
                    key = values.get(key_text, empty)
                    if key is empty:
                        key = plain(key_text)
                key_at = new_pos(PosT, (file, line_no, key_col + 1))
            elif not dash:
                raise _Other()               # a bare scalar: text continued from the line above?
            # the container of this line: a new one (the root, or the block below a 'key:'), or an open one
            if pending is not empty:
                if obj is not None and not (indent > col or (indent == col and dash)):
                    raise _Other()           # an empty value (null): libyaml says where
                if dash:
                    new: Any = LList()
                    new.pos = new_pos(PosT, (file, line_no, indent + 1))
                    new.item_pos = []
                else:
                    new = LMap()
                    new.pos = key_at
                    new.key_pos, new.val_pos = {}, {}
                if obj is None:
                    root = new
                else:
                    obj[pending] = new
                    kpos[pending] = pending_at
                    vpos[pending] = new.pos
                    stack.append((obj, is_map, col, kpos, vpos, items))
                    if len(stack) > _MAX_DEPTH:
                        raise _Other()
                pending = empty
                obj, is_map, col = new, not dash, indent
                if dash:
                    items = new.item_pos
                else:
                    kpos, vpos = new.key_pos, new.val_pos
            elif indent != col or dash == is_map:   # not a '-' of this sequence nor a key of this mapping
                while True:
                    if indent > col or (indent == col and is_map):
                        raise _Other()       # indented too far, or a '-' beside keys
                    if not stack:
                        raise _Other()       # more after the document
                    obj, is_map, col, kpos, vpos, items = stack.pop()
                    if indent == col and dash != is_map:
                        break
            if is_map:
                if key in obj:
                    raise _Other()           # a duplicate key: libyaml's reader reports it
            elif key_text:                   # '- key: …' starts a mapping
                new = LMap()
                new.pos = key_at
                obj.append(new)
                items.append(key_at)
                stack.append((obj, is_map, col, kpos, vpos, items))
                if len(stack) > _MAX_DEPTH:
                    raise _Other()
                new.key_pos, new.val_pos = kpos, vpos = {}, {}
                obj, is_map, col = new, True, key_col
            else:                            # '- value'
                obj.append(value)
                items.append(value_at)
                continue
            if value is empty:
                pending, pending_at = key, key_at
            else:
                obj[key] = value
                kpos[key] = key_at
                vpos[key] = value_at
    if pending is not empty or root is None:
        raise _Other()
    return root


def read_block(text: str, file: str) -> Optional[Any]:
    """The document if ``text`` is plain block YAML (see the module's doc), else None."""
    if _TYPED is None or "\t" in text or "\r" in text or _ODD.search(text) is not None:
        return None
    if text.startswith(("---", "...", "%")) or "\n---" in text or "\n..." in text or "\n%" in text:
        return None
    try:
        return _read(text, file)
    except _Other:
        return None
