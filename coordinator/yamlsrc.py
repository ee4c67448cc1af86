"""YAML with positions: safe loading that remembers where every key and value came from."""
from __future__ import annotations

import operator
import re
from typing import Any, Dict, List, Optional, Tuple

import yaml

from comm.textfile import MAX_BYTES, read_text, text_pos
from coordinator.errors import Pos, TreeError, TreeErrors

__all__ = ["LMap", "LList", "OnDemandPos", "MAX_BYTES", "bool_hint", "load_file", "load_value", "load_yaml", "pos_of",
           "settle"]


def bool_hint(value: Any) -> str:
    """For a name YAML read as true or false (an unquoted ``on``, ``yes``, ``off``, ``no``, YAML 1.1's
    booleans): how to write it; '' for anything else."""
    return ": YAML reads an unquoted on, off, yes or no as true or false; quote the name" if isinstance(
        value, bool) else ""


class OnDemandPos:
    """A ``pos`` kept as the loader stores it (slot ``_pos``, with its file in slot ``_file``) and made
    a ``Pos`` when first read (see :func:`settle`): a valid tree reads few of its positions.

    Setting a position by hand first settles every stored one (``_settle_all``) and forgets the file.
    """

    __slots__ = ()
    _pos: Any
    _file: Optional[str]

    @property
    def pos(self) -> Pos:
        p = self._pos
        if self._file is not None and p.__class__ is not Pos:
            p = self._pos = settle(p, self._file)
        return p

    @pos.setter
    def pos(self, value: Pos) -> None:
        self._settled()
        self._pos = value

    def _settled(self) -> None:
        if getattr(self, "_file", None) is not None:
            self._settle_all()
        self._file = None

    def _settle_all(self) -> None:
        self.pos  # noqa: B018 - settles it


def _stored(slot: str, doc: str) -> property:
    """A container's positions of its parts (slot ``slot``), all made ``Pos`` on the first read."""
    get = operator.attrgetter(slot)

    def read(self: OnDemandPos) -> Any:
        if self._file is not None:
            self._settled()
        return get(self)

    def write(self: OnDemandPos, value: Any) -> None:
        self._settled()
        setattr(self, slot, value)

    return property(read, write, doc=doc)


class LMap(dict, OnDemandPos):
    """A mapping that knows the position of itself, of each key and of each value.

    ``pos``, ``key_pos`` and ``val_pos`` always give ``Pos`` values; ``_kp``/``_vp`` are the
    stored ones, still as the loader keeps them while ``_file`` is set.
    """

    __slots__ = ("_pos", "_kp", "_vp", "_file")

    key_pos = _stored("_kp", "Positions of the keys, by key.")
    val_pos = _stored("_vp", "Positions of the values, by key.")

    def _settle_all(self) -> None:
        file = self._file
        self.pos  # noqa: B018 - settles it
        for d in (self._kp, self._vp):
            for k, p in d.items():
                if p.__class__ is not Pos:
                    d[k] = settle(p, file)


class LList(list, OnDemandPos):
    """A sequence that knows the position of itself and of each item (made on demand, as for LMap)."""

    __slots__ = ("_pos", "_ip", "_file")

    item_pos = _stored("_ip", "Positions of the items, by index.")

    def _settle_all(self) -> None:
        file = self._file
        self.pos  # noqa: B018 - settles it
        ip = self._ip
        for i, p in enumerate(ip):
            if p.__class__ is not Pos:
                ip[i] = settle(p, file)


# libyaml's parser when PyYAML was built with it (Debian's is): the same events, ~10x faster.
_SafeLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _Builder(_SafeLoader):  # type: ignore[misc,valid-type]
    """The safe loader, reading ``5e-1`` and ``1e3`` as numbers as YAML 1.2 (and JSON) do: YAML 1.1,
    PyYAML's, wants a dot (``5.0e-1``) and read them as text, which a float input then refused only
    when its call was built, mid-run (``--set x=5e-1``)."""


_Builder.add_implicit_resolver("tag:yaml.org,2002:float", re.compile(r"^[-+]?(?:[0-9]+|[0-9]*\.[0-9]+)[eE][-+]?[0-9]+$"),
                               list("-+0123456789."))

