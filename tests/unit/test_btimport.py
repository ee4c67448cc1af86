"""bmtree import: BehaviorTree.CPP XML (formats 3 and 4) converted, then loaded and run as the original runs."""
from __future__ import annotations

import pytest

from coordinator.btimport import import_tree
from coordinator.language import load_tree
from coordinator.testing import TreeTest, fail, succeed

V4 = """<?xml version="1.0" encoding="UTF-8"?>
<root BTCPP_format="4" main_tree_to_execute="MainTree">
  <BehaviorTree ID="MainTree">
    <Sequence name="fetch">
      <SetBlackboard output_key="room" value="kitchen"/>
      <RetryUntilSuccessful num_attempts="3">
        <GoTo place="{room}"/>
      </RetryUntilSuccessful>
      <Fallback>
        <Action ID="FindObject" object="apple" position="{apple_at}"/>
        <ForceFailure>
          <Say text="I cannot find it"/>
        </ForceFailure>
      </Fallback>
      <Timeout msec="5000">
        <speech_listen seconds="2.5" text="{heard}"/>
      </Timeout>
      <Delay delay_msec="500">
        <SubTree ID="Report" what="{heard}"/>
      </Delay>
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Report">
    <Say text="{what}"/>
  </BehaviorTree>
  <TreeNodesModel>
    <Action ID="GoTo"><input_port name="place"/></Action>
  </TreeNodesModel>
</root>
"""

V4_YAML = """\
format: 1
name: MainTree
root:
  name: fetch
  sequence:
    - set: {room: kitchen}
    - retry: 3
      child:
        call: navigation.go_to
        inputs: {place: $room}
    - selector:
        - call: vision.find_object
          inputs: {object: apple}
          outputs: {position: apple_at}
        - force_failure:
            call: speech.say
            inputs: {text: I cannot find it}
    - timeout: 5
      child:
        call: speech.listen
        inputs: {seconds: 2.5}
        outputs: {text: heard}
    - sequence:
        - wait: 0.5
        - call: speech.say
          name: Report
          inputs: {text: $heard}
"""

V3 = """<root main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <SequenceStar>
      <IfThenElse name="look">
        <Condition ID="FindObject" object="apple" position="{pos}"/>
        <Action ID="Say" text="Found it {ok}"/>
        <Say text="Not found"/>
      </IfThenElse>
      <Parallel threshold="1">
        <FindObject object="cup" position="{cup}"/>
        <WhereAmI position="{cup}"/>
      </Parallel>
      <SubTree ID="Approach" target="cup"/>
    </SequenceStar>
  </BehaviorTree>
  <BehaviorTree ID="Approach">
    <Sequence>
      <Action ID="navigation.approach" target="{target}"/>
      <listen seconds="1" text="{heard}"/>
      <Say text="{heard}"/>
    </Sequence>
  </BehaviorTree>
</root>
"""


def convert(tmp_path, xml, sim_defs, maps=None, name="tree.xml"):
    src = tmp_path / name
    src.write_text(xml)
    out = tmp_path / (name[:-4] + ".yaml")
    text, warnings = import_tree(str(src), sim_defs, maps or {}, str(out))
    out.write_text(text)
    return out, text, warnings


def test_v4_converts_to_the_expected_yaml(tmp_path, sim_defs):
    out, text, warnings = convert(tmp_path, V4, sim_defs)
    first, rest = text.split("\n", 1)
    assert first.startswith("# imported from ") and "tree.xml (BehaviorTree.CPP format 4, tree MainTree)" in first
    assert rest == V4_YAML
    assert warnings == []
    assert load_tree(str(out), sim_defs).name == "MainTree"


def test_v4_runs_as_the_original(tmp_path, sim_defs):
    out, _text, _w = convert(tmp_path, V4, sim_defs)
    t = TreeTest(str(out), definitions=sim_defs)
    t.mocks["navigation.go_to"].script(fail("blocked"), succeed(room="kitchen"))
    t.mocks["vision.find_object"].script(succeed(success=True, position={"x": 1.0, "y": 2.0}))
    t.mocks["speech.listen"].script(succeed(success=True, text="hello"))
    run = t.run()
    assert run.succeeded
    assert [c.status for c in run.calls("navigation.go_to")] == ["failed", "succeeded"]
    assert run.calls("navigation.go_to")[1].inputs["place"] == "kitchen"
    assert run.said() == ["hello"]   # the SubTree's port, remapped to the caller's key
    assert run.duration >= 0.5       # the Delay


