"""bmtree import of ReactiveSequence and ReactiveFallback: the Conditions checked once, then polled beside the
child that runs (which a condition saying no halts), as BehaviorTree.CPP re-checks them at each tick; a child
before the running one that can run itself is refused where it is written."""
from __future__ import annotations

import json

import pytest

from coordinator.btimport import import_tree
from coordinator.cli import main
from coordinator.errors import TreeErrors
from coordinator.testing import fail, succeed
from modules.definition import load_definitions


def _fn(name, ins=(), outs=()):
    return {"Name": name, "Exec-condition": "", "Description": "", "Concurrent": True,
            "Input-params": [{"Name": n, "Data-type": "std_msgs/String", "Description": ""} for n in ins],
            "Output-params": [{"Name": n, "Data-type": "std_msgs/String", "Description": ""} for n in outs]}


MODULES = {"power": [_fn("battery_ok")], "base": [_fn("move_base", ["goal"])],
           "eyes": [_fn("is_detected", ["entity"], ["frame"])], "head": [_fn("look_around"), _fn("look_at")]}


@pytest.fixture()
def defs(tmp_path):
    for mod, fns in MODULES.items():
        spec = {"Basic Module": mod, "Brief Description": "", "Hardware Required": [], "Functions": fns}
        (tmp_path / ("%s.json" % mod)).write_text(json.dumps(spec))
    return load_definitions([str(tmp_path / ("%s.json" % m)) for m in MODULES])


def convert(tmp_path, xml, defs, poll=0.5):
    src = tmp_path / "tree.xml"
    src.write_text(xml)
    out = tmp_path / "tree.yaml"
    text, warnings = import_tree(str(src), defs, {}, str(out), poll=poll)
    out.write_text(text)
    assert warnings == []
    return str(out), text.split("\n", 1)[1]


def problems(tmp_path, xml, defs):
    src = tmp_path / "tree.xml"
    src.write_text(xml)
    with pytest.raises(TreeErrors) as info:
        import_tree(str(src), defs, {}, str(tmp_path / "tree.yaml"))
    return [(e.pos.line, e.pos.column, e.message) for e in info.value.errors]


def tree(body, fmt="4", extra=""):
    return '<root BTCPP_format="%s"><BehaviorTree ID="M">\n%s\n</BehaviorTree>%s</root>' % (fmt, body, extra)


GUARDED = tree('<ReactiveSequence name="go">\n  <BatteryOK/>\n  <MoveBase goal="kitchen"/>\n</ReactiveSequence>')

GUARDED_YAML = """\
format: 1
name: M
root:
  name: go
  sequence:
    - call: power.battery_ok
    - parallel:
        - call: base.move_base
          name: MoveBase
          inputs: {goal: kitchen}
        - name: while BatteryOK
          sequence:
            - repeat: 172800
              child:
                sequence:
                  - wait: 0.5
                  - call: power.battery_ok
            - fail: "stopped watching BatteryOK after a day (172800 checks, one every 0.5s): bmtree import's bound"
      succeed_on: [MoveBase]
"""


def test_reactive_sequence_checks_once_then_polls_beside_the_action(tmp_path, defs):
    assert convert(tmp_path, GUARDED, defs)[1] == GUARDED_YAML


def test_a_condition_failing_while_the_action_runs_halts_it(tmp_path, defs, bmtree_tree):
    path, _text = convert(tmp_path, GUARDED, defs)
    t = bmtree_tree(path, definitions=defs)
    t.mocks["power.battery_ok"].script(succeed(), succeed(), fail("low"))
    t.mocks["base.move_base"].script(succeed(delay=10))
    run = t.run()
    assert run.failed and run.reason == "repeat x172800: power.battery_ok failed: low"
    assert [c.started for c in run.calls("power.battery_ok")] == [0.0, 0.5, 1.0]
    [drive] = run.calls("base.move_base")
    assert (drive.status, drive.cancel_sent, drive.ended) == ("halted", True, 1.0)


def test_the_action_ending_ends_the_watch(tmp_path, defs, bmtree_tree):
    path, _text = convert(tmp_path, GUARDED, defs)
    t = bmtree_tree(path, definitions=defs)
    t.mocks["base.move_base"].script(succeed(delay=1.2))
    run = t.run()
    assert run.succeeded and run.duration == pytest.approx(1.2)
    assert [c.started for c in run.calls("power.battery_ok")] == [0.0, 0.5, 1.0]
    t.mocks["base.move_base"].script(fail("blocked", delay=0.7))
    run = t.run()
    assert run.failed and run.reason == "MoveBase: base.move_base failed: blocked"


def test_a_condition_failing_at_the_first_tick_never_starts_the_action(tmp_path, defs, bmtree_tree):
    path, _text = convert(tmp_path, GUARDED, defs)
    t = bmtree_tree(path, definitions=defs)
    t.mocks["power.battery_ok"].script(fail("low"))
    run = t.run()
    assert run.failed and run.calls("base.move_base") == []