MAX_NODES = 200000          # every scalar, container and alias expansion counts
MAX_DEPTH = 400
_STR = "tag:yaml.org,2002:str"
_MERGE_TAG = "tag:yaml.org,2002:merge"
_MERGE = object()        # the '<<' key
_NO_KEY = object()
_new_pos = tuple.__new__
_QUOTES = ("'", '"')
_PLAIN_TAGS = ("tag:yaml.org,2002:map", "tag:yaml.org,2002:seq")


def _pos(file: str, mark: Any, quoted: bool = False) -> Pos:
    """Where an event starts; for a quoted scalar, where its text starts (inside the quote)."""
    return _new_pos(Pos, (file, mark.line + 1, mark.column + 1 + quoted))


_MARKS = tuple({yaml.error.Mark, getattr(getattr(yaml, "_yaml", None), "Mark", yaml.error.Mark)})


def settle(p: Any, file: str) -> Any:
    """The ``Pos`` of a position as the loader stores it: a scalar's event (where its text starts,
    inside a quote), a mark (where an alias or a container starts), a nested container (its own
    position) or already a ``Pos`` (anything else is returned as it is)."""
    cls = p.__class__
    if cls is yaml.ScalarEvent:
        return _pos(file, p.start_mark, p.style in _QUOTES)
    if cls in _MARKS:
        return _pos(file, p)
    if cls is LMap or cls is LList:
        return p.pos
    return p


def file_of(loader: Any) -> str:
    return getattr(loader, "bmtree_file", "<yaml>")


def _fail(file: str, mark: Any, message: str) -> TreeErrors:
    return TreeErrors([TreeError(_pos(file, mark), message)])


def _too_many(file: str, mark: Any, written: int) -> TreeErrors:
    """The node limit crossed: by the nodes written, or by what aliases repeat (only then blamed)."""
    if written > MAX_NODES:
        return _fail(file, mark, "the document has more than %d YAML nodes" % MAX_NODES)
    return _fail(file, mark, "the document expands to more than %d YAML nodes through its aliases" % MAX_NODES)


_PLAIN: Dict[str, str] = {}   # plain scalar text -> its resolved tag (keys and common words repeat a lot)


def _scalar(loader: Any, event: Any) -> Any:
    """The value of a scalar event, resolved and constructed as PyYAML's safe loader would."""
    value, tag = event.value, event.tag
    if tag is None:
        if not event.implicit[0]:
            return value
        tag = _PLAIN.get(value)
        if tag is None:
            tag = loader.resolve(yaml.ScalarNode, value, event.implicit)
            if len(_PLAIN) < 4096:
                _PLAIN[value] = tag
        if tag == _STR:
            return value
        if tag == _MERGE_TAG:
            return _MERGE
    elif tag == "!" or tag == _STR:
        return value
    node = yaml.ScalarNode(tag, value, event.start_mark, event.end_mark, event.style)
    try:
        return loader.construct_object(node, deep=True)
    except yaml.YAMLError:
        raise
    except (ValueError, TypeError, AttributeError, OverflowError, LookupError) as exc:  # PyYAML's own bugs, e.g. '!!bool x'
        raise TreeErrors([TreeError(_pos(file_of(loader), event.start_mark), "cannot read %.80r as %s (%s)" % (
            value, tag, type(exc).__name__))])


def _merge(out: LMap, merges: List[Tuple[Any, Any]]) -> LMap:
    """A finished mapping with its ``<<`` merges applied (a merged key never overrides: a clash is an error)."""
    for merged, at in merges:
        sources = merged if isinstance(merged, list) else [merged]
        for src in sources:
            if not isinstance(src, LMap):
                raise TreeErrors([TreeError(settle(at, out._file), "'<<' merges a mapping or a list of mappings")])
            for k, v in src.items():
                if k in out:
                    raise TreeErrors([TreeError(out.key_pos[k], "duplicate key %r" % (k,))])
                out[k] = v
                out._kp[k], out._vp[k] = src._kp[k], src._vp[k]   # raw or not: both settle the same
    return out


