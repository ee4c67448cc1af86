"""The data-flow check counts only the paths by which a node can succeed: a fallback that surely fails
(``force_failure``, or anything built so that it cannot succeed) is no way for a selector or a switch
to succeed. Also: where a key read too early is written, two outputs to one key, and the keys a
subtree replaces on the one tree blackboard."""
from __future__ import annotations

import os
import textwrap
from typing import List

import pytest

from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from coordinator.testing import fail
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA

DEFS = load_definitions([SIM_DIR, os.path.join(DATA, "modules_lang")])

FIND = "{call: vision.find_person, inputs: {name: ''}, outputs: {position: host_position}}"
SAY = "{call: speech.say, inputs: {text: 'I cannot see you'}}"
FAIL = "{force_failure: %s}" % SAY
APPROACH = "{call: navigation.approach, inputs: {target: $host_position}}"


def write(tmp_path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return str(path)


def problems(tmp_path, text: str, name: str = "t.yaml") -> List[str]:
    """The errors of a tree (file names shortened), [] when it loads."""
    path = write(tmp_path, name, text)
    try:
        load_tree(path, DEFS)
    except TreeErrors as exc:
        return [str(e).replace(str(tmp_path) + os.sep, "") for e in exc.errors]
    return []


def warned(tmp_path, name: str) -> List[str]:
    tree = load_tree(str(tmp_path / name), DEFS)
    return [str(w).replace(str(tmp_path) + os.sep, "") for w in tree.warnings]


def fallback(alternative: str, inputs: str = "") -> str:
    """Find the host, else ``alternative``; then approach the host."""
    return "format: 1\n%sroot:\n  sequence:\n    - selector: [%s, %s]\n    - %s\n" % (
        "inputs:\n" + inputs if inputs else "", FIND, alternative, APPROACH)


# 1. a branch that never succeeds is not a way to succeed -------------------------------------------
NEVER_SUCCEED = {
    "force_failure": FAIL,
    "sequence ending in force_failure": "{sequence: [%s, {force_failure: {wait: 1}}]}" % SAY,
    "sequence with a force_failure first": "{sequence: [%s, %s]}" % (FAIL, SAY),
    "inverter of force_success": "{inverter: {force_success: %s}}" % SAY,
    "retry of force_failure": "{retry: 3, child: %s}" % FAIL,
    "retry with a reference count": "{retry: $tries, child: %s}" % FAIL,
    "timeout of force_failure": "{timeout: 5, child: %s}" % FAIL,
    "repeat of force_failure": "{repeat: 2, child: %s}" % FAIL,
    "repeat until of force_failure": "{repeat: 2, until: 'true', child: %s}" % FAIL,
    "for_each one of force_failure": "{for_each: $rooms, as: room, policy: one, child: %s}" % FAIL,
    "for_each all over a literal list": "{for_each: [a, b], as: room, child: %s}" % FAIL,
    "parallel all with a force_failure": "{parallel: [%s, %s]}" % (SAY, FAIL),
    "parallel one of force_failures": "{parallel: {policy: one, children: [%s, %s]}}" % (FAIL, FAIL),
    "selector of force_failures": "{selector: [%s, %s]}" % (FAIL, FAIL),
    "switch whose every case fails": "{switch: $tries, cases: {1: %s}, default: %s}" % (FAIL, FAIL),
    "force_success of a force_failure, inverted": "{inverter: {force_success: %s}}" % FAIL,
}


@pytest.mark.parametrize("alternative", list(NEVER_SUCCEED.values()), ids=list(NEVER_SUCCEED))
def test_a_fallback_that_never_succeeds_does_not_have_to_write_what_the_first_child_writes(tmp_path, alternative):
    assert problems(tmp_path, fallback(alternative, "  tries: {default: 2}\n  rooms: {default: [a]}\n")) == []


MAY_SUCCEED = {
    "a call": SAY,
    "force_success": "{force_success: %s}" % FAIL,
    "inverter of force_failure": "{inverter: %s}" % FAIL,
    "inverter of a call": "{inverter: %s}" % SAY,
    "repeat while (maybe no run)": "{repeat: 2, while: 'tries > 5', child: %s}" % FAIL,
    "for_each all over a list that may be empty": "{for_each: $rooms, as: room, child: %s}" % FAIL,
    "parallel one with a child that succeeds": "{parallel: {policy: one, children: [%s, %s]}}" % (FAIL, SAY),
    "selector with a child that succeeds": "{selector: [%s, %s]}" % (FAIL, SAY),
    "switch with a case that succeeds": "{switch: $tries, cases: {1: %s}, default: %s}" % (SAY, FAIL),
    "sequence of calls": "{sequence: [%s, %s]}" % (SAY, SAY),
}


@pytest.mark.parametrize("alternative", list(MAY_SUCCEED.values()), ids=list(MAY_SUCCEED))
def test_a_fallback_that_may_succeed_must_still_write_the_key(tmp_path, alternative):
    errs = problems(tmp_path, fallback(alternative, "  tries: {default: 2}\n  rooms: {default: [a]}\n"))
    assert len(errs) == 1 and "reads 'host_position', which is not written on every path" in errs[0], errs


def test_the_audit_fallback_and_switch_default(tmp_path):
    assert problems(tmp_path, fallback(FAIL)) == []
    assert problems(tmp_path, """\
        format: 1
        inputs:
          answer: {default: "yes"}
        root:
          sequence:
            - switch: $answer
              cases:
                "yes": %s
              default:
                force_failure: %s
            - %s
        """ % (FIND, SAY, APPROACH)) == []


def test_reads_inside_the_failing_branch_are_still_checked(tmp_path):
    errs = problems(tmp_path, fallback("{force_failure: {call: speech.say, inputs: {text: '{nobody}'}}}"))
    assert len(errs) == 1 and "reads 'nobody'" in errs[0], errs


def test_a_later_alternative_may_read_what_a_failed_one_surely_wrote(tmp_path):
    # the inverter fails only when the find succeeded: the say runs only then
    assert problems(tmp_path, """\
        format: 1
        root:
          selector:
            - inverter: %s
            - {call: navigation.approach, inputs: {target: $host_position}}
        """ % FIND) == []


def test_an_include_whose_subtree_never_succeeds_is_no_way_to_succeed(tmp_path):
    write(tmp_path, "sorry.yaml", "format: 1\nroot: %s\n" % FAIL)
    assert problems(tmp_path, fallback("{include: sorry.yaml}")) == []


# 2. where a key read too early is written ---------------------------------------------------------
def test_a_key_written_on_some_paths_says_where_not_a_close_name(tmp_path):
    errs = problems(tmp_path, """\
        format: 1
        root:
          sequence:
            - {call: vision.find_person, inputs: {name: ''}, outputs: {position: guest_position}}
            - selector: [%s, %s]
            - %s
        """ % (FIND, SAY, APPROACH))
    assert errs == ["t.yaml:6:52: reads 'host_position', which is not written on every path before this node "
                    "(written at line 5, but not before it on every path: write it earlier on every path or "
                    "declare it under 'inputs:')"]


def test_a_key_written_nowhere_still_gets_a_close_name(tmp_path):
    errs = problems(tmp_path, """\
        format: 1
        root:
          sequence:
            - {call: vision.find_person, inputs: {name: ''}, outputs: {position: guest_position}}
            - %s
        """ % APPROACH)
    assert errs == ["t.yaml:5:52: reads 'host_position', which no node writes and no input declares "
                    "(did you mean 'guest_position'?)"]


# 3. two outputs to one key ------------------------------------------------------------------------
def test_two_outputs_to_one_key_are_an_error_at_the_second(tmp_path):
    errs = problems(tmp_path, """\
        format: 1
        root:
          call: speech.listen
          inputs: {seconds: 1.0}
          outputs: {success: result, text: result}
        """)
    assert errs == ["t.yaml:5:36: outputs 'success' and 'text' both write tree key 'result': one value would "
                    "replace the other; give 'text' its own key"]


def test_two_params_of_an_event_to_one_key_are_an_error_too(tmp_path):
    errs = problems(tmp_path, """\
        format: 1
        root:
          wait_event: vision.personSeen
          outputs: {person: seen, position: seen}
        """)
    assert errs == ["t.yaml:4:37: outputs 'person' and 'position' both write tree key 'seen': one value would "
                    "replace the other; give 'position' its own key"]


# 4. keys a subtree replaces on the shared tree blackboard -----------------------------------------
SUB_LOOK = """\
    format: 1
    inputs:
      room: {}
      object: {default: apple}
    root:
      sequence:
        - {call: navigation.go_to, inputs: {place: $room}}
        - {call: vision.find_object, inputs: {object: $object}, outputs: {position: position}}
    """


def parent(args: str) -> str:
    return """\
        format: 1
        inputs:
          object: {default: cup}
        root:
          sequence:
            - {call: vision.find_object, inputs: {object: $object}, outputs: {position: position}}
            - include: sub_look.yaml
              args: %s
            - {call: navigation.approach, inputs: {target: $position}}
        """ % args


def test_a_subtree_default_or_output_replacing_the_callers_key_is_a_warning_naming_both(tmp_path):
    write(tmp_path, "sub_look.yaml", SUB_LOOK)
    write(tmp_path, "parent.yaml", parent("{room: kitchen}"))
    assert warned(tmp_path, "parent.yaml") == [
        "parent.yaml:7:7: warning: include of sub_look.yaml sets its input 'object' to its default 'apple', "
        "replacing the caller's 'object' (an input of parent.yaml): pass it on with args: {object: $object}, "
        "or rename one of them",
        "parent.yaml:7:7: warning: sub_look.yaml writes 'position' (sub_look.yaml:8), replacing the caller's "
        "'position' (written at line 6): rename one of them"]


def test_passing_the_callers_key_on_is_not_a_clash_but_another_value_is(tmp_path):
    write(tmp_path, "sub_look.yaml", SUB_LOOK.replace("outputs: {position: position}", "outputs: {position: seen}"))
    write(tmp_path, "parent.yaml", parent("{room: kitchen, object: $object}").replace("$position", "$seen"))
    assert warned(tmp_path, "parent.yaml") == []
    write(tmp_path, "parent.yaml", parent("{room: kitchen, object: mug}").replace("$position", "$seen"))
    assert warned(tmp_path, "parent.yaml") == [
        "parent.yaml:8:37: warning: argument 'object' of sub_look.yaml is set on the tree blackboard, replacing "
        "the caller's 'object' (an input of parent.yaml): rename the caller's key or the subtree's input"]


def test_the_same_subtree_twice_does_not_clash_with_itself(tmp_path):
    write(tmp_path, "sub_look.yaml", SUB_LOOK)
    write(tmp_path, "twice.yaml", """\
        format: 1
        root:
          sequence:
            - {include: sub_look.yaml, args: {room: kitchen}}
            - {include: sub_look.yaml, args: {room: $room}}
        """)
    assert warned(tmp_path, "twice.yaml") == []


# 5. a missing argument is the one error ------------------------------------------------------------
def test_a_missing_subtree_argument_is_reported_once_not_again_where_the_subtree_reads_it(tmp_path):
    write(tmp_path, "ask.yaml", """\
        format: 1
        inputs:
          question: {}
        root: {call: speech.say, inputs: {text: $question}}
        """)
    assert problems(tmp_path, "format: 1\nroot:\n  include: ask.yaml\n", "top.yaml") == [
        "top.yaml:3:12: include of ask.yaml needs argument 'question'"]


def test_the_accepted_fallback_runs_as_the_check_says(tmp_path, bmtree_tree):
    """When the find fails the fallback fails the selector, so the approach (reading the key) never runs."""
    t = bmtree_tree(write(tmp_path, "t.yaml", fallback(FAIL)), definitions=DEFS)
    t.mocks["vision.find_person"].script(fail("nobody there"))
    run = t.run()
    assert run.failed and run.calls("navigation.approach") == []
    assert [c.inputs["text"] for c in run.calls("speech.say")] == ["I cannot see you"]
    t = bmtree_tree(write(tmp_path, "t.yaml", fallback(FAIL)), definitions=DEFS)
    run = t.run()
    assert run.succeeded, run.reason
    assert len(run.calls("navigation.approach")) == 1
