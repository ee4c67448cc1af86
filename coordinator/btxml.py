"""Reading a BehaviorTree.CPP XML file for ``bmtree import``: safely (no DTD, no entities, bounded size and
depth) and with the position of every element and attribute, which ``xml.etree`` does not keep and every
error of the import needs (``tree.xml:12:7: …``)."""
from __future__ import annotations

import re
import xml.parsers.expat
from typing import Dict, List

from comm.textfile import text_pos
from coordinator.errors import Pos, TreeError
from coordinator.language import MAX_TREE_DEPTH

__all__ = ["Element", "XmlErrors", "parse_xml", "MAX_XML_DEPTH"]

# the tree depth limit of the YAML language, plus <root> and <BehaviorTree> above the nodes
MAX_XML_DEPTH = MAX_TREE_DEPTH + 2
_DECL = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)
# one attribute of a start tag: its name and where its quoted value starts (values never hold their quote)
_TAG = re.compile(rb"<[^\s/>]+")
_ATTR = re.compile(rb"\s+([^\s=/>]+)\s*=\s*(?:\"[^\"]*\"|'[^']*')")


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


class _Refused(Exception):
    pass


def parse_xml(text: str, shown: str) -> Element:
    """The root element of ``text`` (the file's contents, already read bounded); XmlErrors says what
    is wrong, where."""
    data = text.encode("utf-8")
    found = _DECL.search(data)
    if found:   # before expat sees it: Python 3.8's expat expands entities without a bound
        raise XmlErrors([TreeError(Pos(shown, *text_pos(data, found.start())), (
            "the file declares a %s: bmtree import reads no XML with a DTD or entity declarations (entities can "
            "expand without bound); BehaviorTree.CPP and Groot write none: remove it" % found.group(1).decode().upper()))])
    parser = xml.parsers.expat.ParserCreate(encoding="utf-8")   # the bytes are UTF-8, whatever the prolog says
    parser.SetParamEntityParsing(xml.parsers.expat.XML_PARAM_ENTITY_PARSING_NEVER)
    stack: List[Element] = []
    top: List[Element] = []

    def refuse(*_args: object) -> None:
        raise _Refused()

    def start(tag: str, attrs: Dict[str, str]) -> None:
        index = parser.CurrentByteIndex
        # from the line expat counts, not by counting from the file's start each time (quadratic)
        line_start = data.rfind(b"\n", 0, index) + 1
        pos = Pos(shown, parser.CurrentLineNumber, len(data[line_start:index].decode("utf-8", "replace")) + 1)
        if len(stack) >= MAX_XML_DEPTH:
            raise XmlErrors([TreeError(pos, "the XML nests deeper than %d elements (bmtree trees nest at most %d "
                                            "levels)" % (MAX_XML_DEPTH, MAX_XML_DEPTH - 2))])
        el = Element(tag, attrs, pos, _attribute_positions(data, index, pos))
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
        raise XmlErrors([TreeError(Pos(shown, exc.lineno, exc.offset + 1), "not well-formed XML: %s" % (
            xml.parsers.expat.ErrorString(exc.code)))])
    except _Refused:
        raise XmlErrors([TreeError(Pos(shown, parser.CurrentLineNumber, parser.CurrentColumnNumber + 1),
                                   "the file declares a DTD or entities, which bmtree import does not read")])
    return top[0]


def _attribute_positions(data: bytes, index: int, at: Pos) -> Dict[str, Pos]:
    """Where each attribute of the start tag at ``data[index]`` (written at ``at``) is written."""
    out: Dict[str, Pos] = {}
    tag = _TAG.match(data, index)
    i = tag.end() if tag is not None else index
    while True:
        m = _ATTR.match(data, i)
        if m is None:
            return out
        name = m.group(1).decode("utf-8", "replace")
        line, column = text_pos(data[index:m.start(1) + 1], m.start(1) - index)   # within the tag only
        out[name] = Pos(at.file, at.line + line - 1, column if line > 1 else at.column + column - 1)
        i = m.end()


class XmlErrors(Exception):
    """Problems of an XML file, each at its position."""

    def __init__(self, errors: List[TreeError]):
        super().__init__("\n".join(str(e) for e in errors))
        self.errors = errors

