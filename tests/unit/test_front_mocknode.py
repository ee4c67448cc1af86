"""``python -m coordinator.testing.mocknode SCRIPT``: the script's format in ``--help``, and every
mistake of a script said as ``file:line:column: message`` (exit 2), not as a bare KeyError."""
from __future__ import annotations

import pytest
import yaml

from coordinator.errors import TreeErrors
from coordinator.testing import Mocks, fail, succeed
from coordinator.testing.mocknode import load_script, main, script_of


def _main(tmp_path, monkeypatch, capsys, text, name="m.yaml"):
    (tmp_path / name).write_text(text)
    monkeypatch.chdir(tmp_path)
    code = main(["mocknode", name])
    return code, capsys.readouterr().err


def test_help_describes_the_script(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["mocknode", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for part in ("module: navigation", "functions:", "go_to:", "- fail: blocked", "succeed: {room: kitchen}",
                 "delay: 0.5", "events:", "{at: 1.0, event: arrived, params: {place: kitchen}}", "exit 2"):
        assert part in out, out


def test_a_script_without_module_says_what_it_needs(tmp_path, monkeypatch, capsys):
    code, err = _main(tmp_path, monkeypatch, capsys, "functions:\n  go_to: {fail: blocked}\n", "m1.yaml")
    assert code == 2
    assert err == ("m1.yaml:1:1: a mock node's script needs 'module: NAME', the module it plays (known: battery, navigation, "
                   "speech, vision); then 'functions' and 'events' (--help)\n")


def test_a_misspelt_module_is_said_where_it_is_written(tmp_path, monkeypatch, capsys):
    code, err = _main(tmp_path, monkeypatch, capsys, "module: navigaton\n", "m2.yaml")
    assert code == 2
    assert err == "m2.yaml:1:9: no module 'navigaton' in the definitions (did you mean 'navigation'?)\n"


def test_every_mistake_of_a_script_is_said_where_it_is(tmp_path, monkeypatch, capsys):
    code, err = _main(tmp_path, monkeypatch, capsys, (
        "module: navigation\n"
        "funtions: {}\n"
        "functions:\n"
        "  go_to:\n"
        "    - fial: x\n"
        "    - succeed: {rom: kitchen}\n"
        "  goto: {fail: x}\n"
        "  approach: []\n"
        "events:\n"
        "  - {at: -1, event: arived}\n"
        "  - {event: arrived, params: {plac: 3}}\n"
        "  - arrived\n"))
    assert code == 2
    assert err.splitlines() == [
        "m.yaml:2:1: unknown key 'funtions' (did you mean 'functions'?)",
        "m.yaml:5:7: go_to: an outcome has one of succeed, fail, reject, hang, die (and optionally delay, ignores_cancel), got fial: "
        "'fial' is no key of an outcome (did you mean 'fail'?)",
        "m.yaml:6:17: navigation.go_to has no output 'rom' (did you mean 'room'?)",
        "m.yaml:7:3: module 'navigation' has no function 'goto' (did you mean 'go_to'?)",
        "m.yaml:8:13: functions.approach: an empty list of outcomes (leave the function out for the default)",
        "m.yaml:10:10: at must be a number of seconds >= 0, got -1",
        "m.yaml:10:21: module 'navigation' has no event 'arived' (did you mean 'arrived'?)",
        "m.yaml:11:30: navigation event arrived: unknown event param 'plac' (did you mean 'place'?); missing event "
        "param 'place'",
        "m.yaml:12:5: an event is a mapping {at, event, params} (the events of navigation: arrived)",
    ]


def test_a_file_that_is_not_a_script(tmp_path, monkeypatch, capsys):
    code, err = _main(tmp_path, monkeypatch, capsys, "module: [navigation\n")
    assert code == 2 and err.startswith("m.yaml:2:1: YAML syntax error"), err
    code, err = _main(tmp_path, monkeypatch, capsys, "- module: navigation\n")
    assert code == 2 and err.startswith("m.yaml:1:1: a mock node's script needs 'module: NAME'"), err
    monkeypatch.chdir(tmp_path)
    assert main(["mocknode", "absent.yaml"]) == 2
    assert capsys.readouterr().err.startswith("absent.yaml:1:1: cannot read absent.yaml: ")


def test_the_scripts_start_mock_node_writes_load(tmp_path, sim_defs):
    mocks = Mocks(sim_defs)
    mocks["navigation.go_to"].script(fail("door closed"), succeed(room="kitchen", delay=0.5))
    mocks.event(1.0, "navigation.arrived", place="kitchen")
    path = tmp_path / "mock_navigation.yaml"
    path.write_text(yaml.safe_dump(script_of(mocks, "navigation")))
    definition, module = load_script(str(path), sim_defs)
    assert definition.name == "navigation" and module is not None
    path.write_text(yaml.safe_dump(dict(script_of(mocks, "navigation"), module="navigaton")))
    with pytest.raises(TreeErrors):
        load_script(str(path), sim_defs)
