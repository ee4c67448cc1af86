"""The simulated battery (drain with distance and time, ``low`` once per crossing, charge at the dock),
the world's scheduled ``events``, and trees/README.md's "Reacting while an action runs" patterns run
against the simulated modules' real runtime (worker threads, wall clock) in process."""
from __future__ import annotations

import logging
import re
import time

import pytest

from coordinator.builder import build_tree
from coordinator.cli import main
from coordinator.clock import RealClock
from coordinator.context import RunContext
from coordinator.language import load_tree
from coordinator.runner import TreeRunner
from coordinator.testing.inprocess import InProcessTransport
from coordinator.testing.mocks import Mocks
from modules.runtime import ModuleServer
from modules.sim import SIM_CLASSES, Battery, Navigation, Vision, World, WorldError
from modules.sim.robot import RobotState
from modules.sim.world import _default_data
from tests.conftest import TREES, documented_reactions, until
from tests.unit.test_runtime import Served

EVENT, POLL = ("format: 1\nroot:\n" + root for root in documented_reactions())


def world(**keys):
    """The default house with ``keys`` replacing its top-level keys."""
    return World.from_dict(keys, base=_default_data())


def served(sim_defs, w):
    """Navigation and battery over one robot state, as in one process."""
    state = RobotState(w.start, *w.rooms[w.start])
    return Served(sim_defs["navigation"], Navigation(w, state)), Served(sim_defs["battery"], Battery(w, state))


def lows(battery):
    return [round(e.values["percentage"].data, 3) for e in battery.events if e.event == "low"]


# the battery ----------------------------------------------------------------------------------------
def test_the_default_battery_is_full_and_drains_too_slowly_to_matter(sim_defs):
    w = World.load()
    assert (w.battery.level, w.battery.low, w.battery.dock, w.events) == (100.0, 20.0, "entrance", [])
    nav, bat = served(sim_defs, w)
    assert nav.result(nav.call("go_to", place="kitchen")).status == "succeeded"
    level = bat.result(bat.call("level")).values
    assert 98.0 < level["percentage"].data < 100.0 and level["charging"].data is False
    assert lows(bat) == []


def test_driving_drains_the_battery_and_low_is_emitted_once_per_crossing(sim_defs):
    w = world(speed=100.0, battery={"level": 28, "drain_per_metre": 1.0, "low": 20, "charge_per_second": 1000})
    nav, bat = served(sim_defs, w)
    assert nav.result(nav.call("go_to", place="living_room")).status == "succeeded"   # 4 m
    assert bat.result(bat.call("level")).values["percentage"].data == pytest.approx(24.0)
    assert lows(bat) == []
    assert nav.result(nav.call("go_to", place="kitchen")).status == "succeeded"       # ~4.5 m more
    (low,) = lows(bat)
    assert 19.0 < low <= 20.0        # emitted as it fell to the threshold, mid-drive
    assert bat.result(bat.call("level")).values["percentage"].data == pytest.approx(28 - 4 - 20 ** 0.5)
    assert nav.result(nav.call("go_to", place="living_room")).status == "succeeded"
    assert len(lows(bat)) == 1       # still low: not again
    # charging works only at the dock (the start room), and brings it back above the threshold
    r = bat.result(bat.call("charge"))
    assert (r.status, r.error) == ("failed", "not at the dock (entrance): the robot is at living_room")
    nav.result(nav.call("go_to", place="entrance"))
    r = bat.result(bat.call("charge"))
    assert r.status == "succeeded" and r.values["percentage"].data == 100.0
    w2 = world(speed=100.0, battery={"level": 21, "drain_per_metre": 10.0, "low": 20, "charge_per_second": 1000})
    nav, bat = served(sim_defs, w2)
    nav.result(nav.call("go_to", place="living_room"))
    assert len(lows(bat)) == 1
    nav.result(nav.call("go_to", place="entrance"))
    bat.result(bat.call("charge"))   # above the threshold again: the next crossing emits again
    nav.result(nav.call("go_to", place="kitchen"))
    assert len(lows(bat)) == 2


