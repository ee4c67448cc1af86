"""The node-kind registry and what is generated from it; references; checks; observers; error shapes."""
from __future__ import annotations

import glob
import json
import os
import re

import jsonschema
import pytest
import yaml

from comm.errors import EnvironmentProblem, InvalidInput, ProtocolError
from coordinator.cli import main as bmtree
from coordinator.errors import TreeErrors, UsageError
from coordinator.expr import Expr, ExprError
from coordinator.nodes import REGISTRY
from coordinator.refs import Ref, RefError, parse_ref, resolve
from coordinator.runevents import RunObserver
from coordinator.schema import json_schema, markdown_tables, replace_tables
from coordinator.testing import TreeTest, succeed
from coordinator.values import literal
from modules.definition import DefinitionError
from tests.conftest import DATA, ROOT, TREES
from tests.unit.test_language import EVERY_KIND

README = os.path.join(TREES, "README.md")
WARN = os.path.join(DATA, "trees_warn")


def test_every_kind_knows_its_family_options_and_docs():
    assert set(REGISTRY) == {"sequence", "selector", "parallel", "retry", "repeat", "timeout", "inverter",
                             "force_success", "force_failure", "call", "recall", "check", "wait_event", "set",
                             "wait", "include", "for_each", "switch", "fail"}
    for name, kind in REGISTRY.items():
        assert kind.name == name and kind.family in ("composite", "decorator", "leaf")
        assert kind.summary and kind.value[1], name
        assert kind.schema()["required"][0] == name


def test_reference_tables_in_the_readme_are_generated_from_the_registry():
    with open(README, encoding="utf-8") as fh:
        text = fh.read()
    assert replace_tables(text) == text, "trees/README.md is stale: run `bmtree schema --markdown --write " \
                                         "trees/README.md`"
    assert "| `wait_event` | `module.event` |" in markdown_tables()


def test_schema_command_writes_the_tables(tmp_path, capsys):
    stale = tmp_path / "README.md"
    with open(README, encoding="utf-8") as fh:
        stale.write_text(fh.read().replace("| `retry` |", "| `retri` |"))
    assert bmtree(["schema", "--markdown", "--write", str(stale)]) == 0
    assert "updated" in capsys.readouterr().out
    assert "| `retry` |" in stale.read_text() and "retri" not in stale.read_text()
    assert bmtree(["schema", "--write", str(stale)]) == 2


def _validator():
    schema = json_schema()
    jsonschema.Draft7Validator.check_schema(schema)
    return jsonschema.Draft7Validator(schema)


@pytest.mark.parametrize("path", sorted(glob.glob(os.path.join(TREES, "*.yaml")))
                         + sorted(glob.glob(os.path.join(ROOT, "tests", "data", "trees_warn", "*.yaml"))))
def test_every_shipped_tree_is_valid_against_the_json_schema(path):
    with open(path, encoding="utf-8") as fh:
        data = yaml.safe_load(fh)
    errors = list(_validator().iter_errors(data))
    assert not errors, [e.message for e in errors]


def test_json_schema_covers_every_kind_and_refuses_what_the_loader_refuses(capsys):
    v = _validator()
    assert v.is_valid(yaml.safe_load(EVERY_KIND))
    for bad in ("format: 1\nroot: {sequense: [{wait: 1}]}\n", "format: 1\nroot: {wait: 1, tiemout: 2}\n",
                "format: 1\nroot: {retry: 0, child: {wait: 1}}\n", "format: 1\nroot: {retry: 2}\n",
                "format: 1\nroot: {parallel: [{wait: 1}], policy: some}\n", "root: {wait: 1}\n",
                "format: 1\nroot: {sequence: []}\n", "format: 1\nroot: {call: say}\n"):
        assert not v.is_valid(yaml.safe_load(bad)), bad
    assert bmtree(["schema"]) == 0
    assert json.loads(capsys.readouterr().out)["properties"]["format"] == {"const": 1, "description":
                                                                           "the tree language version"}


def test_parallel_of_two_non_concurrent_functions_of_one_module_warns(capsys):
    path = os.path.join(WARN, "parallel_busy.yaml")
    assert bmtree(["check", path]) == 0
    err = capsys.readouterr().err
    assert "parallel_busy.yaml:8:11: warning: navigation.approach can run while navigation.go_to (line 4)" in err
    assert "where_am_i" not in err and "speech" not in err  # concurrent, or another module
    capsys.readouterr()
    assert bmtree(["check", "--strict", path]) == 2
    assert capsys.readouterr().out == "%s: refused: 1 warning (--strict makes warnings errors)\n" % path
    assert bmtree(["check", "--strict", os.path.join(TREES, "find_apple.yaml")]) == 0


def test_a_null_input_is_refused_when_the_tree_loads(tmp_path, capsys):
    path = tmp_path / "null.yaml"
    path.write_text("format: 1\nroot:\n  call: speech.say\n  inputs: {text: null}\n")
    assert bmtree(["check", str(path)]) == 2
    assert capsys.readouterr().err == "%s:4:18: input 'text': null is not a std_msgs/String value\n" % path


