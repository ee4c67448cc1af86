"""Data flow of SMACH ports: a ``switch`` on a call's ``status`` whose ``succeeded`` case reads the call's
outputs; a subtree that reads its caller's keys without declaring them (a warning at the include); and
``include`` ``outputs: {k: k}``, which replaces the caller's key on purpose (no warning)."""
from __future__ import annotations

import os

import pytest

from coordinator.cli import main as bmtree
from tests.unit.test_flow_paths import problems, warned, write

FIND = "{call: vision.find_object, inputs: {object: cup}, outputs: {position: cup_at}, status: found}"
APPROACH = "{call: navigation.approach, inputs: {target: $cup_at}}"
SAY = "{call: speech.say, inputs: {text: lost}}"
NOT_SURE = ("t.yaml:%d:%d: reads 'cup_at', which is not written on every path before this node (written at line %d, "
            "but not before it on every path: write it earlier on every path or declare it under 'inputs:')")


def routed(cases: str, before: str = "", after: str = "", inputs: str = "") -> str:
    """Find the cup (its status to ``found``), then ``before`` and a switch on ``$found`` with ``cases``."""
    return ("format: 1\n%sroot:\n  sequence:\n    - force_success: %s\n%s    - switch: $found\n%s%s"
            % ("inputs: {%s}\n" % inputs if inputs else "", FIND, before, cases, after))


# 1. switch on a call's status: the succeeded case has its outputs ---------------------------------------------
def test_the_succeeded_case_of_a_switch_on_a_calls_status_reads_its_outputs(tmp_path):
    assert problems(tmp_path, routed("      cases: {succeeded: %s}\n" % APPROACH)) == []


def test_a_switch_run_only_through_its_succeeded_case_guarantees_the_outputs_after_it(tmp_path):
    tree = routed("      cases: {succeeded: %s}\n" % SAY, after="    - %s\n" % APPROACH)
    assert problems(tmp_path, tree) == []
    with_default = routed("      cases: {succeeded: %s}\n      default: %s\n" % (SAY, SAY), after="    - %s\n" % APPROACH)
    assert problems(tmp_path, with_default) == [NOT_SURE % (8, 52, 4)]


def test_match_contains_counts_a_case_only_succeeded_contains(tmp_path):
    assert problems(tmp_path, routed("      match: contains\n      cases: {succ: %s}\n" % APPROACH)) == []
    assert problems(tmp_path, routed("      match: contains\n      cases: {e: %s}\n" % APPROACH)) == [
        NOT_SURE % (7, 63, 4)]   # (e is in failed, rejected, …: the call may have failed)


@pytest.mark.parametrize("cases, at", [
    ("      cases: {failed: %s}\n" % APPROACH, (6, 68)),   # (failed: maybe an answered success: false, maybe not)
    ("      cases: {rejected: %s}\n" % APPROACH, (6, 70)),
    ("      cases: {timeout: %s}\n      default: %s\n" % (SAY, APPROACH), (7, 61)),
    ("      cases: {failed: %s, succeeded: %s}\n" % (SAY, APPROACH), None),
    ("      cases: {succeeded: %s, failed: %s}\n" % (SAY, APPROACH), (6, 121)),
], ids=["failed", "rejected", "default", "succeeded second", "failed second"])
def test_no_other_case_nor_the_default_has_the_outputs(tmp_path, cases, at):
    assert problems(tmp_path, routed(cases)) == ([NOT_SURE % (at + (4,))] if at else [])


def test_a_status_key_another_node_writes_gives_nothing(tmp_path):
    case = "      cases: {succeeded: %s}\n" % APPROACH
    assert problems(tmp_path, routed(case, before="    - set: {found: succeeded}\n")) == [NOT_SURE % (7, 71, 4)]
    assert problems(tmp_path, routed(case, after="    - set: {found: succeeded}\n")) == [NOT_SURE % (6, 71, 4)]
    assert problems(tmp_path, routed(case, inputs="found: {default: succeeded}")) == [NOT_SURE % (7, 71, 5)]
    other = "    - force_success: {call: vision.find_object, inputs: {object: mug}, status: found}\n"
    assert problems(tmp_path, routed(case, before=other)) == [NOT_SURE % (7, 71, 4)]
    also = other.replace("status:", "outputs: {position: cup_at}, status:")   # both write cup_at: either did
    assert problems(tmp_path, routed(case, before=also)) == []


def test_a_check_of_the_status_in_a_sequence_lets_the_nodes_after_it_read_the_outputs(tmp_path):
    tree = ("format: 1\nroot:\n  sequence:\n    - force_success: %s\n    - check: found == \"succeeded\"\n"
            "    - %s\n" % (FIND, APPROACH))
    assert problems(tmp_path, tree) == []
    assert problems(tmp_path, tree.replace('found == "succeeded"', "'\"succeeded\" == found'")) == []
    assert problems(tmp_path, tree.replace("succeeded", "failed")) == [NOT_SURE % (6, 52, 4)]
    assert problems(tmp_path, tree.replace('check: found == "succeeded"', 'check: found != "failed"')) == [
        NOT_SURE % (6, 52, 4)]


def test_a_switch_on_the_status_before_the_call_is_still_an_error(tmp_path):
    """Its case runs only after the call succeeded (in a loop's next run): the read of ``found`` is the error."""
    tree = ("format: 1\nroot:\n  sequence:\n    - switch: $found\n      cases: {succeeded: %s}\n"
            "    - force_success: %s\n" % (APPROACH, FIND))
    assert problems(tmp_path, tree) == [
        "t.yaml:4:15: reads 'found', which is not written on every path before this node (written at line 6, but "
        "not before it on every path: write it earlier on every path or declare it under 'inputs:')"]