def _build(loader: Any, file: str) -> Any:
    """One document from the parser's events, with positions; aliases share the anchored value.

    The hot loop of loading a tree: the open container's state lives in locals, and the
    enclosing containers' states on a stack.
    """
    get, check = loader.get_event, loader.check_event
    # locals for the hot loop
    ScalarEvent, MappingStart, SequenceStart, MappingEnd, SequenceEnd, Alias = (  # noqa: N806
        yaml.ScalarEvent, yaml.MappingStartEvent, yaml.SequenceStartEvent, yaml.MappingEndEvent,
        yaml.SequenceEndEvent, yaml.AliasEvent)
    plain, str_tag, no_key, merge_key = _PLAIN, _STR, _NO_KEY, _MERGE
    first_chars = loader.yaml_implicit_resolvers   # plain text starting otherwise is a string
    get()  # StreamStart
    if check(yaml.StreamEndEvent):
        return None
    get()  # DocumentStart
    anchors: Dict[str, Tuple[Any, int]] = {}
    stack: List[Any] = []
    # the open container: itself, its item positions (a sequence) or key/value positions (a mapping),
    # the pending key of a mapping, its '<<' merges, its anchor and its node count at the start
    container: Any = None
    item_pos: Any = None
    key_pos: Any = None
    val_pos: Any = None
    key: Any = no_key
    key_at: Any = None
    merges: Any = None
    anchor: Any = None
    start = 0
    count = 0
    aliased = 0   # of count, the nodes that aliases repeat
    max_nodes = MAX_NODES
    depth = 0
    while True:
        event = get()
        cls = event.__class__
        if cls is ScalarEvent:
            value = event.value
            tag = event.tag
            if tag is None and event.implicit[0]:   # plain: a string unless some implicit type matches
                if value[:1] in first_chars and plain.get(value) != str_tag:
                    value = _scalar(loader, event)
                at = event.start_mark   # positions stay libyaml's objects until read (see settle)
            else:   # quoted or block text, or tagged
                if tag is not None and tag != "!" and tag != str_tag:
                    value = _scalar(loader, event)
                at = event
            count += 1
            if count > max_nodes:
                raise _too_many(file, event.start_mark, count - aliased)
            if event.anchor is not None:
                anchors[event.anchor] = (value, 1)
        elif cls is MappingStart or cls is SequenceStart:
            count += 1
            depth += 1
            mark = event.start_mark
            if count > max_nodes:
                raise _too_many(file, mark, count - aliased)
            if depth > MAX_DEPTH:
                raise _fail(file, mark, "the document is nested too deeply (more than %d levels)" % MAX_DEPTH)
            if event.tag is not None and event.tag not in _PLAIN_TAGS and not event.implicit:
                raise _fail(file, mark, "YAML tag %r is not allowed here (only plain mappings, sequences and "
                                        "scalars)" % event.tag)
            stack.append((container, item_pos, key_pos, val_pos, key, key_at, merges, anchor, start))
            if cls is MappingStart:
                container = LMap()
                container._pos = mark
                container._kp = key_pos = {}
                container._vp = val_pos = {}
                container._file = file
                item_pos = None
                key = no_key
            else:
                container = LList()
                container._pos = mark
                container._ip = item_pos = []
                container._file = file
            merges = None   # the enclosing mapping's merges wait on the stack
            anchor, start = event.anchor, count
            continue
        elif cls is MappingEnd or cls is SequenceEnd:
            value = container if merges is None else _merge(container, merges)
            at = value
            depth -= 1
            if anchor is not None:
                anchors[anchor] = (value, count - start + 1)
            container, item_pos, key_pos, val_pos, key, key_at, merges, anchor, start = stack.pop()
        elif cls is Alias:
            if event.anchor not in anchors:
                if event.anchor == anchor or any(entry[7] == event.anchor for entry in stack):
                    raise _fail(file, event.start_mark, "alias *%s is inside the node anchored &%s: a value cannot "
                                                        "contain itself" % (event.anchor, event.anchor))
                raise _fail(file, event.start_mark, "found undefined alias %r (an alias *NAME must come after "
                                                    "its anchor &NAME)" % event.anchor)
            value, size = anchors[event.anchor]
            count += size
            aliased += size
            at = event.start_mark
            if count > max_nodes:
                raise _too_many(file, event.start_mark, count - aliased)
        else:
            raise _fail(file, event.start_mark, "unexpected YAML event %s" % cls.__name__)
        if container is None:
            break
        if item_pos is not None:
            container.append(value)
            item_pos.append(at)
        elif key is no_key:
            if value.__class__ is not str and isinstance(value, (dict, list)):
                raise TreeErrors([TreeError(settle(at, file), "a mapping key must be a scalar")])
            key, key_at = value, at
        else:
            if key is merge_key:
                if merges is None:
                    merges = []
                merges.append((value, key_at))
            elif key in container:
                raise TreeErrors([TreeError(settle(key_at, file), "duplicate key %r" % (key,))])
            else:
                container[key] = value
                key_pos[key] = key_at
                val_pos[key] = at
            key = no_key
    get()  # DocumentEnd
    if not check(yaml.StreamEndEvent):
        raise _fail(file, get().start_mark, "expected a single document in the stream, found another one")
    return value


