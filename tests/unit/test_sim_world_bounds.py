"""Bad input to the simulated robot, the module definitions, the nodes' private parameters and the
Blackboard: a clear error (file:line:column, the parameter's name), exit 2, never a traceback nor a hang."""
from __future__ import annotations

import argparse
import logging
import os
import sqlite3
import subprocess
import sys
import threading

import pytest

from blackboard.service import BlackboardService
from blackboard.store import Store
from comm import nodeopts
from comm.messages import FunctionResult
from comm.nodeopts import _private_params, count, fill_from_params, seconds
from coordinator.cli import main
from modules.definition import DefinitionError, load_definition
from modules.sim.world import World, WorldError
from tests.conftest import ROOT


@pytest.fixture
def no_master(monkeypatch):
    monkeypatch.setenv("ROS_MASTER_URI", "http://127.0.0.1:9/")  # the discard port: nothing listens there


# 1. world files --------------------------------------------------------------------------------------
BAD_WORLD = """speed: .nan
faults:
  navigation.go_to: {delay: 1e300}
  vision.find_object: {delay: -1, times: 99999999999999999999999999999999999999999}
  speech.say: {delay: .nan}
battery: {level: .nan, drain_per_metre: 123456789012345678901234567890123456789}
events:
  - {at: 1e300, event: battery.low, params: {percentage: 3}}
"""


def test_every_bad_number_of_a_world_is_said_at_once_at_its_position(tmp_path):
    path = tmp_path / "w.yaml"
    path.write_text(BAD_WORLD)
    with pytest.raises(WorldError) as exc:
        World.load(str(path))
    lines = str(exc.value).splitlines()
    assert [line.split(": ", 1)[0] for line in lines] == [
        "%s:%s" % (path, at) for at in ("1:8", "3:29", "4:31", "4:42", "5:23", "6:18", "6:41", "8:10")], lines
    text = str(exc.value)
    assert "speed must be a finite number of metres per second" in text
    assert "faults.navigation.go_to.delay must be a number of seconds from 0 to 86400 (a day), got 1e+300" in text
    assert "faults.vision.find_object.times must be a whole number from 0 to 1000000000" in text
    assert "battery.level must be a non-negative number, got nan" in text
    assert "events[0].at must be a non-negative number of seconds (at most 86400, a day), got 1e+300" in text


@pytest.mark.parametrize("world, says", [
    ("speed: -1\n", "1:8: speed must be"),
    ("speed: 0\n", "1:8: speed must be"),
    ("faults: {speech.say: {delay: 1.0e+300}}\n", "1:30: faults.speech.say.delay must be"),
    ("faults: {speech.say: {fail: x, delay: .inf}}\n", "1:39: faults.speech.say.delay must be"),
    ("faults: {speech.say: {crash: x, delay: 90000}}\n", "1:40: faults.speech.say.delay must be"),
    ("rooms: {a: {x: 1e999, y: 0}}\nstart: a\nplaces: {}\nobjects: {}\npeople: {}\n", "1:16: rooms.a.x must be"),
    ("objects: {car: {room: kitchen, x: .nan, y: 0}}\n", "1:35: objects.car.x must be"),
])
def test_a_number_out_of_range_in_a_world_is_an_error_at_its_position(tmp_path, world, says):
    path = tmp_path / "w.yaml"
    path.write_text(world)
    with pytest.raises(WorldError, match="^" + str(path).replace(".", r"\.") + ":" + says.replace(".", r"\.")):
        World.load(str(path))