def test_v4_fallback_fails_after_saying_so(tmp_path, sim_defs):
    out, _text, _w = convert(tmp_path, V4, sim_defs)
    t = TreeTest(str(out), definitions=sim_defs)
    t.mocks["vision.find_object"].script(succeed(success=False))
    run = t.run()
    assert run.failed
    assert run.said() == ["I cannot find it"]
    assert run.calls("speech.listen") == []


def test_v3_tree_converts(tmp_path, sim_defs):
    _out, text, warnings = convert(tmp_path, V3, sim_defs)
    assert "      policy: first_success\n" in text            # threshold 1
    assert "outputs: {text: approach_heard}" in text           # the subtree's own key, prefixed
    assert "inputs: {target: $cup}" in text                    # v3 remapping: a key name, no braces
    assert "inputs: {text: \"Found it {{ok}}\"}" in text     # literal braces are no template
    assert [(w.pos.line, w.pos.column, w.message) for w in warnings] == [
        (1, 1, "warning: no BTCPP_format on <root>: read as format 3, which BehaviorTree.CPP 3 and Groot 1 write "
               "without it (line 3 has <SequenceStar>, of format 3 only); BehaviorTree.CPP 4 would read it as format "
               "4, where a SubTree's place=\"kitchen\" is text, not the caller's key: add BTCPP_format=\"3\" or \"4\" "
               "to <root> to say which")]


@pytest.mark.parametrize("found, said", [(True, ["Found it {ok}", ""]), (False, ["Not found", ""])])
def test_v3_if_then_else_branches(tmp_path, sim_defs, found, said):
    out, _text, _w = convert(tmp_path, V3, sim_defs)
    t = TreeTest(str(out), definitions=sim_defs)
    t.mocks["vision.find_object"].script(succeed(success=found, position={"x": 1.0}), succeed(success=True))
    t.mocks["navigation.where_am_i"].script(fail("lost"))
    run = t.run()
    assert run.succeeded
    assert run.said() == said


def test_v3_if_then_else_then_failing_does_not_run_else(tmp_path, sim_defs):
    out, _text, _w = convert(tmp_path, V3, sim_defs)
    t = TreeTest(str(out), definitions=sim_defs)
    t.mocks["vision.find_object"].script(succeed(success=True))
    t.mocks["speech.say"].script(fail("mute"))
    run = t.run()
    assert run.failed
    assert [c.inputs["text"] for c in run.calls("speech.say")] == ["Found it {ok}"]


def test_map_and_reads_become_inputs(tmp_path, sim_defs):
    xml = """<root BTCPP_format="4"><BehaviorTree ID="T">
  <Sequence><Grasp place="{where}"/><Say text="{where}"/></Sequence>
</BehaviorTree></root>"""
    out, text, _w = convert(tmp_path, xml, sim_defs, {"Grasp": "navigation.go_to"})
    assert "inputs:\n  where: {}\n" in text
    t = TreeTest(str(out), definitions=sim_defs, inputs={"where": "hall"})
    run = t.run()
    assert run.succeeded and run.calls("navigation.go_to")[0].inputs["place"] == "hall"


def test_subtree_literal_and_autoremap(tmp_path, sim_defs):
    xml = """<root BTCPP_format="4" main_tree_to_execute="M">
  <BehaviorTree ID="M"><Sequence>
    <SubTree ID="Ask" secs="3"/>
    <SubTree ID="Ask" secs="4" _autoremap="true"/>
    <Say text="{text}"/>
  </Sequence></BehaviorTree>
  <BehaviorTree ID="Ask"><listen seconds="{secs}" text="{text}"/></BehaviorTree>
</root>"""
    out, text, _w = convert(tmp_path, xml, sim_defs)
    assert "inputs: {seconds: 3}\n      outputs: {text: ask_text}\n" in text   # its own key
    assert "inputs: {seconds: 4}\n      outputs: {text: text}\n" in text       # the caller's
    t = TreeTest(str(out), definitions=sim_defs)
    t.mocks["speech.listen"].script(succeed(success=True, text="one"), succeed(success=True, text="two"))
    assert t.run().said() == ["two"]
