"""bmtree import on what real BehaviorTree.CPP trees hold: numbers past any range, SequenceWithMemory under a
retry, InOut ports, a file without BTCPP_format, SetBlackboard's strings, subtrees' names and BehaviorTree.CPP
3's bare-word outputs and implicit subtrees, each converted as BehaviorTree.CPP runs it or refused where
written."""
from __future__ import annotations

import json

import pytest

from coordinator.btimport import import_tree
from coordinator.cli import main
from coordinator.errors import TreeErrors
from coordinator.testing import TreeTest, fail, succeed
from modules.definition import load_definitions

RANGE = "out of range (a number has at most 308 digits)"
NINES = "9" * 5000   # past Python 3.11's 4,300 digits of int()


def convert(tmp_path, xml, defs, maps=None):
    src = tmp_path / "tree.xml"
    src.write_text(xml)
    out = tmp_path / "tree.yaml"
    text, warnings = import_tree(str(src), defs, maps or {}, str(out))
    out.write_text(text)
    return out, text.split("\n", 1)[1], [(w.pos.line, w.pos.column, w.message) for w in warnings]


def problems(tmp_path, xml, defs):
    src = tmp_path / "tree.xml"
    src.write_text(xml)
    with pytest.raises(TreeErrors) as info:
        import_tree(str(src), defs, {}, str(tmp_path / "tree.yaml"))
    return [(e.pos.line, e.pos.column, e.message) for e in info.value.errors]


def v4(body):
    return '<root BTCPP_format="4"><BehaviorTree ID="M">\n<Sequence>\n%s\n</Sequence></BehaviorTree></root>' % body


def test_numbers_past_any_range_are_refused_where_written(tmp_path, sim_defs):
    xml = v4('<Timeout msec="1e400"><Say text="x"/></Timeout>\n<Sleep msec="1e309"/>\n'
             '<Delay delay_msec="1E999"><Say text="x"/></Delay>\n<listen seconds="-1e400" text="{t}"/>\n'
             '<SetBlackboard output_key="n" value="1e400"/>\n<Repeat num_cycles="{n}"><Say text="x"/></Repeat>\n'
             '<RetryUntilSuccessful num_attempts="%s"><Say text="x"/></RetryUntilSuccessful>\n'
             '<Parallel success_count="-%s"><Say text="x"/></Parallel>\n<Sleep msec="%s.5"/>\n'
             '<listen seconds="%s" text="{t}"/>' % (NINES, NINES, "1" * 309, NINES))
    long = "99999999999999999999… (5000 characters)"
    assert problems(tmp_path, xml, sim_defs) == [
        (3, 10, "msec of Timeout is 1e400: %s" % RANGE),
        (4, 8, "msec of Sleep is 1e309: %s" % RANGE),
        (5, 8, "delay_msec of Delay is 1E999: %s" % RANGE),
        (6, 9, "Action 'listen' (speech.listen): input 'seconds' is -1e400: %s" % RANGE),
        (7, 31, "value of SetBlackboard is 1e400: %s" % RANGE),   # a count reads it: a number
        (9, 23, "num_attempts of RetryUntilSuccessful is %s: %s" % (long, RANGE)),
        (10, 11, "success_count of Parallel is -9999999999999999999… (5001 characters): %s" % RANGE),
        (11, 8, "msec of Sleep is 11111111111111111111… (311 characters): %s" % RANGE),
        (12, 9, "Action 'listen' (speech.listen): input 'seconds' is %s: %s" % (long, RANGE))]


RETRIED = """<root BTCPP_format="4"><BehaviorTree ID="M">
  <RetryUntilSuccessful num_attempts="3">
    <SequenceWithMemory>
      <Say text="What is your name?"/>
      <FindObject object="cup"/>
    </SequenceWithMemory>
  </RetryUntilSuccessful>
</BehaviorTree></root>"""