def test_a_fault_delay_of_1e300_no_longer_reaches_the_module(no_master, tmp_path, capsys):
    """It used to be accepted, and its timer thread died of it: the module never answered again."""
    path = tmp_path / "w.yaml"
    path.write_text("faults:\n  navigation.go_to: {delay: 1.0e+300}\n")
    out = subprocess.run([sys.executable, "-m", "modules.sim", "navigation", "--world", str(path)], cwd=ROOT,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert out.stderr == ("error: %s:2:29: faults.navigation.go_to.delay must be a number of seconds from 0 to 86400 "
                          "(a day), got 1e+300\n" % path)
    assert main(["run", "--sim", "--world", str(path), os.path.join(ROOT, "trees", "find_apple.yaml")]) == 2
    assert "error: --world %s:2:29: faults.navigation.go_to.delay" % path in capsys.readouterr().err


def _returns_soon(fifo, call):
    """``call()``'s outcome (its exception), within 10 s; else a writer is opened on ``fifo`` to free it, and
    the test fails: the reader waited at open() for a writer."""
    done = []

    def run():
        try:
            call()
            done.append(None)
        except Exception as exc:
            done.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(10.0)
    if not done:
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        thread.join(5.0)
        pytest.fail("reading the FIFO %s waited for a writer" % fifo)
    return done[0]


def test_a_world_read_is_bounded_and_refuses_devices_and_idle_pipes(tmp_path):
    fifo = str(tmp_path / "w.fifo")
    os.mkfifo(fifo)
    exc = _returns_soon(fifo, lambda: World.load(fifo))   # it used to wait for ever
    assert exc is None or str(exc).startswith("%s: cannot read: " % fifo), exc   # empty: the default house
    with pytest.raises(WorldError, match="^/dev/zero: cannot read: "):
        World.load("/dev/zero")
    deep = tmp_path / "deep.yaml"
    deep.write_text("faults: " + "[" * 5000 + "\n")
    with pytest.raises(WorldError, match=r"deep\.yaml:1:\d+: not valid YAML: the document is nested too deeply"):
        World.load(str(deep))
    twice = tmp_path / "twice.yaml"
    twice.write_text("speed: 2\nspeed: 3\n")
    with pytest.raises(WorldError, match=r"twice\.yaml:2:1: not valid YAML: duplicate key 'speed'"):
        World.load(str(twice))


def test_a_fault_given_as_a_node_parameter_is_bounded_too():
    from modules.node import _faults
    from modules.runtime import BindingError
    from modules.sim import definition_path

    nav = load_definition(definition_path("navigation"))
    with pytest.raises(BindingError, match=r"~faults: faults.navigation.go_to.delay must be a number of seconds"):
        _faults(nav, {"go_to": {"delay": 1e300}})
    with pytest.raises(BindingError, match="~faults is not valid YAML: ~faults:1:401: the document is nested too"):
        _faults(nav, "[" * 5000)
    assert _faults(nav, "{go_to: {fail: blocked, delay: 0.5}}")["go_to"].outcome.delay == 0.5


# 2. definition files ---------------------------------------------------------------------------------
def test_a_definition_that_is_a_fifo_or_a_device_is_refused_not_waited_on(tmp_path):
    fifo = str(tmp_path / "m.json")
    os.mkfifo(fifo)
    exc = _returns_soon(fifo, lambda: load_definition(fifo))   # it used to wait for ever
    assert isinstance(exc, DefinitionError) and str(exc).startswith(fifo + ":"), exc
    with pytest.raises(DefinitionError, match="^/dev/zero: cannot read: not a regular file"):
        load_definition("/dev/zero")
    big = tmp_path / "big.json"
    with open(big, "wb") as fh:
        fh.truncate((4 << 20) + 1)
    with pytest.raises(DefinitionError, match="big.json: cannot read: larger than 4 MiB: not a module definition"):
        load_definition(str(big))


# 3. private parameters -------------------------------------------------------------------------------
@pytest.mark.parametrize("arg, says", [
    ("_foo:=99999999999", "private parameter _foo: 99999999999 is no ROS parameter value (whole numbers"),
    ("_foo:=2001-01-01", "private parameter _foo: 2001-01-01 is no ROS parameter value"),
    ("_foo:={1: a}", "private parameter _foo: {1: a} is no ROS parameter value"),
    ("_foo:=~", "private parameter _foo: null is no ROS parameter value"),
    ("_foo:=a:=b", "private parameter _foo: one ':=' between the name and the value"),
    ("_foo:=" + "[" * 3000, "private parameter _foo: nested too deeply"),
    ("_foo:={a: [1", "private parameter _foo:={a: [1: not valid YAML"),
    ("_foo:=!!int x", "private parameter _foo:=!!int x: not valid YAML"),
])
def test_a_private_parameter_rospy_could_not_set_is_refused_before_the_node_starts(arg, says):
    """rospy's init_node raised on them (OverflowError, TypeError, RecursionError, ROSInitException)."""
    with pytest.raises(getattr(nodeopts, "ParamError", ())) as exc:
        _private_params(["navigation", arg], None, 0.1)
    assert str(exc.value).startswith(says), str(exc.value)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="node")
    p.add_argument("--world")
    p.add_argument("--wait", type=seconds())
    p.add_argument("--keep", type=count())
    p.add_argument("--live", action="store_true")
    return p


@pytest.mark.parametrize("params, says", [
    ({"wait": 10 ** 400}, "private parameter ~wait: 1%s... is not valid for --wait: expected a number of seconds"
                          % ("0" * 76)),
    ({"wait": True}, "private parameter ~wait: True is not valid for --wait: expected a number of seconds, got True"),
    ({"wait": [1]}, "private parameter ~wait: [1] is not valid for --wait: expected a single value, got a list"),
    ({"keep": {"a": 1}}, "private parameter ~keep: {'a': 1} is not valid for --keep: expected a single value"),
    ({"keep": True}, "private parameter ~keep: True is not valid for --keep: expected a whole number"),
    ({"world": ["a"]}, "private parameter ~world: ['a'] is not valid for --world: expected a text, got a list"),
    ({"live": "yes please"}, "private parameter ~live: 'yes please' is not valid for --live: expected true or false"),
])
def test_a_private_parameter_of_the_wrong_kind_is_a_usage_error_naming_it(capsys, params, says):
    parser = _parser()
    with pytest.raises(SystemExit) as exc:
        fill_from_params(parser, parser.parse_args([]), [], params)
    assert exc.value.code == 2
    assert says in capsys.readouterr().err


