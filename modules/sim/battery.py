"""The simulated battery: drains with the distance navigation drives (and with time), emits ``low``.

The world's ``battery:`` gives its start ``level``, ``drain_per_metre``, ``drain_per_second``, the
``low`` threshold, ``charge_per_second`` and the ``dock`` where ``charge`` works (see
:class:`~modules.sim.world.BatterySpec`). In one process (unit tests) it shares navigation's
:class:`~modules.sim.robot.RobotState` and drains as the state moves; as a node it hears the
distance on ``/sim/odometer`` while navigation drives and reads the parameter of that name (set
before navigation answers) when asked, so a reading after a drive always counts the whole drive.

``low`` is emitted when the level falls to ``low`` or below, once; again only after it rose above
(charging). A battery that starts at or below ``low`` emits it the first time it drains.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Dict, Optional

from modules.runtime import Failure
from modules.sim.robot import AT_PARAM, ODOMETER_PARAM, ODOMETER_TOPIC, RobotState, SimModule
from modules.sim.world import World
from modules.sim.worldfile import number

__all__ = ["Battery"]


def _metres(value: Any) -> Optional[float]:
    """A distance driven as navigation gives it (a finite number, 0 or more), else None."""
    return number(value, 0.0, float("inf"))


class Battery(SimModule):
    """The charge left, in percent; see the module's docstring."""

    module_name = "battery"
    tick = 0.1   # seconds between time-drain checks (only with drain_per_second)
    step = 0.05  # seconds between charge increments

    def __init__(self, world: Optional[World] = None, state: Optional[RobotState] = None):
        super().__init__(world, state)
        self.spec = self.world.battery
        self._lock = threading.Lock()
        self._level = self.spec.level
        with self.state.lock:
            self._odometer = self.state.odometer  # metres already counted
        self._since: Optional[float] = None        # the clock's time of the last time drain
        self._below = False                        # low was emitted and the level has not risen above since
        self._charging = False
        self.state.listeners.append(self._update)

    # -- the level ---------------------------------------------------------------------------------
    def _now(self) -> float:
        return self._server.scheduler.now() if self._server is not None else time.monotonic()

    def _update(self) -> float:
        """Drain by the distance driven and the time passed since the last update; emit ``low`` when the
        level falls to the threshold. The level."""
        with self.state.lock:
            odometer = self.state.odometer
        now = self._now()
        fell: Optional[float] = None
        with self._lock:
            before = self._level
            drain = self.spec.drain_per_metre * max(0.0, odometer - self._odometer)
            if self._since is not None and not self._charging:
                drain += self.spec.drain_per_second * max(0.0, now - self._since)
            self._odometer = max(self._odometer, odometer)
            self._since = now
            self._level = level = max(0.0, before - drain)
            if level > self.spec.low:
                self._below = False
            elif level < before and not self._below:
                self._below = True
                fell = level
        if fell is not None and self._server is not None:
            self.emit("low", percentage=fell)
        return level

    def _heard_odometer(self, msg: Any) -> None:
        metres = _metres(getattr(msg, "data", None))
        if metres is None:  # not navigation's: a NaN or an infinity would drain the battery for good
            return
        with self.state.lock:
            self.state.odometer = max(self.state.odometer, metres)
        self._update()

    def _mirror(self) -> None:
        """As a node: the distance and the place from the parameters navigation sets before it answers."""
        if self._rospy is None:
            return
        odometer = self._shared(ODOMETER_PARAM, 0.0)
        at = self._shared(AT_PARAM, None)
        with self.state.lock:
            self.state.odometer = max(self.state.odometer, _metres(odometer) or 0.0)
            if at is not None:
                self.state.at = str(at)

    def _tick(self) -> None:
        self._update()
        assert self._server is not None
        self._server.scheduler.call_later(self.tick, self._tick)

    # -- the node ----------------------------------------------------------------------------------
    def setup(self, node: Any) -> None:
        from std_msgs.msg import Float64

        super().setup(node)
        self._rospy.Subscriber(ODOMETER_TOPIC, Float64, self._heard_odometer, queue_size=100)

    def _start(self) -> None:
        super()._start()
        self._update()  # time drains from now
        if self.spec.drain_per_second > 0:
            assert self._server is not None
            self._server.scheduler.call_later(self.tick, self._tick)

    # -- the functions -----------------------------------------------------------------------------
    def level(self) -> Dict[str, Any]:
        self._mirror()
        level = self._update()
        with self._lock:
            charging = self._charging
        return {"percentage": level, "charging": charging}

    def charge(self) -> Dict[str, Any]:
        self._mirror()
        with self.state.lock:
            at = self.state.at
        if at != self.spec.dock:
            raise Failure("not at the dock (%s): the robot is %s" % (
                self.spec.dock, "at %s" % at if at else "between places"))
        level = self._update()
        ctx = self.context
        with self._lock:
            self._charging = True
        try:
            while level < 100.0:
                if not ctx.sleep(self.step):
                    return {"success": False, "percentage": level}
                with self._lock:
                    self._level = level = min(100.0, self._level + self.spec.charge_per_second * self.step)
                    if level > self.spec.low:
                        self._below = False
            return {"success": True, "percentage": level}
        finally:
            with self._lock:
                self._charging = False
                self._since = self._now()  # no time drain while it charged