def test_references_parsed_once_for_values_and_expressions():
    assert parse_ref("$pos.position.x") == Ref("pos", ("position", "x"))
    assert parse_ref("$people[0].name") == Ref("people", (0, "name"))
    assert parse_ref("plain") is None and literal("$$5") == "$5"
    for bad in ("$1abc", "$a.", "$a[x]", "$a b", "$a[1"):
        with pytest.raises(RefError, match="is not a valid reference"):
            parse_ref(bad)
    e = Expr("p . position[ 0 ] == 1 and $q.x")
    assert e.keys == {"p", "q"}
    assert e.evaluate({"p": {"position": [1]}, "q": {"x": True}}.__getitem__)
    with pytest.raises(ExprError) as info:
        Expr("a.")
    assert info.value.offset == 2
    value = {"target": {"x": Ref("pos", ("x",)), "y": 0.0}, "list": [Ref("n")]}
    assert resolve(value, {"pos": {"x": 1.5}, "n": 3}.__getitem__) == {"target": {"x": 1.5, "y": 0.0}, "list": [3]}


def test_literal_inputs_are_converted_once_when_the_tree_loads(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  repeat: 2\n  child:\n    call: navigation.approach\n"
                    "    inputs: {target: {x: 1.0, y: 2.0, z: 0.0}}\n")
    t = TreeTest(str(path))
    static = t.tree.root.children[0].spec.static["target"]
    t.mocks["navigation.approach"].script(succeed(success=True, position={"x": 1.0}))
    run = t.run()
    assert run.succeeded and len(run.calls()) == 2
    assert all(c.messages["target"] is static for c in run.calls())


class _Recorder(RunObserver):
    def __init__(self):
        self.seen = []

    def on_start(self, tree, root, ctx):
        self.seen.append(("start", tree.name, root.name))

    def on_tick(self, root, changes, now):
        self.seen.extend(("tick", b.name, new.value) for b, old, new in changes)

    def on_call_start(self, record):
        self.seen.append(("call", record.target))

    def on_call_end(self, record):
        self.seen.append(("ended", record.target, record.status))

    def on_blackboard_write(self, key, value, now):
        self.seen.append(("write", key))

    def on_end(self, result):
        self.seen.append(("end", result.status.value))


def test_observers_see_the_run(tmp_path):
    from coordinator.builder import build_tree
    from coordinator.clock import SimClock
    from coordinator.context import RunContext
    from coordinator.runner import TreeRunner
    from coordinator.testing.inprocess import InProcessTransport

    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nname: obs\nroot:\n  sequence:\n    - call: speech.listen\n      inputs: {seconds: 1}\n"
                    "      outputs: {text: heard}\n    - check: 'heard == \"hi\"'\n")
    t = TreeTest(str(path))
    t.mocks["speech.listen"].succeed(text="hi")
    clock = SimClock()
    ctx = RunContext(InProcessTransport(t.mocks, clock), clock, t.definitions)
    rec = _Recorder()
    result = TreeRunner(build_tree(t.tree, ctx), ctx, observers=[rec], tree=t.tree).run()
    assert result.succeeded
    assert rec.seen[0] == ("start", "obs", "sequence") and rec.seen[-1] == ("end", "SUCCESS")
    order = [s for s in rec.seen if s[0] in ("call", "ended", "write")]
    assert order == [("call", "speech.listen"), ("ended", "speech.listen", "succeeded"), ("write", "heard")]
    assert ("tick", "speech.listen", "RUNNING") in rec.seen and ("tick", "check heard == \"hi\"", "SUCCESS") in rec.seen


def test_errors_have_two_shapes(tmp_path, capsys):
    for cls in (TreeErrors, DefinitionError, UsageError, ProtocolError, RefError, ExprError):
        assert issubclass(cls, InvalidInput), cls
    from coordinator.graph import GraphError

    assert issubclass(GraphError, EnvironmentProblem)
    assert bmtree(["check", str(tmp_path / "missing.yaml")]) == 2
    assert "cannot read" in capsys.readouterr().err
    bad_def = tmp_path / "bad.json"
    bad_def.write_text("{}")
    assert bmtree(["check", "--modules", str(bad_def), os.path.join(TREES, "find_apple.yaml")]) == 2
    assert "Basic Module" in capsys.readouterr().err


@pytest.mark.parametrize("text,said", [("answer = 'yes'", "unexpected character '=' (compare with '==')"),
                                       ("a && b", "unexpected character '&' (use 'and')"),
                                       ("a || b", "unexpected character '|' (use 'or')"),
                                       ("!a", "unexpected character '!' (use 'not', or '!=')")])
def test_an_operator_from_another_language_says_what_to_write(text, said):
    with pytest.raises(ExprError, match=re.escape(said)):
        Expr(text)
