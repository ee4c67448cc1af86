"""Every problem at once, also inside what cannot be built: the nodes under a kind of another tool
(``Fallback``, ``RetryUntilSuccessful``) and the items of a list given as a decorator's one child are
checked as nodes. Before, only the outer error came, and each renaming showed the next ones."""
from __future__ import annotations

from tests.unit.test_check_messages import check

PORTED = """format: 1
root:
  Fallback:
    - RetryUntilSuccessful:
        num_attempts: 3
        child:
          call: navigation.turn
    - call: speech.say
      input: {text: hi}
    - sequence:
        - call: speech.say
"""


def test_the_nodes_inside_kinds_of_other_tools_are_checked(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, PORTED)
    assert status == 2
    assert lines == [
        "t.yaml:3:3: unknown node kind 'Fallback' (BehaviorTree.CPP's Fallback is bmtree's selector)",
        "t.yaml:4:7: unknown node kind 'RetryUntilSuccessful' (BehaviorTree.CPP's RetryUntilSuccessful is bmtree's "
        "retry: N (attempts in all), with child: beside it)",
        "t.yaml:7:17: module 'navigation' has no function 'turn' (functions: go_to, approach, where_am_i)",
        "t.yaml:8:13: speech.say needs input 'text' (std_msgs/String)",
        "t.yaml:9:7: unknown option 'input' for call (did you mean 'inputs'?)",
        "t.yaml:11:17: speech.say needs input 'text' (std_msgs/String)",
    ]


def test_children_beside_an_unknown_kind_and_a_bare_value_inside_one(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  Timeout: 5\n  children:\n    - call: vision.look\n")
    assert status == 2
    assert lines[0].startswith("t.yaml:3:3: unknown node kind 'Timeout'")
    assert lines[1:] == ["t.yaml:5:13: module 'vision' has no function 'look' (functions: find_object, find_person)"]


def test_the_items_of_a_list_given_as_one_child_are_checked(tmp_path, capsys):
    status, lines = check(tmp_path, capsys, "format: 1\nroot:\n  retry: 3\n  child:\n    - call: navigation.turn\n"
                                            "    - call: speech.say\n")
    assert status == 2
    assert lines == [
        "t.yaml:5:5: a decorator (retry) has one child, not a list: wrap several nodes in a sequence, "
        "child: {sequence: [...]}",
        "t.yaml:5:13: module 'navigation' has no function 'turn' (functions: go_to, approach, where_am_i)",
        "t.yaml:6:13: speech.say needs input 'text' (std_msgs/String)",
    ]