def _unencodable(text: str, index: int) -> str:
    """What a lone surrogate in a text stands for: an undecodable byte (Python decodes command-line
    arguments with ``surrogateescape``), or itself."""
    c = ord(text[index])
    return "not UTF-8 text: byte 0x%02x" % (c - 0xDC00) if 0xDC80 <= c <= 0xDCFF else \
        "YAML error: unacceptable character #x%04x" % c


_INDENT_HINT = ("check the indentation of this line and the one before: the keys of a mapping line up at one "
                "column, the items ('- ') of a list at one column; a key at the wrong depth, or a list item where "
                "a key belongs, breaks the block")


def _syntax_hint(exc: Any, text: str, line: int, column: int) -> str:
    """What most likely causes one of libyaml's (or PyYAML's) syntax errors, and how to fix it: '' if
    nothing is known. ``line``/``column`` (from 1) is where the error is reported."""
    problem = str(getattr(exc, "problem", "") or "")
    context = str(getattr(exc, "context", "") or "")
    cmark = getattr(exc, "context_mark", None)
    inside = ""
    if cmark is not None and "block" in context:   # the block the parser was reading when it broke
        what = "mapping" if "mapping" in context else "list"
        inside = " (in the %s that starts at line %d, column %d)" % (what, cmark.line + 1, cmark.column + 1)
    if "did not find expected key" in problem or "expected <block end>" in problem:
        return "%s: %s" % (inside, _INDENT_HINT)
    if "did not find expected '-' indicator" in problem:
        return ("%s: check the indentation of this line and the one before: every item of a list starts with "
                "'- ' at the same column, and the keys of an item line up with its first key" % inside)
    if "mapping values are not allowed" in problem:
        return (": a ': ' inside a value that is not quoted, or a key indented deeper than the keys above it: "
                "quote the value (name: \"note: hi\") or line the key up with the others")
    lines = text.splitlines()
    row = lines[line - 1] if 0 < line <= len(lines) else ""
    if "expected ',' or" in problem and row[column - 1:column] in ("[", "{"):  # $people[0] in {text: …}
        return ": inside { } or [ ], a value holding [ ] or { } must be quoted ({text: \"$people[0]\"})"
    if "expected ',' or" in problem and row[column - 1:column] == ":":   # {text: Hello: welcome}
        return ": quote a value containing ': ' (%s)" % _quoted_entry(row, column - 1)
    if "cannot start any token" in problem and row[column - 1:column] == "\t" or "tab character" in problem:
        return ": a tab: YAML indents with spaces only"
    return ""


def _quoted_entry(row: str, colon: int) -> str:
    """The entry of a flow mapping that holds ``row[colon]``, a second ': ' in its value, written as it
    must be: ``text: "Hello: welcome"`` (an example when the line is not that simple)."""
    left = row[:colon]
    start = max(left.rfind("{"), left.rfind(",")) + 1
    end = min([i for i in (row.find(",", colon), row.find("}", colon)) if i >= 0] or [len(row)])
    key, sep, head = left[start:].strip().partition(": ")
    value = (head + row[colon:end]).strip()
    if not sep or not key or '"' in value or "\\" in value:
        return '{text: "Hello: welcome"}'
    return '%s: "%s"' % (key, value)


