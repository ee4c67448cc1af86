"""A whole number too large for a float (``1`` and 400 zeros) where a tree or a scenario takes a
number: a ``file:line:column`` error and exit 2 (``math.isfinite`` and ``float()`` of it raise
OverflowError: a traceback before), one check for all of them (``coordinator.nodes.base.finite_number``)."""
from __future__ import annotations

import math
import re

import pytest

from coordinator.bounds import finite_number, shown
from coordinator.cli import main as bmtree
from coordinator.errors import TreeErrors
from coordinator.nodes.base import run_param
from coordinator.refs import parse_ref
from coordinator.testing.mocknode import load_script
from coordinator.testing.mocks import MockError, Mocks, outcome_from_dict

HUGE = 10 ** 400
SAID = "a whole number of 401 digits (numbers go up to 1.8e308)"


@pytest.mark.parametrize("value,finite", [
    (1, True), (0, True), (-2.5, True), (10 ** 308, True), (-(10 ** 308), True), (1.7e308, True),
    (HUGE, False), (-HUGE, False), (2 ** 1024, False), (math.inf, False), (-math.inf, False), (math.nan, False),
    (True, False), ("1", False), (None, False),
])
def test_finite_number_says_without_overflowing(value, finite):
    assert finite_number(value) is finite


def test_shown_says_a_huge_whole_number_by_its_size():
    assert shown(HUGE) == SAID
    assert shown(-HUGE) == "a negative " + SAID[2:]
    assert shown(2.5) == "2.5" and shown("x") == "'x'"


TREE = "format: 1\nname: t\nroot:\n  sequence:\n    children:\n%s"


@pytest.mark.parametrize("node,where,message", [
    ("      - wait: %d\n", "6:15", "duration of wait must be a number of seconds >= 0, got " + SAID),
    ("      - call: speech.say\n        inputs: {text: hi}\n        timeout: %d\n", "8:18",
     "timeout of call must be a positive number of seconds, got " + SAID),
    ("      - wait_event: vision.lostPerson\n        timeout: %d\n", "7:18",
     "timeout of wait_event must be a positive number of seconds, got " + SAID),
    ("      - recall: {p: person}\n        timeout: %d\n", "7:18",
     "timeout of recall must be a positive number of seconds, got " + SAID),
    ("      - timeout: %d\n        child: {wait: 1}\n", "6:18", "must be a positive number of seconds, got " + SAID),
    ("      - retry: 2\n        delay: %d\n        child: {wait: 1}\n", "7:16",
     "delay of retry must be a number of seconds >= 0, got " + SAID),
], ids=["wait", "call-timeout", "wait_event-timeout", "recall-timeout", "timeout", "retry-delay"])
def test_a_huge_number_in_a_tree_is_a_positioned_error_exit_2(tmp_path, capsys, node, where, message):
    path = tmp_path / "t.yaml"
    path.write_text(TREE % (node % HUGE))
    assert bmtree(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert re.search(r"^%s:%s: .*%s" % (re.escape(str(path)), where, re.escape(message)), err, re.M), err


def test_a_huge_cleanup_timeout_is_a_positioned_error(tmp_path, capsys):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nname: t\nroot:\n  wait: 1\ncleanup_timeout: -%d\ncleanup:\n  wait: 1\n" % HUGE)
    assert bmtree(["check", str(path)]) == 2
    assert capsys.readouterr().err == (
        "%s:5:18: cleanup_timeout must be a positive number of seconds (the cleanup's time limit, default 30), "
        "got a negative whole number of 401 digits (numbers go up to 1.8e308)\n" % path)


def test_a_huge_number_a_node_reads_when_it_starts_fails_it_with_why():
    value, why = run_param(parse_ref("$d"), lambda k: HUGE, "seconds0", "duration of wait")
    assert value is None and why == "duration of wait $d is %s, not a number of seconds >= 0" % SAID


SCENARIO = "tree: t.yaml\nscenarios:\n  - name: s\n    mocks:\n      speech.say: %s\n%s"


@pytest.mark.parametrize("mock,extra,where,message", [
    ("{succeed: {}}", "    max_duration: %d\n", "6:19", "max_duration must be a number of seconds >= 0"),
    ("{succeed: {}}", "    killed_at: %d\n", "6:16", "killed_at must be a number of seconds >= 0"),
    ("{succeed: {}}", "    events:\n      - {at: %d, event: vision.lostPerson, params: {person: Ana}}\n", "7:14",
     "at must be a number of seconds >= 0"),
    ("{succeed: {}}", "    expect: {status: success, duration: {at_least: %d}}\n", "6:52",
     "duration at_least must be a number of seconds >= 0"),
    ("{succeed: {}}", "    expect: {status: success, duration: {at_most: %d}}\n", "6:51",
     "duration at_most must be a number of seconds >= 0"),
    ("{succeed: {}, delay: %d}", "", "5:19", "delay must be a number of seconds from 0 to 86400 (a day), got a whole "
                                             "number of 401 digits"),
], ids=["max_duration", "killed_at", "event-at", "at_least", "at_most", "mock-delay"])
def test_a_huge_number_in_a_scenario_is_a_positioned_error_exit_2(tmp_path, capsys, mock, extra, where, message):
    (tmp_path / "t.yaml").write_text("format: 1\nname: t\nroot:\n  call: speech.say\n  inputs: {text: hi}\n")
    path = tmp_path / "s.yaml"
    text = SCENARIO % (mock, extra)
    path.write_text(text.replace("%d", str(HUGE)))
    assert bmtree(["test", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    said = message if ", got " in message else "%s, got %s" % (message, SAID)
    assert "%s:%s: %s\n" % (path, where, said) in err, err


def test_a_mock_nodes_script_and_the_kits_mocks_refuse_a_huge_time(tmp_path, sim_defs):
    script = tmp_path / "m.yaml"
    script.write_text("module: vision\nevents:\n  - {at: %d, event: lostPerson, params: {person: Ana}}\n" % HUGE)
    with pytest.raises(TreeErrors) as info:
        load_script(str(script), sim_defs)
    assert str(info.value) == "%s:3:10: at must be a number of seconds >= 0, got %s" % (script, SAID)
    mocks = Mocks(sim_defs)
    with pytest.raises(MockError, match="at must be a finite number of seconds, got a whole number of 401 digits"):
        mocks.event(HUGE, "vision.lostPerson", person="Ana")
    with pytest.raises(MockError, match="delay must be a number of seconds from 0 to 86400 \\(a day\\), got a whole number of 401 digits"):
        outcome_from_dict({"succeed": {}, "delay": HUGE})


def test_a_whole_number_too_long_for_str_is_said_by_its_size_everywhere():
    """Python 3.11's ``str`` refuses a whole number of more than 4,300 digits (ValueError): an outcome's
    delay of 5,000 digits raised it while its error was being written."""
    from comm.typewords import whole_number_text

    huge = 10 ** 5000
    with pytest.raises(MockError, match="got a whole number of thousands of digits$"):
        outcome_from_dict({"succeed": {}, "delay": huge})
    assert shown(-huge) == "a negative whole number of thousands of digits (numbers go up to 1.8e308)"
    assert whole_number_text(-10 ** 400) == "a negative whole number of 401 digits"
