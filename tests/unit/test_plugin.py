"""The pytest plugin, tested as users meet it (pytester runs a throwaway project)."""
from __future__ import annotations

import os

import pytest

from tests.conftest import TREES

pytest_plugins = ["pytester"]

USER_TEST = '''
from coordinator.testing import fail, succeed

TREE = %r

def test_apple_in_kitchen(bmtree_tree):
    t = bmtree_tree(TREE)
    t.mocks["vision.find_object"].script(succeed(success=False), succeed(success=True, position={"x": 1.0}))
    run = t.run()
    assert run.succeeded
    assert run.calls("navigation.go_to")[0].inputs["place"] == "living_room"
    assert run.calls("navigation.go_to")[1].inputs["place"] == "kitchen"

def test_wrong_expectation_fails(bmtree_tree):
    t = bmtree_tree(TREE)
    run = t.run()
    assert run.calls("navigation.go_to")[0].inputs["place"] == "bedroom"

def test_bad_script_is_refused(bmtree_tree):
    t = bmtree_tree(TREE)
    t.mocks["navigation.go_to"].succeed(success="very")
'''


def test_plugin_fixtures_and_assertions(pytester):
    pytester.makepyfile(test_user=USER_TEST % os.path.join(TREES, "find_apple.yaml"))
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(passed=1, failed=2)
    result.stdout.fnmatch_lines(["*AssertionError*", "*MockError: scripted outputs of navigation.go_to break "
                                 "its definition*"])


def test_plugin_coverage_report(pytester):
    pytester.makepyfile(test_user=USER_TEST % os.path.join(TREES, "find_apple.yaml"))
    result = pytester.runpytest("-p", "no:cacheprovider", "--bmtree-coverage", "-k", "kitchen")
    result.assert_outcomes(passed=1)
    result.stdout.fnmatch_lines([
        "*bmtree tree coverage*",
        "*find_apple.yaml: * of * nodes ran",
        "*find_apple.yaml:*: call 'say I could not find it' never ran",
        "*search_room.yaml:*: call 'look for the object' reached SUCCESS, FAILURE",
    ])


def test_plugin_is_registered_by_entry_point(pytester):
    result = pytester.runpytest("--help")
    result.stdout.fnmatch_lines(["*--bmtree-coverage*"])


def test_the_readme_example_runs(pytester):
    from tests.conftest import ROOT

    with open(os.path.join(ROOT, "README.md")) as fh:
        readme = fh.read()
    section = readme.split("## Testing your trees without a robot", 1)[1]
    code = section.split("```python", 1)[1].split("```", 1)[0]
    code = code.replace('"trees/find_apple.yaml"', repr(os.path.join(TREES, "find_apple.yaml")))
    pytester.makepyfile(test_readme=code)
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(passed=1)


OWN_MODULE_TEST = '''
from coordinator.testing import succeed

def test_by_keyword(bmtree_tree):
    t = bmtree_tree(%(tree)r, modules=[%(gripper)r])
    t.mocks["gripper.close"].script(succeed(success=True, holding=True))
    assert t.run().blackboard["holding"] is True

def test_by_ini(bmtree_tree):
    t = bmtree_tree(%(tree)r)
    assert t.run().succeeded
'''


def test_your_own_modules_by_keyword_or_by_the_ini_key(pytester):
    from tests.conftest import DATA

    gripper = os.path.join(DATA, "gripper")
    pytester.makepyfile(test_user=OWN_MODULE_TEST % {"tree": os.path.join(gripper, "grasp.yaml"),
                                                     "gripper": os.path.join(gripper, "gripper.json")})
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(passed=1, failed=1)  # without the ini key, the tree's gripper is unknown
    result.stdout.fnmatch_lines(["*test_by_ini*", "*unknown module 'gripper'*"])
    pytester.makeini("[pytest]\nbmtree_modules = %s\n" % os.path.relpath(gripper, str(pytester.path)))
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(passed=2)
    # as the README writes it: an end-of-line comment is no list of files
    pytester.makeini("[pytest]\nbmtree_modules = %s   # files or folders, relative to this file\n"
                     "    # one per line\n" % os.path.relpath(gripper, str(pytester.path)))
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(passed=2)


