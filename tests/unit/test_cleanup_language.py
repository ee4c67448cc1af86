"""A tree's ``cleanup:`` in the language: parsing, the checks, data flow, the schema (no ROS master)."""
from __future__ import annotations

import json

import pytest

from coordinator.cli import main as bmtree
from coordinator.errors import TreeErrors
from coordinator.language import load_tree
from coordinator.schema import json_schema
from coordinator.treeast import top_of, used_modules, walk

HEAD = "format: 1\nname: t\n"
ROOT = "root:\n  call: navigation.go_to\n  inputs: {place: kitchen}\n  outputs: {position: pos}\n"


def _write(tmp_path, text, name="t.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _errors(path, sim_defs):
    with pytest.raises(TreeErrors) as exc:
        load_tree(path, sim_defs)
    return [str(e) for e in exc.value.errors]


def test_cleanup_is_a_node_under_the_top_with_root(tmp_path, sim_defs):
    path = _write(tmp_path, HEAD + ROOT + "cleanup:\n  sequence:\n    - call: speech.say\n"
                  "      inputs: {text: 'ended {ended}: {ended_reason}'}\n    - call: vision.find_person\n"
                  "      inputs: {name: ''}\ncleanup_timeout: 7.5\n")
    tree = load_tree(path, sim_defs)
    assert tree.cleanup is not None and tree.cleanup.name == "cleanup" and tree.cleanup_timeout == 7.5
    top = top_of(tree)
    assert top.kind == "with_cleanup" and top.children == [tree.root, tree.cleanup]
    assert (top.pos.line, top.pos.column) == (7, 1)   # the cleanup: key, not a node of the file
    assert used_modules(tree) == ({"navigation", "speech", "vision"}, False)
    assert [n.kind for n in walk(top)] == ["with_cleanup", "call", "sequence", "call", "call"]


def test_without_cleanup_the_top_is_the_root(tmp_path, sim_defs):
    tree = load_tree(_write(tmp_path, HEAD + ROOT), sim_defs)
    assert tree.cleanup is None and tree.top is None and top_of(tree) is tree.root


def test_a_named_cleanup_keeps_its_name_and_a_leaf_its_own(tmp_path, sim_defs):
    named = load_tree(_write(tmp_path, HEAD + ROOT + "cleanup:\n  name: stop all\n  sequence:\n"
                             "    - call: speech.say\n      inputs: {text: bye}\n"), sim_defs)
    assert named.cleanup.name == "stop all"
    leaf = load_tree(_write(tmp_path, HEAD + ROOT + "cleanup: {call: speech.say, inputs: {text: bye}}\n",
                            "leaf.yaml"), sim_defs)
    assert leaf.cleanup.name == "speech.say"


def test_the_cleanup_gets_the_checks_root_gets(tmp_path, sim_defs):
    path = _write(tmp_path, HEAD + ROOT + "cleanup:\n  sequence:\n    - call: speech.sya\n"
                  "    - call: navigation.approach\n      inputs: {target: hello}\n    - sequnce: []\n")
    errors = _errors(path, sim_defs)
    assert any(e.startswith(path + ":9:13: module 'speech' has no function 'sya'") for e in errors), errors
    assert any(e.startswith(path + ":11:24: ") and "target" in e for e in errors), errors
    assert any(e.startswith(path + ":12:7: unknown node kind 'sequnce'") for e in errors), errors


def test_root_keys_are_only_maybe_written_in_the_cleanup(tmp_path, sim_defs):
    path = _write(tmp_path, HEAD + ROOT + "cleanup:\n  call: navigation.approach\n  inputs: {target: $pos}\n")
    assert _errors(path, sim_defs) == [
        path + ":9:20: reads 'pos', which the cleanup cannot count on: it runs however root ended, also when root "
               "was stopped before writing it (written at line 4, but not before it on every path: write it in "
               "the cleanup first, or declare it under 'inputs:' with a default)"]


def test_inputs_and_the_cleanups_own_keys_are_readable_there(tmp_path, sim_defs):
    path = _write(tmp_path, HEAD + "inputs:\n  room: {default: hall}\n" + ROOT + "cleanup:\n  sequence:\n"
                  "    - call: navigation.go_to\n      inputs: {place: $room}\n      outputs: {position: here}\n"
                  "    - call: navigation.approach\n      inputs: {target: $here}\n"
                  "    - switch: $ended\n      cases:\n        stopped: {call: speech.say, inputs: {text: $ended_reason}}\n"
                  "      default: {call: speech.say, inputs: {text: '{ended}'}}\n")
    assert load_tree(path, sim_defs).cleanup is not None


def test_ended_is_known_only_inside_the_cleanup(tmp_path, sim_defs):
    path = _write(tmp_path, HEAD + "root:\n  call: speech.say\n  inputs: {text: $ended}\n"
                  "cleanup: {call: speech.say, inputs: {text: $ended_reason}}\n")
    assert _errors(path, sim_defs) == [
        path + ":5:18: reads 'ended', which bmtree sets only for the tree's cleanup: (how root ended): a node outside "
               "the cleanup cannot read it"]


def test_ended_is_text_for_the_type_checks(tmp_path, sim_defs):
    path = _write(tmp_path, HEAD + ROOT + "cleanup:\n  call: navigation.approach\n  inputs: {target: $ended}\n")
    errors = _errors(path, sim_defs)
    assert len(errors) == 1 and "input 'target' takes a mapping of fields x, y, z" in errors[0] and "text" in errors[0]


def test_writing_or_declaring_the_cleanup_keys_is_an_error_with_a_cleanup(tmp_path, sim_defs):
    path = _write(tmp_path, HEAD + "inputs:\n  ended_reason: {default: ''}\n"
                  "root:\n  call: speech.say\n  inputs: {text: hi}\n  status: ended\n"
                  "cleanup:\n  set: {ended: done}\n")
    assert _errors(path, sim_defs) == [
        path + ":4:3: declares the input 'ended_reason', a key bmtree sets for the tree's cleanup (why root ended, "
               "as the run's reason says it), read-only: use another key",
        path + ":6:3: writes 'ended', a key bmtree sets for the tree's cleanup (how root ended: one of succeeded, "
               "failed, stopped), read-only: use another key",
        path + ":10:3: writes 'ended', a key bmtree sets for the tree's cleanup (how root ended: one of succeeded, "
               "failed, stopped), read-only: use another key"]


def test_writing_the_cleanup_keys_without_a_cleanup_is_a_warning(tmp_path, sim_defs):
    path = _write(tmp_path, HEAD + "root:\n  call: speech.say\n  inputs: {text: hi}\n  status: ended\n")
    tree = load_tree(path, sim_defs)
    assert [str(w) for w in tree.warnings] == [
        path + ":4:3: warning: writes 'ended', a key bmtree sets for a tree's cleanup (how root ended: one of "
               "succeeded, failed, stopped): in a tree with cleanup: this is an error; use another key"]


@pytest.mark.parametrize("key", ["clean_up", "finally", "on_stop", "on_halt", "on_preempt", "CleanUp"])
def test_other_names_of_cleanup_point_to_it(tmp_path, sim_defs, key):
    path = _write(tmp_path, HEAD + ROOT + "%s:\n  call: speech.say\n  inputs: {text: bye}\n" % key)
    errors = _errors(path, sim_defs)
    assert errors == [path + ":7:1: unknown top-level key %r (did you mean 'cleanup'? cleanup: holds the node run "
                             "once after root ends, however it ended: succeeded, failed or stopped)" % key]


@pytest.mark.parametrize("value", ["0", "-1", "abc", "true", ".inf", "none"])
def test_cleanup_timeout_must_be_positive_seconds(tmp_path, sim_defs, value):
    path = _write(tmp_path, HEAD + ROOT + "cleanup: {call: speech.say, inputs: {text: bye}}\n"
                  "cleanup_timeout: %s\n" % value)
    errors = _errors(path, sim_defs)
    assert len(errors) == 1 and errors[0].startswith(path + ":8:18: cleanup_timeout must be a positive number of "
                                                            "seconds (the cleanup's time limit, default 30), got ")


def test_a_cleanup_timeout_in_milliseconds_by_habit_is_a_warning(tmp_path, sim_defs):
    """As ``timeout: 3000`` is (the same warning): 3000 seconds is 50 minutes."""
    cleanup = "cleanup: {call: speech.say, inputs: {text: bye}}\n"
    tree = load_tree(_write(tmp_path, HEAD + ROOT + cleanup + "cleanup_timeout: 3000\n"), sim_defs)
    assert [str(w) for w in tree.warnings] == [
        tree.path + ":8:18: warning: cleanup_timeout is 3000 seconds (50 min): durations are in seconds; for 3000 "
        "milliseconds write 3"]
    assert tree.cleanup_timeout == 3000.0   # still what was written
    for seconds in ("10", "3600"):   # seconds, or whole half hours: no warning
        tree = load_tree(_write(tmp_path, HEAD + ROOT + cleanup + "cleanup_timeout: %s\n" % seconds), sim_defs)
        assert tree.warnings == []


def test_cleanup_timeout_without_cleanup_is_a_warning(tmp_path, sim_defs):
    tree = load_tree(_write(tmp_path, HEAD + ROOT + "cleanup_timeout: 5\n"), sim_defs)
    assert [str(w).split(": ", 1)[1] for w in tree.warnings] == [
        "warning: cleanup_timeout without cleanup: there is no cleanup to limit"]


def test_an_included_files_cleanup_is_a_warning_at_the_include(tmp_path, sim_defs):
    _write(tmp_path, HEAD + "root: {call: speech.say, inputs: {text: hi}}\ncleanup:\n"
           "  call: speech.say\n  inputs: {text: bye}\n", "sub.yaml")
    path = _write(tmp_path, HEAD + "root:\n  include: sub.yaml\n")
    tree = load_tree(path, sim_defs)
    assert [str(w) for w in tree.warnings] == [
        path + ":4:12: warning: sub.yaml has a cleanup: (line 5), which does not run when the file is included: "
               "only the cleanup of the tree that is run runs (move it there, or run sub.yaml by itself)"]
    assert tree.cleanup is None and [n.kind for n in walk(top_of(tree))] == ["include", "call"]


def test_bmtree_check_exits_2_with_file_line_column(tmp_path, capsys):
    path = _write(tmp_path, HEAD + ROOT + "on_halt: {call: speech.say, inputs: {text: bye}}\n")
    assert bmtree(["check", path]) == 2
    assert "%s:7:1: unknown top-level key 'on_halt' (did you mean 'cleanup'?" % path in capsys.readouterr().err


def test_the_schema_knows_cleanup(capsys):
    schema = json_schema()
    props = schema["properties"]
    assert props["cleanup"]["$ref"] == "#/definitions/node" and "ended" in props["cleanup"]["description"]
    assert props["cleanup_timeout"] == {"type": "number", "exclusiveMinimum": 0,
                                        "description": "seconds the cleanup may run (default 30)"}
    assert "with_cleanup" not in json.dumps(schema)   # made by the parser, never written
    assert bmtree(["schema"]) == 0 and '"cleanup_timeout"' in capsys.readouterr().out