def test_a_number_given_for_a_path_parameter_is_its_text(capsys):
    parser = _parser()
    args = fill_from_params(parser, parser.parse_args([]), [], {"world": 5, "live": True})
    assert (args.world, args.live) == ("5", True)   # it was the int 5: os.path.expanduser raised TypeError


@pytest.mark.parametrize("argv, says", [
    (["-m", "modules.sim", "navigation", "_world:=5"], "error: 5: cannot read: No such file or directory"),
    (["-m", "modules.sim", "navigation", "_foo:=99999999999"], "private parameter _foo: 99999999999 is no ROS"),
    (["-m", "blackboard.node", "_db:=[a]"], "private parameter ~db: ['a'] is not valid for --db: expected a text"),
    (["-m", "modules.node", "--definition", "g.json", "--class", "g:G", "_max_bytes:=true"],
     "private parameter ~max_bytes: True is not valid for --max-bytes"),
])
def test_a_node_given_a_bad_parameter_exits_2_with_one_clear_line(no_master, tmp_path, argv, says):
    out = subprocess.run([sys.executable] + argv, cwd=ROOT, capture_output=True, text=True, timeout=60,
                         env=dict(os.environ, ROS_HOME=str(tmp_path)))
    assert out.returncode == 2, out.stderr
    assert says in out.stderr and "Traceback" not in out.stderr, out.stderr


# 4. the Blackboard's names ---------------------------------------------------------------------------
def _result(names, call_id):
    from std_msgs.msg import String

    return FunctionResult(status="succeeded", basic_mod="vision", function="find", call_id=call_id,
                          names=names, msgs=[String("v%d" % i) for i in range(len(names))]).encode()


class _Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.said = []

    def emit(self, record):
        self.said.append(record.getMessage())


def test_a_value_whose_name_no_request_could_ask_for_is_refused_alone():
    store = Store(":memory:")
    service = BlackboardService(store, lambda text: None, threaded=False)
    records = _Records()
    logging.getLogger("bmtree.blackboard").addHandler(records)
    try:
        service.on_result(_result(["", "ok", "a/b", "tab\there"], "c1"))
        for i in range(20):   # a sender repeating it: the warning is not repeated
            service.on_result(_result([""], "c%d" % (i + 2)))
        service.on_result(_result(["after"], "c99"))
    finally:
        logging.getLogger("bmtree.blackboard").removeHandler(records)
    assert [n for n, _count, _stamp in store.names()] == ["after", "ok"]
    assert service.rejected == 23
    warned = [said for said in records.said if "refused" in said]
    assert len(warned) == 1 and "refused 3 value(s) of a result of vision.find (call c1): an empty name" in warned[0]


def test_blackboard_dump_shows_an_old_stores_empty_name(no_master, tmp_path, capsys):
    db = str(tmp_path / "bb.sqlite")
    store = Store(db)
    store.add([("", "std_msgs/String", '{"data": "old"}', "vision", "find", "c1", 1.0),
               ("a/b/c", "std_msgs/String", '{"data": "odd"}', None, None, None, 1e300),
               ("ok", "std_msgs/String", '{"data": "fine"}', "vision", "find", "c1", 2.0)])
    store.close()
    assert main(["blackboard", "dump", "--db", db]) == 0
    out = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in out[1:]] == ["''", "'a/b/c'", "ok"], out
    assert '{"data": "old"}' in out[1] and '{"data": "odd"}' in out[2]
    con = sqlite3.connect(db)
    con.execute("UPDATE value SET stamp = 1e300")
    con.commit()
    con.close()
    assert main(["blackboard", "dump", "--db", db, "--name", "ok"]) == 0
    assert "1e+300" in capsys.readouterr().out


# the simulated modules' own inputs ------------------------------------------------------------------
def test_a_drive_beyond_any_house_fails_at_once_and_a_bad_odometer_is_ignored(sim_defs):
    from std_msgs.msg import Float64

    from modules.sim import Battery, Navigation
    from tests.unit.test_runtime import Served

    world = World.load()
    nav = Served(sim_defs["navigation"], Navigation(world))
    r = nav.result(nav.call("approach", target={"x": 1e300, "y": 0.0}))   # it drove for ever (until cancelled)
    assert r.status == "failed" and "cannot drive to (1e+300, 0): it would take" in r.error, r
    battery = Battery(world)
    for bad in (float("nan"), float("inf"), -5.0):
        battery._heard_odometer(Float64(bad))   # inf drained the battery for good
    assert battery.state.odometer == 0.0 and battery._update() == 100.0
