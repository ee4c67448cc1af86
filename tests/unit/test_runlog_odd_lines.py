"""Odd run logs and run streams: each bad line skipped with a warning naming file:line (a log whose tree
record is unusable refused, exit 2), a size limit, a newer format refused, and a module's control
characters escaped on every terminal output."""
from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys

import pytest
from rich.console import Console

from coordinator import cli
from coordinator.runevents import Display
from coordinator.runlines import call_line
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runstream import RunStream
from coordinator.testing.kit import TreeTest
from coordinator.testing.mocks import fail
from coordinator.watchstate import WatchState
from coordinator.watchtext import summary_lines
from coordinator.watchview import LinePrinter, render
from tests.conftest import DATA, ROOT

GO = os.path.join(DATA, "record", "go_kitchen.yaml")
HOSTILE = "blocked\x1b[2J\x1b]0;owned\x07\rfake\x9b31m"


def _recorded(sim_defs, tmp_path, error="blocked"):
    t = TreeTest(GO, definitions=sim_defs)
    t.mocks["navigation.go_to"].script(fail(error))
    path = str(tmp_path / "run.jsonl")
    live = io.StringIO()
    run = t.run(observers=[RunStream([RunLogWriter(path, fsync=False)]), Display(live, tty=False)])
    return path, open(path, encoding="utf-8").read().splitlines(), live.getvalue(), run


def _log(tmp_path, name, lines):
    runs = tmp_path / ("runs-" + name)
    runs.mkdir()
    path = runs / "20260101-120000-aaaaaa-go_kitchen.jsonl"
    path.write_bytes(b"\n".join(x if isinstance(x, bytes) else x.encode("utf-8") for x in lines) + b"\n")
    return str(runs), str(path)


def _main(argv, capsys):
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_a_bad_line_is_skipped_with_a_warning_naming_it_and_the_rest_is_shown(sim_defs, tmp_path, capsys):
    _path, lines, _live, _run = _recorded(sim_defs, tmp_path)
    head = lines[0]
    bad = {
        "bad-change": '{"v":1,"type":"tick","t":0.0,"n":9,"changes":[5]}',
        "unknown-node": '{"v":1,"type":"tick","t":0.0,"n":9,"changes":[[99,"FAILURE","x"]]}',
        "bad-status": '{"v":1,"type":"tick","t":0.0,"n":9,"changes":[[2,"BOGUS"]]}',
        "empty-change": '{"v":1,"type":"tick","t":0.0,"n":9,"changes":[[]]}',
        "feedback-object": '{"v":1,"type":"tick","t":0.0,"n":9,"changes":[[2,"FAILURE",{"a":1}]]}',
        "nan-time": '{"v":1,"type":"tick","t":NaN,"n":9,"changes":[]}',
        "recall-values": '{"v":1,"type":"recall","t":0.0,"values":5}',
        "not-utf8": b'{"v":1,"type":"event","t":0.0,"module":"\xff","event":"e","params":{}}',
        "deep": '{"v":1,"type":"write","t":0.0,"key":"k","value":' + "[" * 5000 + "]" * 5000 + "}",
        "newer": '{"v":2,"type":"tick","t":0.0,"n":9,"changes":[[2,"FAILURE"]]}',
    }
    for name, line in bad.items():
        runs, path = _log(tmp_path, name, [head, lines[1], line] + lines[2:])
        for extra in ([], ["--failure"], ["--step"], ["--scenario", str(tmp_path / ("%s.yaml" % name))]):
            code, out, err = _main(["replay", path] + extra, capsys)
            assert code == 0, (name, extra, err)
            assert err.startswith("warning: %s:3: " % path) and err.endswith(" (line skipped)\n"), (name, err)
        assert "the failure that ended the run" in _main(["replay", path, "--failure"], capsys)[1]
        code, out, err = _main(["runs", "--dir", runs], capsys)
        assert code == 0 and "go_kitchen" in out and "FAILURE" in out, (name, out, err)
    # a lone surrogate is no UTF-8: made U+FFFD, the line kept
    runs, path = _log(tmp_path, "surrogate", [head.replace('"go_kitchen"', '"go_\\ud800kitchen"')]
                      + [x.replace("blocked", "blo\\udc00cked") for x in lines[1:]])
    proc = subprocess.run([sys.executable, "-m", "coordinator", "replay", path, "--failure"], cwd=ROOT,
                          capture_output=True, timeout=120)
    assert proc.returncode == 0 and b"Traceback" not in proc.stderr, proc.stderr
    assert "blo\ufffdcked" in proc.stdout.decode("utf-8")
    proc = subprocess.run([sys.executable, "-m", "coordinator", "runs", "--dir", runs], cwd=ROOT,
                          capture_output=True, timeout=120)
    assert proc.returncode == 0 and "go_\ufffdkitchen" in proc.stdout.decode("utf-8"), proc.stderr


