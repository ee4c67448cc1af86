"""bmtree import: what it cannot convert, said exactly where (every problem at once), and the CLI's exit codes."""
from __future__ import annotations

import pytest

from coordinator.btimport import import_tree
from coordinator.cli import main
from coordinator.errors import TreeErrors

FUNCTIONS = ("battery.level, battery.charge, navigation.go_to, navigation.approach, navigation.where_am_i, "
             "speech.say, speech.listen, vision.find_object, vision.find_person")

BAD = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence foo="1">
      <Grasp object="cup"/>
      <GoTo place="kitchen" speed="2"/>
      <speech.listen seconds="five" text="hi"/>
      <KeepRunningUntilFailure><Say text="a"/></KeepRunningUntilFailure>
      <Parallel success_count="2" failure_count="1"><Say text="a"/><Say text="b"/><Say text="c"/></Parallel>
      <Say text="x" _skipIf="a == 1"/>
      <SubTree ID="Reprot"/>
      <RetryUntilSuccessful num_attempts="-1"><Say text="a"/></RetryUntilSuccessful>
      <GoTo/>
      <approach target="1;2"/>
      <Find object="x"/>
      <WhileDoElse><Say text="a"/><Say text="b"/><Say text="c"/></WhileDoElse>
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Report"><Say text="r"/></BehaviorTree>
</root>
"""

EXPECTED = [
    (3, 15, "Sequence has no attribute 'foo' (it takes only name)"),
    (4, 7, "Action 'Grasp' matches no module function: give --map Grasp=module.function (functions of the "
           "definitions: %s)" % FUNCTIONS),
    (5, 29, "Action 'GoTo' (navigation.go_to) has no port 'speed': its inputs: place; its outputs: success, room, "
            "position (rename it: --map 'GoTo=navigation.go_to(speed=INPUT)', or drop it: -speed)"),
    (6, 22, "Action 'speech.listen' (speech.listen): input 'seconds' takes a number (std_msgs/Float64), got 'five'"),
    (6, 37, "Action 'speech.listen' (speech.listen): 'text' is an output: give it the blackboard key to write, "
            "text=\"{key}\", not 'hi'"),
    (7, 7, "KeepRunningUntilFailure is not converted: bmtree has no such node (BehaviorTree.CPP's "
           "KeepRunningUntilFailure has no kind of its own in bmtree: repeat: N runs the child again while it "
           "succeeds, at most N times (every bmtree loop is bounded)); write that in the YAML by hand, or change "
           "the XML"),
    (8, 7, "Parallel with success_count 2 and failure_count 1 of 3 children is not converted: bmtree's parallel "
           "succeeds when all children do (policy: all), when the first does (policy: one, failure_count 1; policy: "
           "first_success, failure_count 3) or when named children do (succeed_on): it cannot count 2 successes"),
    (9, 21, "_skipIf of Say (a BehaviorTree.CPP pre/post condition) is not converted: write a selector of check: "
            "'condition' and the node (it is skipped, as SUCCESS, while the condition holds)"),
    (10, 16, "SubTree 'Reprot': no BehaviorTree of that ID in the file (Main, Report) (did you mean 'Report'?)"),
    (11, 29, "num_attempts of RetryUntilSuccessful is -1 (for ever): every bmtree loop and wait is bounded; give the "
             "most it may take, or --forever N to write N for each"),
    (12, 7, "Action 'GoTo' (navigation.go_to): no port place, the function's input: give place=\"…\" or "
            "place=\"{key}\""),
    (13, 17, "Action 'approach' (navigation.approach): input 'target' takes a geometry_msgs/Point: a {key} that "
             "holds one, or x;y;z numbers, got '1;2'"),
    (14, 7, "Action 'Find' matches no module function: give --map Find=module.function (functions of the "
            "definitions: %s)" % FUNCTIONS),
    (15, 7, "WhileDoElse with an else branch is not converted: bmtree would have to tick its condition twice a "
            "tick; write a selector with memory: false of a sequence with memory: false [condition, do] and the "
            "else node, or give WhileDoElse two children"),
]


def problems(tmp_path, xml, sim_defs, maps=None):
    src = tmp_path / "tree.xml"
    src.write_text(xml)
    with pytest.raises(TreeErrors) as info:
        import_tree(str(src), sim_defs, maps or {}, str(tmp_path / "tree.yaml"))
    assert all(e.pos.file == str(src) for e in info.value.errors)
    return [(e.pos.line, e.pos.column, e.message) for e in info.value.errors]


def test_every_problem_at_its_place(tmp_path, sim_defs):
    assert problems(tmp_path, BAD, sim_defs) == EXPECTED


def test_ambiguous_and_wrong_map(tmp_path, sim_defs):
    xml = '<root BTCPP_format="4"><BehaviorTree ID="T">\n<Sequence>\n<Level/>\n<Mod/>\n</Sequence></BehaviorTree></root>'
    assert problems(tmp_path, xml, sim_defs, {"Level": "battery.lvl", "Mod": "arm.grab"}) == [
        (3, 1, "Action 'Level' --map Level=battery.lvl names no function of the definitions (module 'battery' has: "
               "level, charge)"),
        (4, 1, "Action 'Mod' --map Mod=arm.grab names no function of the definitions (no module 'arm'; modules: "
               "battery, navigation, speech, vision; give its definition with --modules)")]


def test_subtree_cycle_and_output_literal(tmp_path, sim_defs):
    xml = """<root BTCPP_format="4" main_tree_to_execute="A">
  <BehaviorTree ID="A"><Sequence><SubTree ID="B" heard="now"/></Sequence></BehaviorTree>
  <BehaviorTree ID="B"><Sequence><listen seconds="1" text="{heard}"/><SubTree ID="A"/></Sequence></BehaviorTree>
