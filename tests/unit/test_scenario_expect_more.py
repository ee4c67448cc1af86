"""Scenario files for tasks ported from SMACH: ``expect: duration``, ``expect: calls: {in_order: [...]}``
(with inputs: what the robot said), a top-level ``modules:`` key, and the kit's documented
signatures (README "Testing your trees without a robot")."""
from __future__ import annotations

import inspect
import io
import os
import re
import shutil

import pytest
import yaml

from coordinator.cli import main as bmtree
from coordinator.testing import TreeTest, fail, hang, reject
from coordinator.testing import scenario as scenarios
from coordinator.testing.scenario import load_scenario_file, run_scenario_file, run_scenarios
from coordinator.testing.scenariokeys import ScenarioDefinitions, modules_key
from coordinator.yamlsrc import load_file
from tests.conftest import DATA, ROOT, TREES
from tests.unit.test_scenarios import SCENARIOS

FIND_APPLE = os.path.join(TREES, "find_apple.yaml")
GRIPPER = os.path.join(DATA, "gripper")
DOC = os.path.join(ROOT, "docs", "scenarios.md")


def _shipped_mocks() -> dict:
    """The mocks of the shipped scenario file's first scenario (two failures, then the apple)."""
    with open(SCENARIOS, encoding="utf-8") as fh:
        return yaml.safe_load(fh)["scenarios"][0]["mocks"]


def _file(tmp_path, expect, mocks=None, name="s.yaml", **top):
    """A scenario file for find_apple with one scenario: these mocks (default: the shipped ones), this expect."""
    data = dict(tree=FIND_APPLE, **top)
    data["scenarios"] = [{"name": "x", "mocks": _shipped_mocks() if mocks is None else mocks, "expect": expect}]
    f = tmp_path / name
    f.write_text(yaml.safe_dump(data, sort_keys=False))
    return str(f)


def _run(path):
    out = io.StringIO()
    results = run_scenario_file(path, out=out)
    return results, out.getvalue()


