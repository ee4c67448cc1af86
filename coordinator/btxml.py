"""Reading a BehaviorTree.CPP XML file for ``bmtree import``: safely (no DTD, no entities, bounded size and
depth) and with the position of every element and attribute, which ``xml.etree`` does not keep and every
error of the import needs (``tree.xml:12:7: …``)."""
from __future__ import annotations

import re
import xml.parsers.expat
from typing import Dict, List, Tuple

from coordinator.errors import Pos, TreeError
from coordinator.language import MAX_TREE_DEPTH

__all__ = ["Element", "XmlErrors", "parse_xml", "byte_pos", "MAX_XML_DEPTH"]

# the tree depth limit of the YAML language, plus <root> and <BehaviorTree> above the nodes
MAX_XML_DEPTH = MAX_TREE_DEPTH + 2
_BOM = b"\xef\xbb\xbf"
_DECL = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)
# one attribute of a start tag: its name and where its quoted value starts (values never hold their quote)
_TAG = re.compile(rb"<[^\s/>]+")
_ATTR = re.compile(rb"\s+([^\s=/>]+)\s*=\s*(?:\"[^\"]*\"|'[^']*')")
_ENTITY_NAME = re.compile(rb"&[#\w]*\Z")   # a bare '&' and what follows it up to where expat gave up


class Element:
    """An XML element with where it and each of its attributes are written."""

    __slots__ = ("tag", "attrs", "pos", "attr_pos", "children")

    def __init__(self, tag: str, attrs: Dict[str, str], pos: Pos, attr_pos: Dict[str, Pos]):
        self.tag = tag
        self.attrs = attrs
        self.pos = pos
        self.attr_pos = attr_pos
        self.children: List[Element] = []

    def at(self, attr: str) -> Pos:
        """Where ``attr`` is written (the element when it is not)."""
        return self.attr_pos.get(attr, self.pos)


class _Cursor:
    """Line and column (from 1, in characters) of byte offsets asked in increasing order, each from the
    bytes since the one before: asking from the file's start each time is quadratic on a file written on
    one line (60,000 elements: 12 s). Lines end at LF, CRLF or a lone CR, as XML's (and expat's) do."""

    def __init__(self, data: bytes):
        self.data = data
        self.index = 0
        self.line = 1
        self.column = 1

    def at(self, index: int) -> Tuple[int, int]:
        seg = self.data[self.index:index]   # never splits a CRLF nor a character: offsets are of '<' or names
        lf, cr = seg.count(b"\n"), seg.count(b"\r")
        if lf or cr:
            self.line += lf + cr - seg.count(b"\r\n")
            seg = seg[max(seg.rfind(b"\n"), seg.rfind(b"\r")) + 1:]
            self.column = 1
        self.column += len(seg.decode("utf-8", "replace"))
        self.index = index
        return self.line, self.column


def byte_pos(data: bytes, index: int) -> Tuple[int, int]:
    """Line and column of ``data[index]`` as an editor shows them (a leading byte order mark is no column)."""
    skip = len(_BOM) if data.startswith(_BOM) and index >= len(_BOM) else 0
    return _Cursor(data[skip:]).at(index - skip)


class _Refused(Exception):
    pass


def parse_xml(text: str, shown: str) -> Element:
    """The root element of ``text`` (the file's contents, already read bounded); XmlErrors says what
    is wrong, where."""
    data = text.encode("utf-8")
    if data.startswith(_BOM):   # not shown by editors: no column of line 1
        data = data[len(_BOM):]
    found = _DECL.search(data)
    if found:   # before expat sees it: Python 3.8's expat expands entities without a bound
        raise XmlErrors([TreeError(Pos(shown, *byte_pos(data, found.start())), (
            "the file declares a %s: bmtree import reads no XML with a DTD or entity declarations (entities can "
            "expand without bound); BehaviorTree.CPP and Groot write none: remove it" % found.group(1).decode().upper()))])
    parser = xml.parsers.expat.ParserCreate(encoding="utf-8")   # the bytes are UTF-8, whatever the prolog says
    parser.SetParamEntityParsing(xml.parsers.expat.XML_PARAM_ENTITY_PARSING_NEVER)
    stack: List[Element] = []
    top: List[Element] = []
    cursor = _Cursor(data)

    def refuse(*_args: object) -> None:
        raise _Refused()

    def start(tag: str, attrs: Dict[str, str]) -> None:
        index = parser.CurrentByteIndex
        pos = Pos(shown, *cursor.at(index))
        if len(stack) >= MAX_XML_DEPTH:
            raise XmlErrors([TreeError(pos, "the XML nests deeper than %d elements (bmtree trees nest at most %d "
                                            "levels)" % (MAX_XML_DEPTH, MAX_XML_DEPTH - 2))])
        el = Element(tag, attrs, pos, _attribute_positions(data, index, shown, cursor))
        if stack:
            stack[-1].children.append(el)
        else:
            top.append(el)
        stack.append(el)

    def end(_tag: str) -> None:
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.StartDoctypeDeclHandler = refuse
    parser.EntityDeclHandler = refuse
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as exc:
        raise XmlErrors([_not_well_formed(data, parser.ErrorByteIndex, Pos(shown, exc.lineno, exc.offset + 1),
                                          xml.parsers.expat.ErrorString(exc.code))])
    except _Refused:
        raise XmlErrors([TreeError(Pos(shown, parser.CurrentLineNumber, parser.CurrentColumnNumber + 1),
                                   "the file declares a DTD or entities, which bmtree import does not read")])
    return top[0]


def _not_well_formed(data: bytes, index: int, at: Pos, said: str) -> TreeError:
    """Expat's error, with what to write instead for a '<' or a bare '&' in an attribute (a script's
    ``a < b && c``), which expat only calls an invalid token."""
    if said == "not well-formed (invalid token)" and 0 <= index < len(data):
        if data[index:index + 1] == b"<":
            return TreeError(at, "not well-formed XML: a '<' in an attribute's value is written &lt; (a < b: "
                                 "a &lt; b)")
        amp = _ENTITY_NAME.search(data, max(0, index - 40), index)   # '&&', '& ', '&amp ': expat stops after it
        if amp is None and data[index:index + 1] == b"&":   # '&' between attributes
            amp = _ENTITY_NAME.match(data, index, index + 1)
        if amp is not None:   # the bytes from the '&' to the error are ASCII: one column each
            return TreeError(Pos(at.file, at.line, at.column - (index - amp.start())),
                             "not well-formed XML: a '&' is written &amp; (a && b: a &amp;&amp; b), or begins an "
                             "entity such as &lt; that ends with ';'")
    return TreeError(at, "not well-formed XML: %s" % said)


def _attribute_positions(data: bytes, index: int, shown: str, cursor: _Cursor) -> Dict[str, Pos]:
    """Where each attribute of the start tag at ``data[index]`` is written."""
    out: Dict[str, Pos] = {}
    tag = _TAG.match(data, index)
    i = tag.end() if tag is not None else index
    while True:
        m = _ATTR.match(data, i)
        if m is None:
            return out
        out[m.group(1).decode("utf-8", "replace")] = Pos(shown, *cursor.at(m.start(1)))
        i = m.end()


class XmlErrors(Exception):
    """Problems of an XML file, each at its position."""

    def __init__(self, errors: List[TreeError]):
        super().__init__("\n".join(str(e) for e in errors))
        self.errors = errors