BAD_TREE_TEST = '''
def test_bad_tree(bmtree_tree):
    t = bmtree_tree(%r)

def test_bad_script(bmtree_tree):
    t = bmtree_tree(%r)
    t.mocks["navigation.go_to"].fail_first(1, room=3)
'''


def test_a_tree_error_shows_at_the_users_line_without_the_kits_frames(pytester, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: 1\nroot:\n  call: navigation.goto\n")
    pytester.makepyfile(test_user=BAD_TREE_TEST % (str(bad), os.path.join(TREES, "find_apple.yaml")))
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(failed=2)
    out = result.stdout.str()
    assert "%s:3:9: " % bad in out and "did you mean 'go_to'" in out
    assert "MockError: scripted outputs of navigation.go_to break its definition" in out
    for internal in ("language.py", "kit.py", "plugin.py", "mocks.py", "definition.py", "raise exc.with_traceback"):
        assert internal not in out, internal


def test_a_missing_tree_input_fails_where_the_test_is_made_saying_how(pytester):
    pytester.makepyfile(test_user="def test_inputs_missing(bmtree_tree):\n    t = bmtree_tree(%r)\n"
                                  % os.path.join(TREES, "search_room.yaml"))
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*UsageError: *search_room.yaml: tree input 'room' must be given: "
                                 "bmtree_tree(path, inputs={'room': ...})*"])
    assert "kit.py" not in result.stdout.str()


PATHS_TEST = '''
def test_from_the_ini_folder(bmtree_tree):
    assert bmtree_tree("trees/go.yaml").run().succeeded

def test_beside_the_test(bmtree_tree):
    assert bmtree_tree("beside.yaml").run().succeeded

def test_nowhere(bmtree_tree):
    bmtree_tree("trees/nowhere.yaml")
'''


def test_a_tree_path_is_found_wherever_pytest_is_started(pytester, monkeypatch):
    """From the working directory, else the ini file's folder (as bmtree_modules), else the test's: started
    in another folder, the test found no tree (cannot read trees/go.yaml: No such file or directory)."""
    tree = "format: 1\nroot:\n  call: speech.say\n  inputs: {text: hi}\n"
    pytester.makeini("[pytest]\n")
    (pytester.path / "trees").mkdir()
    (pytester.path / "trees" / "go.yaml").write_text(tree)
    tests = pytester.path / "tests"
    tests.mkdir()
    (tests / "beside.yaml").write_text(tree)
    (tests / "test_paths.py").write_text(PATHS_TEST)
    elsewhere = pytester.path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    result = pytester.runpytest("-p", "no:cacheprovider", str(tests))
    result.assert_outcomes(passed=2, failed=1)
    out = " ".join(result.stdout.str().split())
    assert ("UsageError: bmtree_tree('trees/nowhere.yaml'): no such file; tried %s, %s, %s" % (
        elsewhere / "trees/nowhere.yaml", pytester.path / "trees/nowhere.yaml", tests / "trees/nowhere.yaml")) in out, out


UNSCRIPTED_TEST = '''
TREE = %r

def test_unscripted(bmtree_tree):
    run = bmtree_tree(TREE).run()
    assert run.succeeded
'''


@pytest.mark.filterwarnings("default::coordinator.testing.kit.UnscriptedWarning")  # this suite ignores it
def test_unscripted_calls_are_in_the_warnings_summary_and_fail_with_the_ini_key(pytester):
    pytester.makepyfile(test_user=UNSCRIPTED_TEST % os.path.join(TREES, "find_apple.yaml"))
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(passed=1, warnings=1)
    result.stdout.fnmatch_lines(["*warnings summary*", "*UnscriptedWarning: *find_apple.yaml: calls answered without "
                                 "a script (success, empty text, zero numbers): navigation.approach, navigation.go_to, "
                                 "vision.find_object; script them*"])
    pytester.makeini("[pytest]\nbmtree_strict_mocks = true\n")
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*MockError: calls to functions without a script (strict mocks; answered failed): "
                                 "speech.say*"])