def _errors(path, capsys, *args):
    assert bmtree(["test", *args, path]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return err.splitlines()


def _at(path, line, column, text):
    """``text`` is one of the errors, at ``line:column`` of ``path``."""
    return "%s:%d:%d: %s" % (path, line, column, text)


# 1. expect: duration ----------------------------------------------------------------------------------
DELAYED = {"navigation.go_to": {"succeed": {"room": "kitchen"}, "delay": 2.0},
           "vision.find_object": {"succeed": {"success": True, "position": {"x": 1.0, "y": 2.0, "z": 0.5}},
                                  "delay": 4}}   # 2 s, then 4 s: the run lasts 6 simulated seconds


@pytest.mark.parametrize("bounds, says", [
    ({"at_most": 30}, None),
    ({"at_least": 6, "at_most": 6}, None),   # bounds included
    ({"at_least": 0}, None),
    ({"at_most": 5}, "duration 6 s (simulated), expected at most 5 s"),
    ({"at_least": 10, "at_most": 60}, "duration 6 s (simulated), expected at least 10 s"),
])
def test_expect_duration_bounds_the_simulated_time_of_the_run(tmp_path, bounds, says):
    results, out = _run(_file(tmp_path, {"duration": bounds}, DELAYED))
    assert results == [says is None], out
    if says:
        assert "    %s\n" % says in out


def test_a_duration_failure_is_said_beside_the_other_problems(tmp_path):
    results, out = _run(_file(tmp_path, {"status": "failure", "duration": {"at_most": 1}}, DELAYED))
    assert results == [False]
    assert "    status SUCCESS, expected FAILURE\n" in out and "    duration 6 s (simulated), expected at most 1 s\n" in out


def test_duration_values_are_checked_where_they_are_written(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n" % FIND_APPLE
                 + "  - expect: {duration: 30}\n"                             # 3
                 + "  - expect: {duration: {at_mots: 3}}\n"                   # 4
                 + "  - expect: {duration: {at_least: -1, at_most: .nan}}\n"  # 5
                 + "  - expect: {duration: {at_least: 10, at_most: 5}}\n"     # 6
                 + "  - expect: {duration: {}}\n"                             # 7
                 + "  - expect: {zzz: 1}\n")                                  # 8
    assert _errors(str(f), capsys) == [
        _at(f, 3, 24, "duration is a mapping of at_least and/or at_most, in simulated seconds ({at_most: 30}), got 30"),
        _at(f, 4, 25, "unknown duration key 'at_mots' (did you mean 'at_most'?): duration takes at_least and/or "
                      "at_most (simulated seconds)"),
        _at(f, 5, 35, "duration at_least must be a number of seconds >= 0, got -1"),
        _at(f, 5, 48, "duration at_most must be a number of seconds >= 0, got nan"),
        _at(f, 6, 24, "duration at_least 10 is above at_most 5: no run can pass"),
        _at(f, 7, 24, "duration is a mapping of at_least and/or at_most, in simulated seconds ({at_most: 30}), got {}"),
        _at(f, 8, 14, "unknown expect key 'zzz' (expect keys: %s)" % ", ".join(scenarios._EXPECT_KEYS))]
    assert "duration" in scenarios._EXPECT_KEYS


# 2. and 3. expect: calls: {in_order: [...]}, with inputs -----------------------------------------------------
IN_ORDER = [{"speech.say": {"text": "I am going to look for the apple."}},
            {"navigation.go_to": {"place": "kitchen"}},
            "navigation.approach",
            {"speech.say": {"text": "I found the apple and I am next to it."}}]


def test_calls_in_order_pass_with_other_calls_between(tmp_path):
    results, out = _run(_file(tmp_path, {"calls": {"in_order": IN_ORDER}}))  # 4 of the run's 9 calls
    assert results == [True], out
    # the same four as an exact list: the run made five more
    results, out = _run(_file(tmp_path, {"calls": IN_ORDER}))
    assert results == [False] and "expected 4 calls, got 9" in out


def test_what_the_robot_said_is_a_call_with_its_text(tmp_path):
    said = {"calls": {"in_order": [{"speech.say": {"text": "I found the apple and I am next to it."}}]}}
    results, out = _run(_file(tmp_path, said))
    assert results == [True], out
    results, out = _run(_file(tmp_path, said, {"vision.find_object": {"succeed": {"success": False}}}))
    assert results == [False]
    assert ("    calls in order: expected call 1 of 1, speech.say {\"text\": \"I found the apple and I am next to it.\"}, "
            "not found from the start of the run\n") in out
    assert ("      call 1 (speech.say): input text is 'I am going to look for the apple.', expected 'I found the apple "
            "and I am next to it.'\n") in out
    assert "      call 10 (speech.say): input text is 'I am sorry, I could not find the apple.', expected " in out


def test_a_missing_call_is_said_with_the_made_call_it_was_looked_for_after(tmp_path):
    expect = {"calls": {"in_order": [IN_ORDER[0], {"navigation.go_to": {"place": "attic"}}, IN_ORDER[2],
                                     {"speech.say": {"text": "I found the pear."}}]}}
    results, out = _run(_file(tmp_path, expect))
    assert results == [False]
    lines = out.splitlines()[1:]
    assert lines[:6] == [
        '    calls in order: expected call 2 of 4, navigation.go_to {"place": "attic"}, not found after call 1, '
        'speech.say {"text": "I am going to look for the apple."} (which matched expected call 1)',
        "      call 2 (navigation.go_to): input place is 'living_room', expected 'attic'",
        "      call 3 (navigation.go_to): input place is 'living_room', expected 'attic'",
        "      call 4 (navigation.go_to): input place is 'living_room', expected 'attic'",
        "      and 1 more navigation.go_to call",
        # the next expected call is looked for after the same made call: it is found
        '    calls in order: expected call 4 of 4, speech.say {"text": "I found the pear."}, not found after call 8, '
        'navigation.approach {"target": {"x": 8.6, "y": 2.3, "z": 0.9}} (which matched expected call 3)']
    assert lines[6] == ("      call 9 (speech.say): input text is 'I found the apple and I am next to it.', "
                        "expected 'I found the pear.'")
    assert lines[8:13] == ['      = 1 speech.say {"text": "I am going to look for the apple."}',
                           '      - navigation.go_to {"place": "attic"}',
                           '        2 navigation.go_to {"place": "living_room"}',
                           '        3 navigation.go_to {"place": "living_room"}',
                           '        4 navigation.go_to {"place": "living_room"}']
    assert lines[-3:] == ['      = 8 navigation.approach {"target": {"x": 8.6, "y": 2.3, "z": 0.9}}',
                          '      - speech.say {"text": "I found the pear."}',
                          '        9 speech.say {"text": "I found the apple and I am next to it."}']


def test_calls_in_the_wrong_order_or_once_too_few_are_said_so(tmp_path):
    expect = {"calls": {"in_order": ["navigation.approach", IN_ORDER[0], "speech.say", "speech.say",
                                     "vision.find_object", "navigation.approach"]}}
    results, out = _run(_file(tmp_path, expect))
    assert results == [False]
    assert ("    calls in order: expected call 2 of 6, speech.say {\"text\": \"I am going to look for the apple.\"}, "
            "not found after call 8, navigation.approach {\"target\": {\"x\": 8.6, \"y\": 2.3, \"z\": 0.9}} (which "
            "matched expected call 1)\n"
            "      call 9 (speech.say): input text is 'I found the apple and I am next to it.', expected 'I am going to "
            "look for the apple.'\n"
            "      call 1 matches it, but it is not after call 8: the order differs\n") in out
    assert ("    calls in order: expected call 4 of 6, speech.say, not found after call 9, speech.say {\"text\": "
            "\"I found the apple and I am next to it.\"} (which matched expected call 3)\n"
            "      call 9 matches it, but it is expected call 3 already: each made call matches one expected call\n") in out
    assert "      call 7 matches it, but it is not after call 9: the order differs\n" in out
    results, out = _run(_file(tmp_path, {"calls": {"in_order": [IN_ORDER[3], {"navigation.go_to": {"place": "attic"}}]}}))
    assert results == [False]
    assert "\n      navigation.go_to was called only up to call 9: calls 2, 3, 4, 6\n" in out


def test_a_call_the_run_never_made(tmp_path):
    results, out = _run(_file(tmp_path, {"calls": {"in_order": ["vision.find_person"]}}))
    assert results == [False]
    assert out.splitlines()[1:4] == [
        "    calls in order: expected call 1 of 1, vision.find_person, not found from the start of the run",
        "      the run made no vision.find_person call",
        "    calls made (= matched an expected call; - an expected call not found after the call above; the others "
        "may come between):"]
    assert out.splitlines()[4] == "      - vision.find_person"


def test_the_in_order_form_is_checked_where_it_is_written(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text("tree: %s\nscenarios:\n" % FIND_APPLE
                 + "  - expect: {calls: {inorder: [speech.say]}}\n"                                       # 3
                 + "  - expect: {calls: {}}\n"                                                            # 4
                 + "  - expect: {calls: {in_order: []}}\n"                                                # 5
                 + "  - expect: {calls: {in_order: [speech.say, {speech.say: 3}, speech.sya,"             # 6
                 + " speech.say: {txt: hi}, speech.say: {text: [1]}]}}\n"
                 + "  - expect: {calls: speech.say}\n")                                                   # 7
    err = _errors(str(f), capsys)
    call = "module.function or {module.function: {input: value}}"
    assert err[:7] == [
        _at(f, 3, 22, "unknown calls key 'inorder' (did you mean 'in_order'?): calls is a list of calls, or "
                      "{in_order: [calls]}"),
        _at(f, 4, 21, "calls {} lists no call: write calls: {in_order: [calls]}, or calls: [] for a run that makes none"),
        _at(f, 5, 32, "calls in_order is a list of the calls made in this order (%s), at least one; got []" % call),
        _at(f, 6, 45, "calls in_order: call 2 is not %s, got {'speech.say': 3}" % call),
        _at(f, 6, 62, "expected call: module 'speech' has no function 'sya' (did you mean 'say'?)"),
        _at(f, 6, 87, "speech.say has no input 'txt' (did you mean 'text'?)"),
        _at(f, 6, 116, "speech.say input 'text' takes text (std_msgs/String), got [1]")]
    assert err[7] == _at(f, 7, 21, "calls is a list of %s (exactly the calls made), or {in_order: [such calls]} "
                                   "(these calls in this order, others may come between), got 'speech.say'" % call)
    assert len(err) == 8


# 4. modules: the file's own definitions ------------------------------------------------------------------
def _project(tmp_path, modules_line, defs="defs"):
    """trees/grasp.yaml (calls the user's gripper), defs/gripper.json and tests/s.yaml."""
    (tmp_path / "trees").mkdir()
    shutil.copy(os.path.join(GRIPPER, "grasp.yaml"), str(tmp_path / "trees"))
    (tmp_path / defs).mkdir(exist_ok=True)
    shutil.copy(os.path.join(GRIPPER, "gripper.json"), str(tmp_path / defs))
    (tmp_path / "tests").mkdir()
    f = tmp_path / "tests" / "s.yaml"
    f.write_text("tree: ../trees/grasp.yaml\n%sscenarios:\n  - name: grasp\n"
                 "    mocks: {gripper.close: {succeed: {holding: true}}}\n"
                 "    expect: {blackboard: {holding: true}}\n" % modules_line)
    return str(f)


@pytest.fixture
def no_module_path(monkeypatch):
    monkeypatch.delenv("BMTREE_MODULE_PATH", raising=False)
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)


@pytest.mark.parametrize("line", ["modules: ../defs\n", "modules: ../defs/gripper.json\n",
                                  "modules: [../defs/gripper.json]\n", "modules:\n  - ../defs\n"])
def test_a_scenario_file_names_its_own_definitions(tmp_path, capsys, no_module_path, line):
    path = _project(tmp_path, line)
    assert bmtree(["test", path]) == 0, capsys.readouterr()
    assert capsys.readouterr().out.rstrip().endswith("1 passed, 0 failed")
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    with open(path, "w", encoding="utf-8") as fh:   # without the key (nor --modules) the user's module is unknown
        fh.write(text.replace(line, ""))
    err = _errors(path, capsys)
    assert any("unknown module 'gripper'" in e for e in err), err


def test_modules_over_bmtree_module_path_as_modules_would(tmp_path, capsys, monkeypatch):
    """The file's definitions come after $BMTREE_MODULE_PATH's, as --modules does: a module of both is the file's."""
    path = _project(tmp_path, "modules: ../defs\n")
    with open(os.path.join(GRIPPER, "gripper.json"), encoding="utf-8") as fh:
        old = fh.read().replace('"close"', '"shut"')
    assert '"shut"' in old
    (tmp_path / "env").mkdir()
    (tmp_path / "env" / "gripper.json").write_text(old)
    monkeypatch.setenv("BMTREE_MODULE_PATH", str(tmp_path / "env"))
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    assert bmtree(["test", path]) == 0, capsys.readouterr()


def test_modules_on_the_command_line_win_and_the_files_are_only_checked(tmp_path, capsys, no_module_path):
    path = _project(tmp_path, "modules: ../wrong\n")
    with open(os.path.join(GRIPPER, "gripper.json"), encoding="utf-8") as fh:
        (tmp_path / "wrong").mkdir()
        (tmp_path / "wrong" / "gripper.json").write_text(fh.read().replace('"close"', '"shut"'))
    err = _errors(path, capsys)   # the file's own: its gripper has no close
    assert any("module 'gripper' has no function 'close'" in e for e in err), err
    assert bmtree(["test", "--modules", str(tmp_path / "defs"), path]) == 0  # --modules wins: ../wrong not loaded
    capsys.readouterr()
    shutil.rmtree(str(tmp_path / "wrong"))  # still checked: each path must exist
    assert _errors(path, capsys, "--modules", str(tmp_path / "defs")) == [
        _at(path, 2, 10, "modules %s: no such file or folder (relative paths are from the scenario file's folder)"
            % (tmp_path / "wrong"))]


@pytest.mark.parametrize("line, column, says", [
    ("modules: 5", 10, "modules is the path of a module definition file or folder, or a list of them (relative to "
                       "the scenario file's folder), got 5"),
    ("modules: {a: b}", 10, "modules is the path of a module definition file or folder, or a list of them "
                            "(relative to the scenario file's folder), got {'a': 'b'}"),
    ("modules: []", 10, "modules is the path of a module definition file or folder, or a list of them (relative "
                        "to the scenario file's folder); it is empty: leave the key out for the default definitions"),
    ("modules:", 9, "modules is the path of a module definition file or folder, or a list of them (relative "
                    "to the scenario file's folder); it is empty: leave the key out for the default definitions"),
    ("modules: [../defs, 5]", 20, "modules is the path of a module definition file or folder, or a list of them "
                                  "(relative to the scenario file's folder): got 5"),
    ("modules: ''", 11, "modules is the path of a module definition file or folder, or a list of them (relative "
                        "to the scenario file's folder): got ''"),
    ("modules: /dev/null", 10, "modules /dev/null: not a definition file or folder"),
    ("modules: ../nowhere", 10, "modules {tmp}/nowhere: no such file or folder (relative paths are from the "
                                "scenario file's folder)"),
    ("modules: ../trees", 10, "modules {tmp}/trees: no module definition (.json file) in this folder"),
    ("modules: ../trees/grasp.yaml", 10, "modules: {tmp}/trees/grasp.yaml:1:1: invalid JSON: Expecting value"),
    ("modules: [../defs, ../more]", 20, "modules: module 'gripper' is defined twice: in {tmp}/defs/gripper.json "
                                        "and {tmp}/more/gripper.json"),
])
def test_modules_that_make_no_sense_are_positioned_errors(tmp_path, capsys, no_module_path, line, column, says):
    path = _project(tmp_path, line + "\n")
    (tmp_path / "more").mkdir()
    shutil.copy(os.path.join(GRIPPER, "gripper.json"), str(tmp_path / "more"))
    # alone: the tree and the scenarios are not checked without their definitions ("unknown module 'gripper'")
    assert _errors(path, capsys) == [_at(path, 2, column, says.replace("{tmp}", str(tmp_path)))]


def test_a_modules_problem_comes_with_the_other_top_level_ones(tmp_path, capsys, no_module_path):
    path = _project(tmp_path, "modules: ../nowhere\nmodulse: x\nextra: 1\n")
    assert _errors(path, capsys) == [
        _at(path, 2, 10, "modules %s/nowhere: no such file or folder (relative paths are from the scenario file's "
                         "folder)" % tmp_path),
        _at(path, 3, 1, "unknown top-level key 'modulse' (did you mean 'modules'?)"),
        _at(path, 4, 1, "unknown top-level key 'extra' (top-level keys: tree, modules, scenarios)")]


def test_the_definitions_are_loaded_once_for_many_files(tmp_path, no_module_path):
    path = _project(tmp_path, "modules: ../defs\n")
    data = load_file(path)
    named = modules_key(data, path, None, lambda at, msg: pytest.fail(msg))
    source = ScenarioDefinitions()
    first = source.of(named, lambda at, msg: pytest.fail(msg))
    assert "gripper" in first and "navigation" in first and source.of(named, lambda at, msg: None) is first
    assert "gripper" not in source.of([], lambda at, msg: None)
    other = tmp_path / "tests" / "t.yaml"
    shutil.copy(path, str(other))
    assert run_scenarios([path, str(other)], out=io.StringIO()) == 0
    assert len(load_scenario_file(path)) == 1


# 5. the kit's signatures, as the README writes them -----------------------------------------------------
def _readme_section() -> str:
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        return fh.read().split("## Testing your trees without a robot", 1)[1].split("\n## ", 1)[0]


def test_the_readme_gives_the_real_signatures_of_fail_reject_and_run():
    section = _readme_section()
    for fn, written in ((fail, "fail(reason, delay=s)"), (reject, "reject(reason, delay=s)")):
        assert list(inspect.signature(fn).parameters) == ["reason", "delay"] and "`%s`" % written in section
    params = inspect.signature(TreeTest.run).parameters
    shown = ", ".join("%s=%r" % (k, p.default) for k, p in params.items() if k != "self")
    assert shown == ("max_duration=3600.0, default_timeout=30.0, observers=(), stop_when=None, max_ticks=100000, "
                     "max_ticks_per_instant=10000, kill_at=None")
    assert "`t.run(%s)`" % shown in section


def test_the_readmes_default_timeout_and_stop_when_examples_do_what_it_says():
    section = _readme_section()
    t = TreeTest(FIND_APPLE)
    t.mocks["speech.say"].script(hang())
    assert "`t.run(default_timeout=5)`" in section and "`speech.say: no answer within 5s`" in section
    run = t.run(default_timeout=5)
    assert run.failed and "speech.say: no answer within 5s" in run.reason
    example = re.search(r"`t\.run\((stop_when=lambda: [^`]*)\)`", section).group(1)
    t = TreeTest(FIND_APPLE)
    t.mocks["navigation.go_to"].script(fail("blocked", delay=2.0))
    run = eval("t.run(%s)" % example, {"t": t})  # noqa: S307  (the README's own words)
    assert run.failed and run.reason.startswith("blocked 3 times while '")
    assert run.duration < 30


def test_the_readme_and_the_help_name_the_new_keys(capsys):
    section = _readme_section()
    for words in ("modules: ../defs", "calls: {in_order: [...]}", "duration: {at_most: 30}", "--modules` wins"):
        assert words in section.replace("\n", " "), words
    assert bmtree(["test", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for key in scenarios._TOP_KEYS + scenarios._EXPECT_KEYS + ("in_order",):
        assert key in text, key
    assert "Given, it wins: a scenario file's own top-level 'modules:' is then not loaded" in text


# the format page: every key, and its examples run as written -------------------------------------------------
def _doc() -> str:
    with open(DOC, encoding="utf-8") as fh:
        return fh.read()


def test_the_format_page_has_a_row_for_every_new_key():
    doc = _doc()
    for key in scenarios._TOP_KEYS + scenarios._EXPECT_KEYS:
        assert "| `%s` |" % key in doc, key
    assert "**`--modules` wins.**" in doc


def test_the_format_pages_in_order_example_and_its_failure_are_what_bmtree_test_does(tmp_path):
    doc = _doc()
    block = next(b for b in re.findall(r"```yaml\n(.*?)```", doc, re.S) if b.lstrip().startswith("expect:"))
    expect = yaml.safe_load(block)["expect"]
    results, out = _run(_file(tmp_path, expect))
    assert results == [True], out
    # the FAIL it shows: the shipped file's scenario expecting navigation to the attic
    shown = re.search(r"```\n(FAIL .*?)```", doc, re.S).group(1)
    (tmp_path / "tests" / "scenarios").mkdir(parents=True)
    expect["calls"]["in_order"][1] = {"navigation.go_to": {"place": "attic"}}
    path = _file(tmp_path / "tests" / "scenarios", expect, name="find_apple.scenarios.yaml")
    with open(path, encoding="utf-8") as fh:
        data = yaml.safe_load(fh)
    data["scenarios"][0]["name"] = "says where it looks"
    with open(path, "w", encoding="utf-8") as fh:
        yaml.safe_dump(data, fh, sort_keys=False)
    results, out = _run(path)
    assert results == [False]
    out = re.sub(r", [0-9.]+ ms\)", ", T ms)", out.replace(str(tmp_path) + os.sep, ""))
    assert out == re.sub(r", [0-9.]+ ms\)", ", T ms)", shown)


def test_the_format_pages_modules_example_runs(tmp_path, no_module_path):
    block = next(b for b in re.findall(r"```yaml\n(.*?)```", _doc(), re.S) if b.startswith("tree: ../trees/grasp"))
    path = _project(tmp_path, "", defs="defs")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(block)
    results, out = _run(path)
    assert results == [True], out
