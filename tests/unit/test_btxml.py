"""bmtree import's XML reader: positions as an editor shows them (any line ending, a BOM, one long line), and
what to write instead of a character XML does not take in an attribute."""
from __future__ import annotations

import pytest

from coordinator.btimport import import_tree
from coordinator.btxml import XmlErrors, parse_xml
from coordinator.errors import TreeErrors

TREE = '<root BTCPP_format="4">{nl}  <BehaviorTree ID="M">{nl}    <Sequence>{nl}      <Say text="é"/>{nl}' \
       '      <Bogus  a="€" b="1"/>{nl}    </Sequence>{nl}  </BehaviorTree>{nl}</root>{nl}'


@pytest.mark.parametrize("nl", ["\n", "\r\n", "\r"])
def test_positions_with_any_line_ending(nl):
    root = parse_xml(TREE.format(nl=nl), "t.xml")
    bogus = root.children[0].children[0].children[1]
    assert (bogus.pos.line, bogus.pos.column) == (5, 7)
    assert [(p.line, p.column) for p in bogus.attr_pos.values()] == [(5, 15), (5, 21)]


def test_a_byte_order_mark_is_no_column():
    root = parse_xml("\ufeff" + TREE.format(nl="\n"), "t.xml")
    assert (root.pos.line, root.pos.column, root.at("BTCPP_format").column) == (1, 1, 7)
    from coordinator.btxml import byte_pos

    assert byte_pos(b"\xef\xbb\xbf<a>\r<b/>", 3) == (1, 1)
    assert byte_pos(b"\xef\xbb\xbf<a>\r<b/>", 7) == (2, 1)


def test_one_long_line_keeps_its_columns():
    body = "".join('<Say text="%s"/>' % ("€" * (i % 3)) for i in range(2000))
    root = parse_xml('<root><BehaviorTree ID="M"><Sequence>%s</Sequence></BehaviorTree></root>' % body, "t.xml")
    says = root.children[0].children[0].children
    assert says[-1].pos.column == 38 + len(body) - len('<Say text="€"/>') and says[-1].pos.line == 1
    assert says[-1].at("text").column == says[-1].pos.column + 5


@pytest.mark.parametrize("attr, column, said", [
    ('if="a &amp;&amp; b"', 0, ""),
    ('if="a && b"', 23, "a '&' is written &amp; (a && b: a &amp;&amp; b), or begins an entity such as &lt; that "
                        "ends with ';'"),
    ('if="a & b"', 23, "a '&' is written &amp; (a && b: a &amp;&amp; b), or begins an entity such as &lt; that ends "
                       "with ';'"),
    ('if="a &amp b"', 23, "a '&' is written &amp; (a && b: a &amp;&amp; b), or begins an entity such as &lt; that "
                          "ends with ';'"),
    ('if="€ < 3"', 23, "a '<' in an attribute's value is written &lt; (a < b: a &lt; b)"),
    ('if="1" &', 24, "a '&' is written &amp; (a && b: a &amp;&amp; b), or begins an entity such as &lt; that ends "
                     "with ';'"),
])
def test_a_character_xml_does_not_take_is_named(attr, column, said):
    text = '<root>\r  <Precondition %s/></root>' % attr
    if not said:
        assert parse_xml(text, "t.xml").children[0].attrs["if"] == "a && b"
        return
    with pytest.raises(XmlErrors) as info:
        parse_xml(text, "t.xml")
    assert [str(e) for e in info.value.errors] == ["t.xml:2:%d: not well-formed XML: %s" % (column, said)]


def test_other_xml_errors_keep_expat_words():
    with pytest.raises(XmlErrors) as info:
        parse_xml("<root><a></b></root>", "t.xml")
    assert [str(e) for e in info.value.errors] == ["t.xml:1:12: not well-formed XML: mismatched tag"]


def test_not_utf8_after_a_bom_at_its_column(tmp_path, sim_defs):
    src = tmp_path / "t.xml"
    src.write_bytes(b'\xef\xbb\xbf<root a="\xe9"/>')
    with pytest.raises(TreeErrors) as info:
        import_tree(str(src), sim_defs, {}, str(tmp_path / "t.yaml"))
    assert [(e.pos.line, e.pos.column, e.message) for e in info.value.errors] == [(1, 10, "not UTF-8 text: byte 0xe9")]