def test_a_log_whose_tree_record_is_unusable_is_refused_naming_it(sim_defs, tmp_path, capsys):
    _path, lines, _live, _run = _recorded(sim_defs, tmp_path)
    head = json.loads(lines[0])
    cases = {"nan": (json.dumps(dict(head, started=float("nan"))), "'started' of the tree record must be a Unix time"),
             "huge": (json.dumps(dict(head, started=1e300)), "'started' of the tree record must be a Unix time"),
             "nodes": (json.dumps(dict(head, nodes=[{"id": 0, "parent": 1}])), "node 0 of the tree record"),
             "newer": (json.dumps(dict(head, v=2)), "this run log was written by a newer bmtree (format version 2); "
                                                    "this bmtree reads version 1")}
    for name, (first, says) in cases.items():
        runs, path = _log(tmp_path, name, [first] + lines[1:])
        for extra in ([], ["--failure"], ["--at", "0.1"]):
            code, out, err = _main(["replay", path] + extra, capsys)
            assert code == 2 and err.startswith("error: %s:1: %s" % (path, says)), (name, err)
        code, out, err = _main(["runs", "--dir", runs], capsys)  # listed no more, and said why
        assert code == 0 and err.startswith("warning: %s:1: %s" % (path, says)) and "(not listed)" in err, err


def test_a_log_past_the_size_limit_is_refused_with_the_limit(sim_defs, tmp_path, capsys, monkeypatch):
    from coordinator import runlog

    assert runlog.MAX_LOG_BYTES <= 64 << 20   # read, a log takes some ten times its size
    _path, lines, _live, _run = _recorded(sim_defs, tmp_path)
    runs, path = _log(tmp_path, "big", lines[:-1] + [lines[1]] * 20000 + lines[-1:])
    monkeypatch.setenv("BMTREE_MAX_LOG_MB", "1")
    code, out, err = _main(["replay", path], capsys)
    assert code == 2 and "is larger than the 1 MB a run log may have to be read" in err, err
    monkeypatch.setenv("BMTREE_MAX_LOG_MB", "64")
    assert _main(["replay", path, "--at", "0"], capsys)[0] == 0


def test_a_fifo_among_the_logs_does_not_hang_runs(sim_defs, tmp_path):
    path, _lines, _live, _run = _recorded(sim_defs, tmp_path)
    runs = tmp_path / "runs"
    runs.mkdir()
    os.mkfifo(str(runs / "20260101-120000-aaaaaa-fifo.jsonl"))
    os.rename(path, str(runs / "20260102-120000-bbbbbb-go_kitchen.jsonl"))
    proc = subprocess.run([sys.executable, "-m", "coordinator", "runs", "--dir", str(runs)], cwd=ROOT,
                          capture_output=True, timeout=60)
    assert proc.returncode == 0 and b"go_kitchen" in proc.stdout


def test_watch_refuses_a_newer_format_and_leaves_out_bad_records():
    state = WatchState()
    tree = {"v": 2, "type": "tree", "run": "r2", "t": 0.0, "name": "later",
            "nodes": [{"id": 0, "parent": None, "name": "root"}]}
    state.apply(tree)
    assert not state.nodes
    assert state.refused == ("the run r2 (later) on the run stream was written by a newer bmtree (format version 2); "
                             "this bmtree reads version 1: update bmtree to read it")
    state = WatchState()
    state.apply(dict(tree, v=1))
    for bad in ({"v": 1, "type": "tick", "run": "r2", "t": 0.1, "n": 1, "changes": [[7, "FAILURE"]]},
                {"v": 1, "type": "tick", "run": "r2", "t": 0.1, "n": 1, "changes": [[0, "FAILURE", {"a": 1}]]},
                {"v": 1, "type": "snapshot", "run": "r2", "t": 0.1, "n": 5, "status": {"0": "BOGUS"}}):
        state.apply(bad)
    state.apply_text('{"v":1,"type":"write","run":"r2","t":0.1,"key":"k","value":' + "[" * 100000 + "]" * 100000 + "}")
    assert state.tick == 0 and state.status == {} and state.skipped == 3 and "k" not in state.blackboard
    state.apply({"v": 1, "type": "tick", "run": "r2", "t": 0.1, "n": 1, "changes": [[0, "RUNNING"]]})
    assert state.status == {0: "RUNNING"}