RETRIED_YAML = """\
format: 1
name: M
root:
  sequence:
    - set: {sequence_1_done_1: false}
    - retry: 3
      child:
        sequence:
          - selector:
              - check: sequence_1_done_1
              - sequence:
                  - call: speech.say
                    inputs: {text: "What is your name?"}
                  - set: {sequence_1_done_1: true}
          - call: vision.find_object
            inputs: {object: cup}
          - set: {sequence_1_done_1: false}
"""


def test_sequence_with_memory_retried_resumes_at_the_child_that_failed(tmp_path, sim_defs):
    out, text, warnings = convert(tmp_path, RETRIED, sim_defs)
    assert (text, warnings) == (RETRIED_YAML, [])
    t = TreeTest(str(out), definitions=sim_defs)
    t.mocks["vision.find_object"].script(fail("not seen"), succeed(success=True))
    run = t.run()
    assert run.succeeded and run.said() == ["What is your name?"] and len(run.calls("vision.find_object")) == 2


def test_sequence_with_memory_run_once_stays_a_sequence(tmp_path, sim_defs):
    xml = v4('<ReactiveSequence><AlwaysSuccess/><SequenceStar><Say text="a"/><Say text="b"/></SequenceStar>'
             '</ReactiveSequence>')
    _out, text, _w = convert(tmp_path, xml, sim_defs)
    assert "              - check: sequence_1_done_1\n" in text   # a reactive parent ticks it again
    _out, text, _w = convert(tmp_path, xml.replace("ReactiveSequence", "Sequence"), sim_defs)
    assert "done" not in text and "        - sequence:\n            - call: speech.say\n" in text


def test_in_out_port_is_read_and_written(tmp_path):
    spec = {"Basic Module": "guests", "Brief Description": "", "Hardware Required": [], "Functions": [
        {"Name": "add_guest", "Exec-condition": "", "Description": "",
         "Input-params": [{"Name": "n", "Data-type": "std_msgs/Int32", "Description": ""}],
         "Output-params": [{"Name": "n", "Data-type": "std_msgs/Int32", "Description": ""}]}]}
    (tmp_path / "guests.json").write_text(json.dumps(spec))
    defs = load_definitions([str(tmp_path / "guests.json")])
    xml = v4('<SetBlackboard output_key="n" value="0"/>\n<AddGuest n="{n}"/>\n<AddGuest n="{n}"/>')
    out, text, _w = convert(tmp_path, xml, defs)
    assert text.endswith('    - set: {"n": 0}\n    - call: guests.add_guest\n      inputs: {"n": $n}\n'
                         '      outputs: {"n": "n"}\n    - call: guests.add_guest\n      inputs: {"n": $n}\n'
                         '      outputs: {"n": "n"}\n')
    t = TreeTest(str(out), definitions=defs)
    t.mocks["guests.add_guest"].script(succeed(n=1), succeed(n=2))
    run = t.run()
    assert [c.inputs["n"] for c in run.calls("guests.add_guest")] == [0, 1]


def test_switch_case_from_a_key_is_refused_and_from_a_subtree_literal_kept(tmp_path, sim_defs):
    xml = """<root BTCPP_format="4" main_tree_to_execute="M">
<BehaviorTree ID="M"><Sequence><SubTree ID="S" c="hall" room="{room}"/>
<Switch2 variable="{room}" case_1="kitchen" case_2="{other}"><Say text="a"/><Say text="b"/><Say text="c"/></Switch2>
</Sequence></BehaviorTree>
<BehaviorTree ID="S"><Switch2 variable="{room}" case_1="kitchen" case_2="{c}">
<Say text="a"/><Say text="b"/><Say text="c"/></Switch2></BehaviorTree></root>"""
    assert problems(tmp_path, xml, sim_defs) == [
        (3, 45, "case_2 of Switch2 is the blackboard key 'other': bmtree's switch cases are values written in the tree: "
                "give the value itself, or write the choice in the YAML by hand (a selector of sequences of check: "
                "\"variable == key\" and the node)")]
    _out, text, _w = convert(tmp_path, xml.replace(' case_2="{other}"', ' case_2="x"'), sim_defs)
    assert "        hall:\n" in text