</root>"""
    assert problems(tmp_path, xml, sim_defs) == [
        (3, 54, "Action 'listen' (speech.listen): 'text' is an output, but the SubTree gives it the literal 'now' "
                "(%s:2:50): give it a {key}" % (tmp_path / "tree.xml")),
        (3, 70, "SubTree 'A' includes itself: A -> B -> A")]


def test_check_errors_at_the_xml_line(tmp_path, sim_defs):
    xml = """<root BTCPP_format="4"><BehaviorTree ID="T">
  <Sequence>
    <Say text="{x}"/>
    <listen seconds="1" text="{x}"/>
  </Sequence>
</BehaviorTree></root>"""
    assert problems(tmp_path, xml, sim_defs) == [
        (3, 5, "reads 'x', which is not written on every path before this node (written at line 4, but not before "
               "it on every path: write it earlier on every path or declare it under 'inputs:') (imported YAML "
               "line 7)")]


@pytest.mark.parametrize("decl", ['<!DOCTYPE root [<!ENTITY a "aaaaaaaa">]>', '<!ENTITY a "b">'])
def test_dtd_refused_before_parsing(tmp_path, capsys, decl):
    src, out = tmp_path / "t.xml", tmp_path / "t.yaml"
    src.write_text('<?xml version="1.0"?>\n%s\n<root BTCPP_format="4"/>\n' % decl)
    assert main(["import", str(src), "-o", str(out)]) == 2
    word = "DOCTYPE" if "DOCTYPE" in decl else "ENTITY"
    assert capsys.readouterr().err == (
        "%s:2:1: the file declares a %s: bmtree import reads no XML with a DTD or entity declarations (entities can "
        "expand without bound); BehaviorTree.CPP and Groot write none: remove it\n" % (src, word))
    assert not out.exists()


def test_not_well_formed_and_not_a_tree(tmp_path, capsys):
    src = tmp_path / "t.xml"
    src.write_text('<root>\n <BehaviorTree ID="a">\n  <Say text="x">\n </BehaviorTree></root>')
    assert main(["import", str(src)]) == 2
    assert capsys.readouterr().err == "%s:4:4: not well-formed XML: mismatched tag\n" % src
    src.write_text('<tree/>')
    assert main(["import", str(src)]) == 2
    assert capsys.readouterr().err == "%s:1:1: not a BehaviorTree.CPP file: its top element is <tree>, not <root>\n" % src


def test_cli_writes_only_a_checked_tree(tmp_path, capsys):
    src, out = tmp_path / "t.xml", tmp_path / "t.yaml"
    src.write_text('<root BTCPP_format="4"><BehaviorTree ID="T"><Say text="hi"/></BehaviorTree></root>')
    assert main(["import", str(src)]) == 0
    assert capsys.readouterr().out.endswith("format: 1\nname: T\nroot:\n  call: speech.say\n  inputs: {text: hi}\n")
    assert main(["import", str(src), "-o", str(out)]) == 0
    assert out.read_text().endswith("root:\n  call: speech.say\n  inputs: {text: hi}\n")
    assert main(["check", str(out)]) == 0
    out.unlink()
    src.write_text('<root BTCPP_format="4"><BehaviorTree ID="T"><Grab/></BehaviorTree></root>')
    assert main(["import", str(src), "-o", str(out)]) == 2
    assert not out.exists()
    assert main(["import", str(src), "--map", "Grab=speech.say"]) == 2   # now its input is missing
    assert "no port text" in capsys.readouterr().err
    assert main(["import", str(src), "--map", "Grab"]) == 2
    assert capsys.readouterr().err.endswith("--map takes ID=module.function, or ID=module.function(port=input,-port) "
                                            "to rename or drop ports (e.g. --map 'Speak=speech.say(say_text=text)'), "
                                            "got 'Grab'\n")
    assert main(["import", str(tmp_path / "none.xml")]) == 2


def test_a_count_of_children_is_said_in_words_that_fit_it(tmp_path, sim_defs):
    xml = ('<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence><Sequence/><Inverter/>'
           '<Inverter><Sequence/></Inverter></Sequence></BehaviorTree></root>')
    said = [m for _l, _c, m in problems(tmp_path, xml, sim_defs)]
    assert "Sequence takes at least 1 child, it has 0" in said and "Inverter takes 1 child, it has 0" in said
