"""An expression that compares a call's ``status`` key with text no status is (``st == "timed_out"``) is an
error of the check, as a ``switch`` case of that text is, with the same words and did-you-mean."""
from __future__ import annotations

from coordinator.language import load_tree
from tests.unit.test_call_status import DEFS, GRASP, errors_of

CALL = """  sequence:
    - force_success:
        call: arm.grasp
        inputs: {object: cup}
        status: st
"""
STATUSES = "one of 'succeeded', 'failed', 'rejected', 'cancelled', 'timeout', 'module_lost', 'not_sent'"
SAID = "$st is the status of the call to arm.grasp at line 5"


def test_comparing_a_status_with_no_status_is_an_error_with_did_you_mean(tmp_path):
    root = CALL + """    - check: 'st == "timed_out"'
    - check: '"timed_out" != $st'
    - check: '"tim_" in st or st == "timeout"'
    - check: 'st == "halted" and true'
    - set: {said: "$(st == 'failed ')"}
    - call: speech.say
      inputs: {text: "{not (st == 'succeded')}"}
"""
    assert errors_of(tmp_path, root) == [
        'bad.yaml:8:18: st == "timed_out" is always false: %s, %s (did you mean \'timeout\'?)' % (SAID, STATUSES),
        'bad.yaml:9:27: "timed_out" != st is always true: %s, %s (did you mean \'timeout\'?)' % (SAID, STATUSES),
        'bad.yaml:10:22: "tim_" in st is always false: %s, %s' % (SAID, STATUSES),
        'bad.yaml:11:18: st == "halted" is always false: %s, written when the call has ended, never when it is '
        'halted (its parent moved on, and a halted call writes no status)' % SAID,
        'bad.yaml:12:25: st == "failed " is always false: %s, %s (did you mean \'failed\'?)' % (SAID, STATUSES),
        'bad.yaml:14:32: input \'text\': st == "succeded" is always false: %s, %s (did you mean \'succeeded\'?)'
        % (SAID, STATUSES)]


def test_comparisons_a_status_can_pass_are_left_alone(tmp_path):
    path = tmp_path / "ok.yaml"
    ok = CALL + """    - check: 'st == "timeout" or st != "failed" or "time" in st or "TIME" in st or st in "timeout failed"'
    - check: 'st == "succeeded"'
"""
    path.write_text("format: 1\nroot:\n" + ok)
    load_tree(str(path), DEFS)
    # a key something else writes too (a set), or a tree input, may hold anything
    path.write_text("format: 1\nroot:\n" + CALL + "    - set: {st: timed_out}\n    - check: 'st == \"timed_out\"'\n")
    load_tree(str(path), DEFS)
    path.write_text("format: 1\ninputs: {st: {default: timed_out}}\nroot:\n" + CALL + "    - check: 'st == \"timed_out\"'\n")
    load_tree(str(path), DEFS)
    # the error key holds any text, as does an output of text
    path.write_text("format: 1\nroot:\n" + GRASP
                    + "    - check: 'why == \"timed_out\" or grasp == \"timeout\"'\n"
                    + "    - {call: speech.listen, inputs: {seconds: 5}, outputs: {text: heard}}\n    - check: 'heard == \"timed_out\"'\n")
    load_tree(str(path), DEFS)


def test_a_switch_and_a_check_say_the_same(tmp_path):
    switch = errors_of(tmp_path, CALL + "    - switch: $st\n      cases:\n        timed_out: {set: {x: 1}}\n")
    check = errors_of(tmp_path, CALL + "    - check: 'st == \"timed_out\"'\n")
    assert switch[0].split(" never matches: ")[1] == check[0].split(" is always false: ")[1]