NO_FORMAT = """<root main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence>
      <SubTree ID="Go" place="kitchen"/>
      %s
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Go"><GoTo place="{place}"/></BehaviorTree>
</root>"""


def test_a_file_without_format_is_read_as_its_nodes_say(tmp_path, sim_defs):
    _out, text, warnings = convert(tmp_path, NO_FORMAT % '<SequenceWithMemory><Say text="x"/></SequenceWithMemory>',
                                   sim_defs)
    assert "inputs: {place: kitchen}" in text   # format 4: the text
    assert warnings == [(1, 1, "warning: no BTCPP_format on <root>: read as format 4, as BehaviorTree.CPP 4 does "
                               "(line 5 has <SequenceWithMemory>, of format 4 only): add BTCPP_format=\"4\" to <root> "
                               "to say so")]
    _out, text, warnings = convert(tmp_path, NO_FORMAT % '<Say text="x"/>', sim_defs)
    assert "inputs: {place: $kitchen}" in text and "inputs:\n  kitchen: {}\n" in text   # format 3: the caller's key
    assert warnings == [(1, 1, "warning: no BTCPP_format on <root>: read as format 3, which BehaviorTree.CPP 3 and "
                               "Groot 1 write without it (nothing in it is of format 4 only); BehaviorTree.CPP 4 would "
                               "read it as format 4, where a SubTree's place=\"kitchen\" is text, not the caller's key: "
                               "add BTCPP_format=\"3\" or \"4\" to <root> to say which")]
    assert problems(tmp_path, NO_FORMAT % '<Parallel threshold="1" success_count="1"><Say text="x"/></Parallel>',
                    sim_defs) == [
        (1, 1, "warning: no BTCPP_format on <root>: read as format 4, as BehaviorTree.CPP 4 does (line 5 has "
               "success_count=, of format 4 only; line 5 has threshold=, of format 3 only): add BTCPP_format=\"4\" to "
               "<root> to say so"),
        (5, 17, "Parallel has no attribute 'threshold' (it takes success_count, failure_count)")]


def test_set_blackboard_literal_is_typed_by_its_readers(tmp_path, sim_defs):
    xml = v4('<SetBlackboard output_key="count" value="42"/>\n<Say text="{count}"/>\n'
             '<SetBlackboard output_key="secs" value="2"/>\n<listen seconds="{secs}" text="{heard}"/>\n'
             '<SetBlackboard output_key="ms" value="1500"/>\n<Timeout msec="{ms}"><Say text="{heard}"/></Timeout>\n'
             '<SetBlackboard output_key="flag" value="true"/>\n<SetBlackboard output_key="copy" value="{count}"/>')
    _out, text, warnings = convert(tmp_path, xml, sim_defs)
    assert '    - set: {count: "42"}\n' in text and "    - set: {secs: 2}\n" in text
    assert "    - set: {ms: 1500}\n" in text and "    - timeout: \"$(ms / 1000)\"\n" in text
    assert '    - set: {flag: "true"}\n' in text and "    - set: {copy: $count}\n" in text   # no reader: BT.CPP's string
    assert warnings == []


def test_milliseconds_converted_are_no_habit_to_warn_about(tmp_path, sim_defs):
    xml = v4('<Sleep msec="3000000"/>\n<Timeout msec="1200000"><Say text="x"/></Timeout>\n'
             '<Delay delay_msec="2500000"><Say text="x"/></Delay>')
    _out, text, warnings = convert(tmp_path, xml, sim_defs)
    assert "    - wait: 3000\n" in text and "    - timeout: 1200\n" in text and "        - wait: 2500\n" in text
    assert warnings == []


def test_the_callers_name_wins_for_a_subtree(tmp_path, sim_defs):
    xml = """<root BTCPP_format="4" main_tree_to_execute="Main"><BehaviorTree ID="Main"><Sequence>
<SubTree ID="Sub" name="FirstSubtree"/><SubTree ID="Sub"/><SubTree ID="Plain"/></Sequence></BehaviorTree>
<BehaviorTree ID="Sub"><Sequence name="SleepSequence"><Sleep msec="300"/></Sequence></BehaviorTree>
<BehaviorTree ID="Plain"><Sequence><Sleep msec="300"/></Sequence></BehaviorTree></root>"""
    _out, text, _w = convert(tmp_path, xml, sim_defs)
    assert [line.strip() for line in text.splitlines() if "name:" in line] == [
        "name: Main", "- name: FirstSubtree", "- name: SleepSequence", "- name: Plain"]