def test_the_watch_gives_up_after_a_day(tmp_path, defs, bmtree_tree):
    xml = tree('<ReactiveSequence><BatteryOK/><Sleep msec="100000000"/></ReactiveSequence>')
    path, text = convert(tmp_path, xml, defs, poll=3600)
    assert "            - repeat: 24\n" in text and "                  - wait: 3600\n" in text
    with open(path, "w") as fh:   # its 24 checks an hour apart, a second apart (a day is 345,600 ticks)
        fh.write(text.replace("wait: 3600\n", "wait: 1\n"))
    run = bmtree_tree(path, definitions=defs).run()
    assert run.failed and run.duration == pytest.approx(24) and len(run.calls("power.battery_ok")) == 25
    assert run.reason == "fail: stopped watching BatteryOK after a day (24 checks, one every 3600s): bmtree " \
                         "import's bound"


SEARCH = tree('<ReactiveFallback>\n  <Condition ID="IsDetected" entity="cup" frame="{cup}"/>\n'
              '  <Action ID="LookAround"/>\n</ReactiveFallback>')

SEARCH_YAML = """\
format: 1
name: M
root:
  selector:
    - call: eyes.is_detected
      inputs: {entity: cup}
      outputs: {frame: cup}
    - parallel:
        - call: head.look_around
          name: LookAround
        - name: until IsDetected
          selector:
            - retry: 172800
              child:
                sequence:
                  - wait: 0.5
                  - call: eyes.is_detected
                    inputs: {entity: cup}
                    outputs: {frame: cup}
            - fail: "stopped watching IsDetected after a day (172800 checks, one every 0.5s): bmtree import's bound"
      policy: one
"""


def test_reactive_fallback_polls_until_a_condition_holds(tmp_path, defs, bmtree_tree):
    path, text = convert(tmp_path, SEARCH, defs)
    assert text == SEARCH_YAML
    t = bmtree_tree(path, definitions=defs)
    t.mocks["eyes.is_detected"].script(fail("no"), fail("no"), succeed(frame="cup_1"))
    t.mocks["head.look_around"].script(succeed(delay=10))
    run = t.run()
    assert run.succeeded and run.duration == pytest.approx(1.0) and run.blackboard["cup"] == "cup_1"
    [look] = run.calls("head.look_around")
    assert (look.status, look.cancel_sent) == ("halted", True)


def test_reactive_fallback_ends_with_its_action_or_never_starts_it(tmp_path, defs, bmtree_tree):
    path, _text = convert(tmp_path, SEARCH, defs)
    t = bmtree_tree(path, definitions=defs)
    t.mocks["eyes.is_detected"].script(fail("no"))
    t.mocks["head.look_around"].script(fail("stuck", delay=0.7))
    run = t.run()
    assert run.failed and run.reason == "LookAround: head.look_around failed: stuck"
    assert len(run.calls("eyes.is_detected")) == 2   # once, then the poll at 0.5 s
    t.mocks["eyes.is_detected"].script(succeed(frame="cup_1"))
    run = t.run()
    assert run.succeeded and run.calls("head.look_around") == []


def test_while_do_else_of_two_is_a_reactive_sequence(tmp_path, defs):
    _path, text = convert(tmp_path, GUARDED.replace("ReactiveSequence", "WhileDoElse"), defs)
    assert text == GUARDED_YAML


def test_poll_option(tmp_path, defs, capsys):
    src = tmp_path / "t.xml"
    src.write_text(GUARDED)
    mods = [a for m in MODULES for a in ("--modules", str(tmp_path / ("%s.json" % m)))]
    assert main(["import", str(src), "--poll", "2"] + mods) == 0
    out = capsys.readouterr().out
    assert "            - repeat: 43200\n" in out and "                  - wait: 2\n" in out
    for bad in ("0", "-1", "nan", "inf", "0.001", "3601", "x"):
        assert main(["import", str(src), "--poll", bad] + mods) == 2
        assert "argument --poll: expected seconds from 0.01 to 3600, got '%s'" % bad in capsys.readouterr().err


def test_what_runs_is_told_by_the_xml(tmp_path, defs):
    # the last child a Condition: the Action before it is the one that runs, nothing to re-check before it
    xml = tree('<ReactiveFallback><Action ID="LookAround"/><Condition ID="IsDetected" entity="cup"/>'
               '</ReactiveFallback>')
    assert convert(tmp_path, xml, defs)[1].endswith(
        "root:\n  selector:\n    - call: head.look_around\n    - call: eyes.is_detected\n      inputs: {entity: cup}\n")
    # one child; only conditions; TreeNodesModel says what a bare tag is
    xml = tree('<ReactiveSequence><MoveBase goal="a"/></ReactiveSequence>')
    assert convert(tmp_path, xml, defs)[1].endswith("root:\n  sequence:\n    - call: base.move_base\n"
                                                    "      inputs: {goal: a}\n")
    model = '<TreeNodesModel><Condition ID="IsDetected"/><Condition ID="BatteryOK"/></TreeNodesModel>'
    xml = tree('<ReactiveSequence><BatteryOK/><IsDetected entity="cup"/></ReactiveSequence>', extra=model)
    assert convert(tmp_path, xml, defs)[1].endswith(
        "root:\n  sequence:\n    - call: power.battery_ok\n    - call: eyes.is_detected\n      inputs: {entity: cup}\n")
    # checks only before the action: bmtree's memory: false re-checks them at each tick, as BehaviorTree.CPP
    xml = tree('<ReactiveSequence><AlwaysSuccess/><MoveBase goal="a"/><BatteryOK/></ReactiveSequence>', extra=model)
    assert convert(tmp_path, xml, defs)[1].endswith(
        "root:\n  sequence:\n    - sequence:\n        - check: \"true\"\n        - call: base.move_base\n"
        "          inputs: {goal: a}\n      memory: false\n    - call: power.battery_ok\n")


