"""README-as-written audit, second round: a world file of some top-level keys takes the rest from
the default house; --sim's advice for an unknown module; a scenario file's errors, its tree's
first; the catch-up line stamped with the moment of attaching; replay --speed is a factor."""
from __future__ import annotations

import io
import json
import os
import re

import pytest

from coordinator.cli import main
from coordinator.errors import TreeErrors
from coordinator.testing.scenario import load_scenario_file, run_scenarios
from coordinator.watchsinks import SnapshotSink
from coordinator.watchstate import WatchState
from coordinator.watchview import LinePrinter
from modules.sim.world import DEFAULT_WORLD, World, WorldError
from tests.conftest import DATA, ROOT

GRIPPER = os.path.join(DATA, "gripper")
GRASP = os.path.join(GRIPPER, "grasp.yaml")


@pytest.fixture
def no_master(monkeypatch):
    monkeypatch.setenv("ROS_MASTER_URI", "http://127.0.0.1:9/")  # the discard port: nothing listens there
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("BMTREE_MODULE_PATH", raising=False)


# 1. a world of some top-level keys ------------------------------------------------------------
def test_a_world_of_faults_alone_is_the_default_house_with_those_faults(tmp_path):
    house = World.load()
    jam = tmp_path / "jam.yaml"
    jam.write_text("faults: {gripper.close: {fail: jammed, times: 1}}\n")
    world = World.load(str(jam), others=["gripper.close", "gripper.open"])
    assert (world.rooms, world.start, world.speed) == (house.rooms, house.start, house.speed)
    assert sorted(world.places) == sorted(house.places) and sorted(world.objects) == sorted(house.objects)
    assert sorted(world.people) == ["Ana"]
    assert list(world.faults) == ["gripper.close"] and world.faults_of("gripper") == {
        "close": {"fail": "jammed", "times": 1}}
    # the node of a simulated module reads the same file (others=True)
    assert World.load(str(jam), others=True).start == house.start


def test_a_key_the_file_gives_replaces_the_default_whole(tmp_path):
    f = tmp_path / "w.yaml"
    f.write_text("objects: {car: {room: kitchen, x: 1, y: 2}}\nfaults: {navigation.go_to: {fail: blocked, times: 1}}\n"
                 "speed: 2\n")
    world = World.load(str(f))
    assert list(world.objects) == ["car"] and world.speed == 2.0
    assert sorted(world.rooms) == sorted(World.load().rooms) and "sofa" in world.places
    (tmp_path / "empty.yaml").write_text("# nothing yet\n")
    assert sorted(World.load(str(tmp_path / "empty.yaml")).objects) == ["apple", "cup"]


def test_a_world_that_gives_rooms_must_give_a_consistent_house(tmp_path):
    f = tmp_path / "mine.yaml"
    f.write_text("rooms: {hall: {x: 0, y: 0}}\n")
    with pytest.raises(WorldError) as exc:
        World.load(str(f))
    assert str(exc.value).splitlines()[0] == (
        "%s: places.sofa.room: unknown room 'living_room' (places is the default house's, %s: a world that gives "
        "rooms: must give a consistent house: give places: too, places: {} for none)" % (f, DEFAULT_WORLD))
    f.write_text("rooms: {hall: {x: 0, y: 0}}\nplaces: {}\nobjects: {}\npeople: {}\n")
    with pytest.raises(WorldError, match=r"mine.yaml: start: unknown room 'entrance' \(start is the default "
                                         r"house's, .*: give start: too\)$"):
        World.load(str(f))
    f.write_text("rooms: {hall: {x: 0, y: 0}}\nplaces: {}\nobjects: {}\npeople: {}\nstart: hall\n")
    world = World.load(str(f))
    assert (list(world.rooms), world.start, world.objects, world.speed) == (["hall"], "hall", {}, 40.0)


def test_a_thing_in_a_room_the_default_house_lacks_says_the_rooms_are_the_default_ones(tmp_path):
    f = tmp_path / "o.yaml"
    f.write_text("objects:\n  car: {room: garage, x: 0, y: 0}\n")
    with pytest.raises(WorldError) as exc:
        World.load(str(f))
    assert str(exc.value) == ("%s:2:15: objects.car.room: unknown room 'garage' (the rooms are the default house's, "
                              "%s: give rooms: for others)" % (f, DEFAULT_WORLD))
    f.write_text("faults:\n  gripper.clsoe: {fail: jammed}\n")  # still checked, with the default house
    with pytest.raises(WorldError, match=r"faults.gripper.clsoe: not a function of the simulated robot or of your "
                                         r"--module \(did you mean 'gripper.close'\?\)"):
        World.load(str(f), others=["gripper.close"])
    f.write_text("faults: {speech.say: {fail: x}\n")  # YAML errors keep file:line:column
    with pytest.raises(WorldError, match=r"o.yaml:2:1: not valid YAML"):
        World.load(str(f))


def test_run_sim_checks_a_faults_only_world_before_anything_starts(no_master, tmp_path, capsys):
    """The reported command got `--world jam.yaml: start: unknown room ''`; now the world is valid,
    so the run gets past the check (to a --record error, found after it and before anything starts)."""
    jam = tmp_path / "jam.yaml"
    jam.write_text("faults: {gripper.close: {fail: jammed, times: 1}}\n")
    spec = "%s=%s:Gripper" % (os.path.join(GRIPPER, "gripper.json"), os.path.join(GRIPPER, "gripper.py"))
    notes = tmp_path / "notes.txt"
    notes.write_text("not a run log\n")
    assert main(["run", "--sim", "--world", str(jam), "--module", spec, "--record", str(notes), GRASP]) == 2
    err = capsys.readouterr().err
    assert "--record %s: the file exists and is not a bmtree run log" % notes in err and "--world" not in err, err
    jam.write_text("faults: {gripper.clsoe: {fail: jammed, times: 1}}\n")
    assert main(["run", "--sim", "--world", str(jam), "--module", spec, GRASP]) == 2
    assert "error: --world %s:1:10: faults.gripper.clsoe: not a function" % jam in capsys.readouterr().err