def _first_line(exc: Exception) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]


def load_file(path: str) -> Any:
    """A YAML file (:func:`read_text`'s limits) as position-carrying data; a file that cannot be read
    or is not UTF-8 is a TreeErrors at its start or at the bad byte, as a syntax error is."""
    try:
        text = read_text(path)
    except OSError as exc:
        raise TreeErrors([TreeError(Pos(path, 1, 1), "cannot read %s: %s" % (path, exc.strerror or exc))])
    except UnicodeDecodeError as exc:
        raise TreeErrors([TreeError(Pos(path, *text_pos(exc.object, exc.start)),
                                    "not UTF-8 text: byte 0x%02x" % exc.object[exc.start])])
    return load_yaml(text, path)


def load_yaml(text: str, file: str) -> Any:
    """Parse one YAML document (safe loader only); syntax errors become TreeErrors."""
    if len(text) > MAX_BYTES:   # a file read otherwise than with read_text (characters: at least as many bytes)
        raise TreeErrors([TreeError(Pos(file, 1, 1), "the document is larger than %d MiB" % (MAX_BYTES >> 20))])
    try:
        loader = _Builder(text)
    except UnicodeEncodeError as exc:   # libyaml reads UTF-8: lone surrogates cannot be given to it
        raise TreeErrors([TreeError(Pos(file, *text_pos(text, exc.start)), _unencodable(text, exc.start))])
    loader.bmtree_file = file  # for errors raised while constructing scalars
    try:
        return _build(loader, file)
    except RecursionError:
        raise TreeErrors([TreeError(Pos(file, 1, 1), "the document is nested too deeply")])
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line, col = (mark.line + 1, mark.column + 1) if mark else (1, 1)
        raise TreeErrors([TreeError(Pos(file, line, col), "YAML syntax error: %s%s" % (
            exc.problem or _first_line(exc), _syntax_hint(exc, text, line, col)))])
    except yaml.reader.ReaderError as exc:   # libyaml's position counts bytes: the first such character is it
        char = exc.character if isinstance(exc.character, int) else 0
        at = text.find(chr(char))
        raise TreeErrors([TreeError(Pos(file, *text_pos(text, at if at >= 0 else min(exc.position, len(text)))),
                                    "YAML error: unacceptable character #x%04x: %s" % (char, exc.reason))])
    except yaml.YAMLError as exc:
        raise TreeErrors([TreeError(Pos(file, 1, 1), "YAML error: %s" % _first_line(exc))])
    finally:
        loader.dispose()


def _plain(value: Any) -> Any:
    """A loaded value as plain dicts and lists (iterative: values nest up to MAX_DEPTH levels)."""
    if not isinstance(value, (dict, list)):
        return value
    made: Dict[int, Any] = {}   # by id: a shared (aliased) value stays one object
    out = {} if isinstance(value, dict) else []
    made[id(value)] = out
    todo = [(value, out)]
    while todo:
        src, dst = todo.pop()
        for k, v in (src.items() if isinstance(src, dict) else enumerate(src)):
            if isinstance(v, (dict, list)):
                copy = made.get(id(v))
                if copy is None:
                    copy = made[id(v)] = {} if isinstance(v, dict) else []
                    todo.append((v, copy))
                v = copy
            if isinstance(dst, dict):
                dst[k] = v
            else:
                dst.append(v)
    return out


def load_value(text: str, name: str) -> Any:
    """One value given outside a file (``--set``): the limits of tree files, plain dicts and lists."""
    return _plain(load_yaml(text, name))


def pos_of(container: Any, key: Any = None, default: Any = None) -> Pos:
    """Position of a value inside a container (or of the container), falling back to ``default``."""
    if key is not None:
        if isinstance(container, LMap) and key in container.val_pos:
            return container.val_pos[key]
        if isinstance(container, LList) and isinstance(key, int) and key < len(container.item_pos):
            return container.item_pos[key]
    p = getattr(container, "pos", None)
    return p if p is not None else default
