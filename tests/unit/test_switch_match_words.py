"""``switch`` with ``match: words``: a spoken answer matched by whole words ("no" is in "No, thanks." but
not in "I don't know", which ``match: contains`` takes for a no)."""
from __future__ import annotations

import os

import pytest

from coordinator.nodes.switch import matches
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA, one_file_trees
from tests.unit.test_port_hints import check_counted, switch_on

DEFS = load_definitions([SIM_DIR, os.path.join(DATA, "modules_lang")])


@pytest.mark.parametrize("value, case, expected", [
    ("No, thanks.", "no", True), ("I don't know", "no", False), ("NO!", "no", True),
    ("yes, please", "yes please", True), ("please yes", "yes please", False), ("yesterday", "yes", False),
    ("¿Sí?", "sí", True), ("", "no", False), (3, "3", False),
])
def test_words_match_whole_words_in_order(value, case, expected):
    assert matches(value, case, "words") is expected


@pytest.fixture
def tree(tmp_path, bmtree_tree):
    return one_file_trees(tmp_path, bmtree_tree, DEFS)


@pytest.mark.parametrize("heard, expected", [("I don't know", "pardon"), ("No, thank you", "no"),
                                             ("Yes please!", "yes")])
def test_a_spoken_answer_takes_the_case_of_its_words(tree, heard, expected):
    t = tree("""
  switch: $heard
  match: words
  cases:
    "no": {set: {took: "no"}}
    "yes": {set: {took: "yes"}}
  default: {set: {took: pardon}}
""", inputs="  heard: {default: %r}\n" % heard)
    run = t.run()
    assert run.succeeded and run.blackboard["took"] == expected, run.blackboard


def test_words_on_a_value_that_is_not_text_is_an_error(tmp_path, capsys):
    status, lines = check_counted(tmp_path, capsys, switch_on("count", '"3": {wait: 0}', "      match: words\n"))
    assert lines == ["t.yaml:10:14: match: words looks for the case's words in the value, but $count holds a "
                     "whole number (std_msgs/Int32): use match: equals"]