SAY = ("but it comes before %s, the last child that runs in %s (line %d): BehaviorTree.CPP ticks it again on every "
       "tick while that one runs, and halts that one whenever it runs; bmtree import polls Conditions there, not "
       "nodes that run: put only Conditions before the running child, run this one before the %s (both in a "
       "Sequence), or write this part in the YAML by hand ('Reacting while an action runs' in trees/README.md)")


def test_a_child_that_runs_before_the_running_one_is_refused(tmp_path, defs):
    model = '<TreeNodesModel><Action ID="LookAt"/></TreeNodesModel>'
    xml = tree("""<ReactiveSequence>
  <ReactiveFallback>
    <Condition ID="IsDetected" entity="cup"/>
    <Action ID="LookAround"/>
  </ReactiveFallback>
  <LookAt/>
  <Sleep msec="10"/>
  <MoveBase goal="a"/>
</ReactiveSequence>""", extra=model)
    assert problems(tmp_path, xml, defs) == [
        (3, 3, "the ReactiveFallback can run (the Action 'LookAround' at line 5), "
               + SAY % ("'MoveBase'", "ReactiveSequence", 2, "ReactiveSequence")),
        (7, 3, "the Action 'LookAt' can run (TreeNodesModel declares it), "
               + SAY % ("'MoveBase'", "ReactiveSequence", 2, "ReactiveSequence")),
        (8, 3, "the Sleep can run (it waits), " + SAY % ("'MoveBase'", "ReactiveSequence", 2, "ReactiveSequence"))]
    xml = tree('<ReactiveFallback>\n<Action ID="LookAround"/>\n<SubTree ID="S"/>\n</ReactiveFallback>',
               extra='<BehaviorTree ID="S"><Sequence><BatteryOK/><Action ID="LookAt"/></Sequence></BehaviorTree>')
    assert problems(tmp_path, xml.replace('<root BTCPP_format="4">', '<root BTCPP_format="4" main_tree_to_execute'
                                          '="M">'), defs) == [
        (3, 1, "the Action 'LookAround' can run, " + SAY % ("the SubTree 'S'", "ReactiveFallback", 2, "ReactiveFallback"))]


def test_nested_in_the_running_place_and_names_kept_apart(tmp_path, defs, bmtree_tree):
    xml = tree("""<ReactiveSequence>
  <Condition ID="BatteryOK"/>
  <ReactiveFallback name="while BatteryOK">
    <Condition ID="IsDetected" entity="cup"/>
    <Action ID="LookAround"/>
  </ReactiveFallback>
</ReactiveSequence>""")
    path, text = convert(tmp_path, xml, defs)
    assert "    - parallel:\n        - name: while BatteryOK\n          selector:\n" in text
    assert '        - name: "while BatteryOK (watch)"\n' in text and "      succeed_on: [while BatteryOK]\n" in text
    t = bmtree_tree(path, definitions=defs)
    t.mocks["eyes.is_detected"].script(fail("no"), fail("no"), fail("no"), succeed())
    t.mocks["head.look_around"].script(succeed(delay=10))
    run = t.run()   # BatteryOK holds; the cup is seen at the third poll
    assert run.succeeded and run.duration == pytest.approx(1.5) and len(run.calls("power.battery_ok")) == 4
    assert [c.status for c in run.calls("head.look_around")] == ["halted"]


def test_the_watch_is_named_as_behaviortree_cpp_shows_its_conditions(tmp_path, defs):
    xml = tree('<ReactiveFallback><Inverter><BatteryOK/></Inverter><SubTree ID="Seen"/><MoveBase goal="a"/>'
               '</ReactiveFallback>', extra='<BehaviorTree ID="Seen"><IsDetected entity="cup"/></BehaviorTree>')
    _path, text = convert(tmp_path, xml.replace('"4">', '"4" main_tree_to_execute="M">'), defs)
    assert "        - name: until not BatteryOK or Seen\n" in text and "\n      policy: one\n" in text
    assert '            - fail: "stopped watching not BatteryOK or Seen after a day (172800 checks, one every ' \
           '0.5s): bmtree import\'s bound"\n' in text