def test_format_3_outputs_bare_words_and_empty_ones(tmp_path, sim_defs):
    xml = """<root BTCPP_format="3"><BehaviorTree ID="M"><Sequence>
<listen seconds="1" text="heard"/><listen seconds="1" text=""/><Say text="{heard}"/>
</Sequence></BehaviorTree></root>"""
    _out, text, _w = convert(tmp_path, xml, sim_defs)
    assert ("    - call: speech.listen\n      inputs: {seconds: 1}\n      outputs: {text: heard}\n"
            "    - call: speech.listen\n      inputs: {seconds: 1}\n    - call: speech.say\n") in text
    assert problems(tmp_path, xml.replace('"3"', '"4"'), sim_defs) == [
        (2, 21, "Action 'listen' (speech.listen): 'text' is an output: give it the blackboard key to write, "
                "text=\"{key}\", not 'heard'")]   # format 4 writes no bare word (and keeps no "" either)


def test_tree_option_chooses_among_several(tmp_path, capsys):
    src = tmp_path / "t.xml"
    src.write_text('<root BTCPP_format="4">\n<BehaviorTree ID="MainTree"><Say text="a"/></BehaviorTree>\n'
                   '<BehaviorTree ID="Other"><Say text="b"/></BehaviorTree></root>')
    assert main(["import", str(src)]) == 2
    assert capsys.readouterr().err == (
        "%s:1:1: several BehaviorTrees (MainTree, Other) and no main_tree_to_execute on <root>: choose the one to "
        "import with --tree ID (BehaviorTree.CPP's createTree(ID))\n" % src)
    assert main(["import", str(src), "--tree", "Other"]) == 0
    assert capsys.readouterr().out.endswith("name: Other\nroot:\n  call: speech.say\n  inputs: {text: b}\n")
    assert main(["import", str(src), "--tree", "Main"]) == 2
    assert "--tree Main: no BehaviorTree of that ID in %s (MainTree, Other) (did you mean 'MainTree'?)" % src \
        in capsys.readouterr().err


def test_format_3_includes_a_tree_by_its_tag(tmp_path, sim_defs):
    xml = """<root BTCPP_format="3" main_tree_to_execute="Main"><BehaviorTree ID="Main"><Sequence>
<SetBlackboard output_key="greeting" value="hi"/><SayHello what="greeting"/><Action ID="SayHello" what="{greeting}"/>
</Sequence></BehaviorTree>
<BehaviorTree ID="SayHello"><Say text="{what}"/></BehaviorTree></root>"""
    _out, text, _w = convert(tmp_path, xml, sim_defs)
    assert text.endswith("    - call: speech.say\n      name: SayHello\n      inputs: {text: $greeting}\n" * 2)
    assert problems(tmp_path, xml.replace('"3"', '"4"'), sim_defs)[0][:2] == (2, 50)   # format 4 has no such thing
    assert problems(tmp_path, xml.replace('"3"', '"4"'), sim_defs)[0][2].endswith(
        "; 'SayHello' is a BehaviorTree of this file, which format 4 includes with <SubTree ID=\"SayHello\"/>")