def test_a_battery_that_starts_low_says_so_at_its_first_drain_and_time_drains_it_too(sim_defs):
    w = world(battery={"level": 10, "drain_per_metre": 0, "drain_per_second": 20.0, "low": 5})
    nav, bat = served(sim_defs, w)
    bat.server.impl._start()   # the time drain's checks start with the module
    until(lambda: lows(bat), timeout=3.0)
    assert lows(bat)[0] <= 5.0
    w = world(speed=100.0, battery={"level": 15, "drain_per_metre": 0.1})
    nav, bat = served(sim_defs, w)
    nav.result(nav.call("go_to", place="living_room"))
    assert len(lows(bat)) == 1


@pytest.mark.parametrize("battery, message", [
    ({"levle": 10}, r"w.yaml:\d+:\d+: battery.levle: unknown key \(did you mean 'level'\?\)"),
    ({"low": -1}, r"w.yaml:\d+:\d+: battery.low must be a non-negative number, got -1"),
    ({"level": 150}, r"w.yaml:\d+:\d+: battery.level and battery.low are percentages"),
    ({"dock": "garage"}, r"w.yaml:\d+:\d+: battery.dock: unknown room or place 'garage'"),
    ([1], r"w.yaml:\d+:\d+: battery must be a mapping"),
])
def test_a_bad_battery_is_an_error_naming_file_and_key(tmp_path, battery, message):
    path = tmp_path / "w.yaml"
    import yaml

    path.write_text(yaml.safe_dump({"battery": battery}))
    with pytest.raises(WorldError, match=message):
        World.load(str(path))


# scheduled events -----------------------------------------------------------------------------------
@pytest.mark.parametrize("events, message", [
    ([{"at": 1, "event": "vision.lostPersn", "params": {"person": "Ana"}}],
     r"w.yaml:\d+:\d+: events\[0\].event: 'vision.lostPersn' is not an event of the simulated robot \(did you mean "
     r"'vision.lostPerson'\?\)"),
    ([{"at": 1, "event": "vision.lostPerson", "params": {"persn": "Ana"}}],
     r"w.yaml:\d+:\d+: events\[0\].params: vision event lostPerson: unknown event param 'persn'"),
    ([{"at": 1, "event": "battery.low", "params": {"percentage": "low"}}],
     r"w.yaml:\d+:\d+: events\[0\].params: battery event low: event param 'percentage'"),
    ([{"event": "battery.low", "params": {"percentage": 3}}], r"w.yaml:\d+:\d+: events\[0\].at must be a non-negative"),
    ([{"at": 1, "event": "battery.low", "when": 3}], r"w.yaml:\d+:\d+: events\[0\]: unknown key 'when'"),
    ({"at": 1}, r"w.yaml:\d+:\d+: events must be a list"),
])
def test_a_bad_scheduled_event_is_an_error_naming_file_and_key(tmp_path, capsys, events, message):
    import yaml

    path = tmp_path / "w.yaml"
    path.write_text(yaml.safe_dump({"events": events}))
    with pytest.raises(WorldError, match=message):
        World.load(str(path))
    # bmtree run says so before anything starts: exit 2
    assert main(["run", "--sim", "--world", str(path), "%s/find_apple.yaml" % TREES]) == 2
    assert re.search(r"error: --world %s:\d+:\d+: events" % re.escape(str(path)), capsys.readouterr().err)


def test_a_scheduled_event_is_emitted_by_its_module_at_its_time_from_the_start(sim_defs):
    w = world(events=[{"at": 0.3, "event": "vision.lostPerson", "params": {"person": "Ana"}},
                      {"at": 0.1, "event": "battery.low", "params": {"percentage": 12.5}}])
    vis = Served(sim_defs["vision"], Vision(w))
    bat = Served(sim_defs["battery"], Battery(w))
    start = time.monotonic()
    vis.server.impl._start()
    bat.server.impl._start()
    until(lambda: vis.events and bat.events, timeout=3.0)
    assert time.monotonic() - start >= 0.3
    assert [(e.event, e.values["person"].data) for e in vis.events] == [("lostPerson", "Ana")]
    assert lows(bat) == [12.5]