def test_control_characters_from_a_module_are_escaped_on_every_terminal_output(sim_defs, tmp_path, capsys):
    from coordinator.runevents import terminal_text

    def clean(text):
        return not any(c in text for c in "\x1b\x07\r\x9b")

    assert terminal_text("a\x1b[2Jb\tc\nd") == "a\\x1b[2Jb\tc\nd"
    assert terminal_text("a\nb\rc", newlines=False) == "a\\nb\\rc"
    path, lines, live, run = _recorded(sim_defs, tmp_path, error=HOSTILE)
    assert clean(live) and "blocked\\x1b[2J" in live                      # bmtree run's lines
    from coordinator.runlines import summary_lines as run_summary
    assert all(clean(x) for x in run_summary(run.result, "go_kitchen"))           # bmtree run's summary
    assert clean(call_line(0.0, "a.b", "failed", 0.1, HOSTILE))
    for extra in ([], ["--failure"], ["--step"], ["--at", "0.0"], ["--speed", "1000"]):
        code, out, err = _main(["replay", path] + extra, capsys)
        assert code == 0 and clean(out) and "blocked\\x1b[2J" in out, (extra, out)
    code, out, err = _main(["runs", "--dir", os.path.dirname(_log(tmp_path, "hostile", lines)[1])], capsys)
    assert code == 0 and clean(out) and "blocked\\x1b[2J" in out
    state, printed = WatchState(), io.StringIO()
    printer = LinePrinter(printed)
    for line in lines:
        rec = json.loads(line)
        state.apply(rec)
        printer.record(rec, state)
    assert clean(printed.getvalue()) and "blocked\\x1b[2J" in printed.getvalue()   # watch --plain
    shown = io.StringIO()
    Console(file=shown, width=200, no_color=True, force_terminal=False).print(render(state, 200, 50))
    assert clean(shown.getvalue()) and "\\x1b[2J" in shown.getvalue()              # watch's view, run's view
    assert all(clean(x) for x in summary_lines(state))
    from coordinator.cliutil import err as say
    say("error: " + HOSTILE)
    assert capsys.readouterr().err == "error: blocked\\x1b[2J\\x1b]0;owned\\x07\\rfake\\x9b31m\n"


def test_a_lone_surrogate_in_a_record_does_not_stop_the_log(sim_defs, tmp_path):
    """UTF-8 has no lone surrogate: the record's text holds its escape, read back as U+FFFD."""
    from coordinator.runstream import to_json

    _path, lines, _live, _run = _recorded(sim_defs, tmp_path)
    path = str(tmp_path / "surrogate.jsonl")
    writer = RunLogWriter(path, fsync=False)
    writer.write("tree", lines[0])
    writer.write("events", to_json({"v": 1, "type": "event", "t": 0.0, "module": "m", "event": "bad \udc80 byte",
                                    "params": {}}))
    writer.write("end", lines[-1])
    writer.close()
    log = read_log(path)
    assert [r["type"] for r in log.records] == ["tree", "event", "end"] and not log.warnings
    assert log.records[1]["event"] == "bad \ufffd byte"


if __name__ == "__main__":
    sys.exit(pytest.main([__file__]))


def test_replay_at_past_the_runs_end_says_so(sim_defs, tmp_path, capsys):
    """``replay --at 99`` of a 0.3 s run printed ``at 99.000s:`` and the last state, as if the run lived on."""
    path, _lines, _live, _run = _recorded(sim_defs, tmp_path)
    code, out, _ = _main(["replay", path, "--at", "99"], capsys)
    assert code == 0 and re.search(r"^at 99\.000s \(past the run's end at \d+\.\d{3}s: its last state\):$", out, re.M), out
    code, out, _ = _main(["replay", path, "--at", "0"], capsys)
    assert code == 0 and "\nat 0.000s:\n" in out and "past the run's end" not in out