# 2. a subtree reading its caller's keys ---------------------------------------------------------------------------
SUB = """format: 1
inputs:
  room: {default: kitchen}
root:
  sequence:
    - call: navigation.go_to
      inputs: {place: $room}
    - call: speech.say
      inputs: {text: $greeting}
"""
PARENT = """format: 1
root:
  sequence:
    - set: {greeting: hello}
    - include: sub.yaml
"""
READS = ("parent.yaml:5:7: warning: sub.yaml reads 'greeting' (line 9), which it neither declares in inputs: nor "
         "writes: it reads the caller's key; declare it under its inputs: and pass it in args: {greeting: $greeting}")


def test_a_subtree_reading_a_key_of_its_caller_is_a_warning_at_the_include(tmp_path, capsys):
    write(tmp_path, "sub.yaml", SUB)
    parent = write(tmp_path, "parent.yaml", PARENT)
    assert warned(tmp_path, "parent.yaml") == [READS]
    assert bmtree(["check", parent]) == 0
    assert bmtree(["check", "--strict", parent]) == 2
    said = capsys.readouterr()
    assert said.err.replace(str(tmp_path) + os.sep, "").splitlines() == [READS, READS]
    assert "parent.yaml: refused: 1 warning (--strict makes warnings errors)" in said.out


def test_a_subtree_declaring_the_key_and_given_it_is_not_warned(tmp_path):
    write(tmp_path, "sub.yaml", SUB.replace("  room: {default: kitchen}\n", "  room: {default: kitchen}\n  greeting: {}\n"))
    write(tmp_path, "parent.yaml", PARENT + "      args: {greeting: $greeting}\n")
    assert warned(tmp_path, "parent.yaml") == []


def test_a_subtree_writing_the_key_only_on_some_paths_says_where(tmp_path):
    write(tmp_path, "sub.yaml", SUB.replace("    - call: speech.say\n", "    - force_success: {sequence: [{check: "
                                            "'room == \"hall\"'}, {set: {greeting: hi}}]}\n    - call: speech.say\n"))
    write(tmp_path, "parent.yaml", PARENT)
    assert warned(tmp_path, "parent.yaml") == [
        "parent.yaml:5:7: warning: sub.yaml reads 'greeting' (line 10), which it neither declares in inputs: nor "
        "writes on every path before it (it writes it at line 8): it reads the caller's key; declare it under its "
        "inputs: and pass it in args: {greeting: $greeting}",
        "parent.yaml:5:7: warning: sub.yaml writes 'greeting' (sub.yaml:8), replacing the caller's 'greeting' "
        "(written at line 4): rename one of them"]


def test_a_read_the_caller_cannot_give_either_is_only_the_error(tmp_path):
    write(tmp_path, "sub.yaml", SUB)
    assert problems(tmp_path, PARENT.replace("    - set: {greeting: hello}\n", ""), "parent.yaml") == [
        "sub.yaml:9:22: reads 'greeting', which no node writes and no input declares (write it first, with a call's "
        "'outputs:' or a 'set', or declare it under 'inputs:')"]


def test_a_nested_subtrees_read_is_warned_once_at_its_own_include(tmp_path):
    write(tmp_path, "sub.yaml", SUB)
    write(tmp_path, "mid.yaml", "format: 1\nroot:\n  sequence:\n    - {call: speech.say, inputs: {text: $greeting}}\n"
                                "    - include: sub.yaml\n")
    write(tmp_path, "parent.yaml", PARENT.replace("sub.yaml", "mid.yaml"))
    assert warned(tmp_path, "parent.yaml") == [
        "mid.yaml:5:7: warning: sub.yaml reads 'greeting' (line 9), which it neither declares in inputs: nor writes: "
        "it reads the caller's key; declare it under its inputs: and pass it in args: {greeting: $greeting}",
        "parent.yaml:5:7: warning: mid.yaml reads 'greeting' (line 4), which it neither declares in inputs: nor "
        "writes: it reads the caller's key; declare it under its inputs: and pass it in args: {greeting: $greeting}"]


def test_a_subtree_in_the_cleanup_may_read_how_root_ended(tmp_path):
    write(tmp_path, "sub.yaml", "format: 1\nroot: {call: speech.say, inputs: {text: $ended}}\n")
    write(tmp_path, "t.yaml", "format: 1\nroot: {wait: 1}\ncleanup: {include: sub.yaml}\n")
    assert warned(tmp_path, "t.yaml") == []


# 3. include outputs: {k: k} replaces the caller's key on purpose --------------------------------------------------
LEARN = "format: 1\nroot: {call: speech.listen, inputs: {seconds: 5}, outputs: {text: guest_name}}\n"
CALLER = """format: 1
root:
  sequence:
    - set: {guest_name: nobody}
    - include: learn_guest.yaml
      outputs: {guest_name: %s}
    - {call: speech.say, inputs: {text: "Hello {guest_name}"}}
"""


def test_include_outputs_copying_a_key_to_the_same_caller_key_is_not_a_clash(tmp_path):
    write(tmp_path, "learn_guest.yaml", LEARN)
    write(tmp_path, "t.yaml", CALLER % "guest_name")
    assert warned(tmp_path, "t.yaml") == []
    write(tmp_path, "t.yaml", CALLER % "guest")
    assert warned(tmp_path, "t.yaml") == [
        "t.yaml:5:7: warning: learn_guest.yaml writes 'guest_name' (learn_guest.yaml:2), replacing the caller's "
        "'guest_name' (written at line 4): rename one of them"]


def test_the_language_references_example_checks(tmp_path):
    from tests.unit.test_lang_parallel_include import readme_example

    assert problems(tmp_path, readme_example("In the `succeeded` case the call's `outputs` may be read")) == []