# the README's patterns on the simulated robot ---------------------------------------------------------
class SimTransport(InProcessTransport):
    """The simulated robot's modules (one robot state) served by the real runtime in this process."""

    def __init__(self, definitions, w):
        super().__init__(Mocks(definitions), RealClock())
        state = RobotState(w.start, *w.rooms[w.start])
        self.impls = {name: cls(w, state) for name, cls in SIM_CLASSES.items()}
        self.servers = {name: ModuleServer(definitions[name], impl, self._on_result, self._on_event, cancel_grace=0.5)
                        for name, impl in self.impls.items()}

    def connect(self, deliver):
        self._deliver = deliver
        for impl in self.impls.values():
            impl._start()


def run_on_sim(tmp_path, sim_defs, text, w):
    path = tmp_path / "t.yaml"
    path.write_text(text)
    transport = SimTransport(sim_defs, w)
    ctx = RunContext(transport, RealClock(), sim_defs)
    return TreeRunner(build_tree(load_tree(str(path), sim_defs), ctx), ctx).run(30.0), transport


def test_the_event_pattern_halts_the_drive_when_the_battery_falls_low_midway(tmp_path, sim_defs):
    # kitchen: ~8.2 m at 4 m/s, ~2 s; low after 1 m
    w = world(speed=4.0, battery={"level": 21, "drain_per_metre": 1.0, "low": 20})
    result, transport = run_on_sim(tmp_path, sim_defs, EVENT, w)
    assert not result.succeeded and result.reason == "fail: battery low", result.reason
    (drive,) = [c for c in result.calls if c.target == "navigation.go_to"]
    assert drive.status.value == "halted" and result.duration < 1.5
    state = transport.impls["navigation"].state
    assert 0.9 < state.odometer < 4.0 and state.room == "entrance"   # stopped on the way
    result, _ = run_on_sim(tmp_path, sim_defs, EVENT, world(speed=8.0))   # the default battery: it arrives
    assert result.succeeded, result.reason


def test_the_polled_pattern_halts_the_drive_once_the_level_read_is_low(tmp_path, sim_defs):
    w = world(speed=2.0, battery={"level": 30, "drain_per_metre": 5.0, "low": 20})  # 20 % after 2 m, 1 s
    result, transport = run_on_sim(tmp_path, sim_defs, POLL, w)
    assert not result.succeeded and result.reason.startswith("check battery > 20: battery > 20 is false"), \
        result.reason
    (drive,) = [c for c in result.calls if c.target == "navigation.go_to"]
    assert drive.status.value == "halted" and result.duration < 3.5
    assert transport.impls["navigation"].state.room == "entrance"
    result, _ = run_on_sim(tmp_path, sim_defs, POLL, world(speed=8.0))
    assert result.succeeded, result.reason


class _MasterGone:
    """rospy's parameter calls with the ROS master away (killed, its machine unreachable)."""

    def set_param(self, name, value):
        raise ConnectionRefusedError(111, "the ROS master did not answer")

    def get_param(self, name, default=None):
        raise ConnectionRefusedError(111, "the ROS master did not answer")


def test_the_simulated_robot_drives_on_while_the_master_is_away(sim_defs):
    """Rehearsing a master fault on the simulator: navigation shares the robot's state through the parameter
    server, and every go_to failed with ConnectionRefusedError (robot.py in _drive), as if the module
    were broken; it goes on with its own state, as a robot's drivers would, and says so in its log."""
    from tests.conftest import log_records

    w = world(speed=100.0)
    nav, bat = served(sim_defs, w)
    nav.server.impl._rospy = bat.server.impl._rospy = _MasterGone()
    with log_records("bmtree.module", logging.WARNING) as said:
        assert nav.result(nav.call("go_to", place="kitchen")).status == "succeeded"
        assert nav.result(nav.call("go_to", place="living_room")).status == "succeeded"
        assert bat.result(bat.call("level")).status == "succeeded"
    away = [r.getMessage() for r in said if "the ROS master does not answer" in r.getMessage()]
    # once per module (navigation wrote four times, the battery read twice), not once per write
    assert len(away) == 2 and "not shared with the other simulated modules until it does" in away[0], away