def test_unset_blackboard_and_loops_over_a_literal_queue(tmp_path, sim_defs):
    xml = v4('<LoopString queue="kitchen;hall" value="{room}"><GoTo place="{room}"/></LoopString>\n'
             '<LoopDouble queue="1;2.5" value="{s}" if_empty="FAILURE"><listen seconds="{s}" text="{t}"/></LoopDouble>\n'
             '<UnsetBlackboard key="room"/>')
    _out, text, _w = convert(tmp_path, xml, sim_defs)
    assert text.endswith("""\
    - for_each: [kitchen, hall]
      as: room
      child:
        call: navigation.go_to
        inputs: {place: $room}
    - force_failure:
        for_each: [1.0, 2.5]
        as: s
        child:
          call: speech.listen
          inputs: {seconds: $s}
          outputs: {text: t}
    - set: {room: null}
""")
    assert problems(tmp_path, v4('<LoopInt queue="1;x" value="{n}"><Say text="a"/></LoopInt>\n'
                                 '<LoopString queue="{q}" value="{n}"><Say text="a"/></LoopString>'), sim_defs) == [
        (3, 10, "queue of LoopInt holds 'x', which is no whole number"),
        (4, 13, "LoopString over the queue of a blackboard key is not converted: bmtree's for_each runs over a list "
                "written in the tree (or a key holding a list): write for_each: $key, with as: and child: beside it, "
                "in the YAML by hand")]


def test_forever_writes_a_bound_for_each_minus_one_and_says_so(tmp_path, capsys):
    """4 of 4 real RoboCup trees retried -1 times (BehaviorTree.CPP's for ever): --forever N converts them."""
    from coordinator.cli import main as bmtree

    xml = tmp_path / "t.xml"
    xml.write_text('<root BTCPP_format="4">\n  <BehaviorTree ID="Main">\n    <RetryUntilSuccessful num_attempts="-1">\n'
                   '      <Repeat num_cycles="-1">\n        <AlwaysSuccess/>\n      </Repeat>\n'
                   '    </RetryUntilSuccessful>\n  </BehaviorTree>\n</root>\n')
    assert bmtree(["import", str(xml), "--forever", "1000"]) == 0
    out = capsys.readouterr()
    assert "retry: 1000" in out.out and "repeat: 1000" in out.out, out.out
    assert out.err.replace(str(xml), "t.xml").splitlines() == [
        "t.xml:3:27: warning: num_attempts of RetryUntilSuccessful is -1 (for ever): written as 1000 (--forever)",
        "t.xml:4:15: warning: num_cycles of Repeat is -1 (for ever): written as 1000 (--forever)"], out.err
    for bad in ("0", "x", "10000000000"):
        assert bmtree(["import", str(xml), "--forever", bad]) == 2
        assert "argument --forever: expected a whole number of runs from 1, got '%s'" % bad in capsys.readouterr().err


def test_map_renames_and_drops_ports(tmp_path, capsys):
    """The IRL trees' Speak say_text=, Nav2's server_timeout: --map renames a port to the function's input, or
    drops it; a rename to a name the function does not have is an error naming its ports."""
    from coordinator.cli import main as bmtree

    xml = tmp_path / "t.xml"
    xml.write_text('<root BTCPP_format="4">\n  <BehaviorTree ID="Main">\n    <Sequence>\n'
                   '      <Speak say_text="{greeting}" server_timeout="100"/>\n'
                   '      <Listen listened_text="{heard}" seconds="3"/>\n    </Sequence>\n  </BehaviorTree>\n</root>\n')
    assert bmtree(["import", str(xml), "--map", "Speak=speech.say(say_text=text, -server_timeout)",
                   "--map", "Listen=speech.listen(listened_text=text)"]) == 0
    out = capsys.readouterr().out
    assert "- call: speech.say\n      inputs: {text: $greeting}" in out, out
    assert "server_timeout" not in out and "outputs: {text: heard}" in out, out
    assert bmtree(["import", str(xml), "--map", "Speak=speech.say(say_text=txt)", "--map",
                   "Listen=speech.listen(listened_text=text)"]) == 2
    err = capsys.readouterr().err.replace(str(xml), "t.xml")
    assert "t.xml:4:7: --map Speak renames port say_text to 'txt', which speech.say does not have: its inputs: " \
           "text; its outputs: success" in err, err
    for bad in ("Speak=speech.say(say text=text)", "Speak=speech.say(=text)", "Speak=speech.say(a=b"):
        assert bmtree(["import", str(xml), "--map", bad]) == 2
        assert "--map takes ID=module.function, or ID=module.function(port=input,-port)" in capsys.readouterr().err
