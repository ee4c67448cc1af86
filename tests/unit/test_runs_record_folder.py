"""``bmtree runs`` / ``replay`` on a folder of ``--record`` logs: any ``.jsonl`` whose first record is a run's
is a run, whatever its name, ordered by its start; other files cost one short read; the retention still
deletes only the logs bmtree named itself (no ROS master)."""
from __future__ import annotations

import builtins
import json
import os

from coordinator import cli
from coordinator import runlog as runlog_module
from coordinator.replay import find_run
from coordinator.runlog import RunLogWriter, list_runs, plan_run_files, read_log
from coordinator.runstream import RunStream
from coordinator.testing.kit import TreeTest
from coordinator.testing.mocks import fail, succeed
from tests.conftest import DATA

GO = os.path.join(DATA, "record", "go_kitchen.yaml")
T0 = 1795712562.0   # 2026-11-26 (local time), as the audit's runs


def _record(sim_defs, path, blocked):
    t = TreeTest(GO, definitions=sim_defs)
    t.mocks["navigation.go_to"].script(fail("blocked") if blocked else succeed(room="kitchen"))
    t.run(observers=[RunStream([RunLogWriter(str(path), fsync=False)], {"inputs": {}})])


def _restarted(path, started, run_id):
    """Rewrite ``path``'s tree record with another start and run id (as another run's log)."""
    lines = path.read_text().splitlines()
    head = json.loads(lines[0])
    head.update(started=started, run=run_id)
    path.write_text("\n".join([json.dumps(head)] + lines[1:]) + "\n")


def _folder(tmp_path, sim_defs):
    """``logs/`` as the audit's: ``--record`` logs of the user's names, whose order is not their names',
    a copy renamed as bmtree names its own, and files that are no run logs."""
    logs = tmp_path / "logs"
    logs.mkdir()
    _record(sim_defs, logs / "run_b.jsonl", blocked=True)
    _restarted(logs / "run_b.jsonl", T0 + 60, "20261126-170342-bbbbbb")
    _record(sim_defs, logs / "z_first.jsonl", blocked=False)
    _restarted(logs / "z_first.jsonl", T0, "20261126-170242-aaaaaa")
    _record(sim_defs, logs / "20261126-170442-cccccc-go_kitchen.jsonl", blocked=False)
    _restarted(logs / "20261126-170442-cccccc-go_kitchen.jsonl", T0 + 120, "20261126-170442-cccccc")
    (logs / "a_data.jsonl").write_text('{"x": 1, "y": 2}\n' * 3)      # someone else's JSON lines
    (logs / "notes.jsonl").write_text("not json at all\n")
    (logs / "run_b.out").write_text("go_kitchen: FAILURE\n")          # not .jsonl: not looked at
    return logs


def test_runs_lists_record_logs_of_any_name_by_their_start(sim_defs, tmp_path, capsys):
    logs = _folder(tmp_path, sim_defs)
    assert cli.main(["runs", "--dir", str(logs)]) == 0
    out, err = capsys.readouterr()
    rows = [line.split() for line in out.splitlines()[2:]]
    assert [(r[0], r[5]) for r in rows] == [("1", "SUCCESS"), ("2", "FAILURE"), ("3", "SUCCESS")], out
    assert [os.path.basename(r.path) for r in list_runs(str(logs))] == [
        "z_first.jsonl", "run_b.jsonl", "20261126-170442-cccccc-go_kitchen.jsonl"]   # oldest first, by start
    # the two .jsonl files that are no run logs: one line, not one per file, and not an error
    assert err == ("warning: %s: 2 other .jsonl files are not run logs (their first lines are no run's 'tree' "
                   "record) (not listed)\n" % logs), err


def test_replay_last_and_by_number_and_by_run_id_on_a_folder_of_record_logs(sim_defs, tmp_path, capsys):
    logs = _folder(tmp_path, sim_defs)
    assert find_run("last", str(logs)).endswith("20261126-170442-cccccc-go_kitchen.jsonl")
    assert find_run("2", str(logs)).endswith("run_b.jsonl")
    assert find_run("3", str(logs)).endswith("z_first.jsonl")
    assert find_run("20261126-170242-aa", str(logs)).endswith("z_first.jsonl")   # its run's id (scenario names)
    assert find_run("run_b", str(logs)).endswith("run_b.jsonl")                # the start of its file name
    assert cli.main(["replay", "2", "--dir", str(logs)]) == 0
    out = capsys.readouterr().out
    assert "replay of %s" % (logs / "run_b.jsonl") in out and "blocked" in out, out
    assert cli.main(["replay", "last", "--dir", str(logs), "--at", "0.001"]) == 0
    assert "20261126-170442-cccccc-go_kitchen.jsonl" in capsys.readouterr().out


def test_other_jsonl_files_cost_one_short_read_each(sim_defs, tmp_path, monkeypatch):
    """A folder may hold large JSON-lines data: bmtree reads the first 4 KB of a file it did not name to
    know it is no run log, never the whole first line of a big one."""
    logs = _folder(tmp_path, sim_defs)
    big = logs / "points.jsonl"
    with open(big, "w") as fh:   # one 8 MB line: a run log's first record could be that long, this is not one
        fh.write('{"points": [' + ",".join(["[1.0, 2.0, 3.0]"] * 500000) + "]}\n")
    read = {}
    real_open = builtins.open

    class Counted:
        def __init__(self, fh, name):
            self.fh, self.name = fh, name

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def _count(self, data):
            read[self.name] = read.get(self.name, 0) + len(data)
            return data

        def read(self, *a):
            return self._count(self.fh.read(*a))

        def readline(self, *a):
            return self._count(self.fh.readline(*a))

        def __getattr__(self, name):
            return getattr(self.fh, name)

    def counting_open(path, *a, **kw):
        return Counted(real_open(path, *a, **kw), os.path.basename(str(path)))

    monkeypatch.setattr(runlog_module, "open", counting_open, raising=False)
    assert len(list_runs(str(logs))) == 3
    assert read["points.jsonl"] <= 4096 and read["a_data.jsonl"] <= 4096, read


def test_retention_never_deletes_a_record_log_in_the_runs_folder(sim_defs, tmp_path, monkeypatch):
    """`--record ~/.ros/bmtree/runs/mine.jsonl` is listed with bmtree's own logs, by its start, but the
    retention (--keep-runs) counts and deletes only the logs bmtree named itself."""
    monkeypatch.setenv("ROS_HOME", str(tmp_path))
    runs = tmp_path / "bmtree" / "runs"
    runs.mkdir(parents=True)
    _record(sim_defs, runs / "mine.jsonl", blocked=True)
    _restarted(runs / "mine.jsonl", T0 - 3600, "20261126-160242-mmmmmm")   # older than all of bmtree's
    for i in range(3):
        name = "2026112%d-120000-abcde%d-go_kitchen.jsonl" % (i + 1, i)
        _record(sim_defs, runs / name, blocked=False)
        _restarted(runs / name, T0 + i, name[:22])
    assert [os.path.basename(r.path) for r in list_runs(str(runs))][0] == "mine.jsonl"
    plan_run_files(GO, None, False, 2)    # this run and the newest one of bmtree's are kept
    assert sorted(os.listdir(runs)) == ["20261123-120000-abcde2-go_kitchen.jsonl", "mine.jsonl"]
    assert read_log(str(runs / "mine.jsonl")).end["status"] == "FAILURE"
    assert find_run("2", str(runs)).endswith("mine.jsonl")