# 2. --sim's advice for a module it does not know ----------------------------------------------
def test_an_unknown_module_under_sim_suggests_module_not_modules(no_master, capsys):
    assert main(["run", "--sim", GRASP]) == 2
    err = capsys.readouterr().err
    assert "grasp.yaml:12:15: unknown module 'gripper' (known: battery, navigation, speech, vision; --sim starts your module " \
           "beside the simulated robot with --module DEF.json=FILE.py:CLASS)" in err, err
    assert "--modules FILE.json" not in err
    assert main(["check", GRASP]) == 2  # elsewhere a definition is what is missing
    assert "give your module's definition with --modules FILE.json" in capsys.readouterr().err


# 3. a scenario file's errors: its tree's first ------------------------------------------------
SCENARIOS = """tree: grip.yaml
scenarios:
  - mocks:
      gripper.close: {succeed: {holding: true}}
    expect: {status: success}
"""


@pytest.mark.parametrize("name", ["grip.scen.yaml", "a.yaml", "zz.yaml"])
def test_a_scenario_files_tree_errors_come_before_its_own(tmp_path, capsys, name):
    with open(GRASP) as fh:
        (tmp_path / "grip.yaml").write_text(fh.read())
    scen = tmp_path / name
    scen.write_text(SCENARIOS)
    with pytest.raises(TreeErrors) as exc:
        load_scenario_file(str(scen))
    where = [(os.path.basename(e.pos.file), e.pos.line) for e in exc.value.errors]
    assert where == [("grip.yaml", 12), ("grip.yaml", 14), (name, 4)], where
    assert run_scenarios([str(scen)], out=io.StringIO()) == 2
    lines = capsys.readouterr().err.splitlines()
    assert [re.sub(r":\d+:\d+: .*", "", os.path.basename(line)) for line in lines] == ["grip.yaml", "grip.yaml", name]
    assert "no module 'gripper' to mock" in lines[2]
    # and how to give its definition, the scenario's modules: first (a team's module where its workspace is not sourced)
    assert "give its definition: modules: in the scenario file (a file or folder, relative to it)" in lines[2]


# 4. the catch-up line: the moment of attaching ------------------------------------------------
def test_a_snapshot_is_stamped_with_the_runs_time_when_taken():
    now = [100.0]
    sink = SnapshotSink(publish=lambda text: None, clock=lambda: now[0])
    nodes = [{"id": 0, "parent": None, "kind": "wait", "shape": "leaf", "name": "wait 5s"}]
    sink.write("tree", json.dumps({"v": 1, "type": "tree", "run": "r1", "t": 0.0, "name": "t", "nodes": nodes}))
    now[0] = 100.001
    sink.write("status", json.dumps({"type": "tick", "run": "r1", "n": 2, "t": 0.001, "changes": [[0, "RUNNING"]]}))
    now[0] = 103.0  # a watcher attaches 3 s into the wait: nothing changed since the tick
    snap = json.loads(json.dumps(sink.snapshot()))
    assert snap["t"] == pytest.approx(3.0) and snap["n"] == 2
    late = WatchState()
    out = io.StringIO()
    printer = LinePrinter(out)
    for rec in ({"v": 1, "type": "tree", "run": "r1", "t": 0.0, "name": "t", "nodes": nodes}, snap):
        late.apply(rec)
        printer.record(rec, late)
    assert "[  3.000s] caught up at tick 2: wait 5s RUNNING" in out.getvalue(), out.getvalue()
    # published ones too; and an ended run keeps the end's time
    published = []
    sink.publish = published.append
    sink.flush()
    assert json.loads(published[-1])["t"] == pytest.approx(3.0)
    sink.write("end", json.dumps({"type": "end", "run": "r1", "t": 5.002, "status": "SUCCESS", "ticks": 3}))
    now[0] = 110.0
    assert sink.snapshot()["t"] == pytest.approx(5.002)


# 5. replay --speed is a factor; the README's bmtree test output ---------------------------------
def test_replay_speed_is_a_factor(no_master, capsys):
    for value in ("0", "-1", "nan"):
        assert main(["replay", "last", "--speed", value]) == 2
        err = capsys.readouterr().err
        assert "argument --speed: expected a factor greater than 0" in err and "seconds" not in err, err
    assert main(["replay", "last", "--speed", "fast"]) == 2
    assert "argument --speed: expected a number (a factor" in capsys.readouterr().err
    assert main(["run", "--period", "0", GRASP]) == 2  # the other options keep their wording
    assert "argument --period: expected a finite number of seconds greater than 0" in capsys.readouterr().err


def test_the_readmes_bmtree_test_examples_end_with_the_summary_line():
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        text = fh.read()
    blocks = re.findall(r"```console\n(.*?)```", text, re.S)
    runs = [b.split("\n$ ") for b in blocks if "$ bmtree test " in b]
    assert runs
    for parts in runs:
        for part in parts:
            if part.lstrip("$ ").startswith("bmtree test "):
                lines = [line for line in part.splitlines()[1:] if line.strip()]
                assert lines and re.fullmatch(r"\d+ passed, \d+ failed.*", lines[-1]), part
