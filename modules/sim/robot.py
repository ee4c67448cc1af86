"""The simulated modules: navigation, vision and speech over a :class:`World`.

Each runs as its own node. Navigation writes the robot's room to the ROS parameter
``/sim/robot_room`` before it answers, and the others read it when a call needs it: the
master orders the two, so a call made after navigation answered always sees the new room
(a topic would not: ROS orders messages per connection, not across topics). The same goes for
the distance driven (``/sim/odometer``, for the battery; also published on the topic of that name
while driving, so the battery drains midway) and the place the robot stands at (``/sim/robot_at``).

A module emits the world's scheduled ``events`` of its own from :meth:`SimModule._start`: as a node,
once its events have a listener (the coordinator: in practice the run's start); in process, when
whoever serves it calls ``_start()``.
"""
from __future__ import annotations

import logging
import math
import threading
import time
from typing import Any, Callable, Dict, List, Optional

from comm.saylimit import SayLimit
from modules.outcome import Outcome
from modules.runtime import BasicModule, Failure
from modules.sim.world import Fault, ScheduledEvent, World
from modules.sim.worldfile import MAX_SECONDS

__all__ = ["SimModule", "RobotState", "Navigation", "Vision", "Speech", "ROOM_PARAM", "SAID_TOPIC",
           "ODOMETER_PARAM", "ODOMETER_TOPIC", "AT_PARAM"]

ROOM_PARAM = "/sim/robot_room"
SAID_TOPIC = "/sim/speech/said"
ODOMETER_PARAM = ODOMETER_TOPIC = "/sim/odometer"   # metres driven since navigation started
AT_PARAM = "/sim/robot_at"   # the room or place the robot stands at ("" while driving or after a halted drive)

log = logging.getLogger("bmtree.module")


class RobotState:
    """Where the robot is, shared in-process (unit tests) or mirrored from ROS; ``listeners`` are
    called (without the lock) after each stretch :meth:`moved` adds to the odometer."""

    def __init__(self, room: str, x: float, y: float):
        self.room, self.x, self.y = room, x, y
        self.at = room
        self.odometer = 0.0
        self.lock = threading.Lock()
        self.listeners: List[Callable[[], None]] = []

    def moved(self, x: float, y: float) -> float:
        """The robot drove to (x, y): its position and odometer (returned) change; listeners are told."""
        with self.lock:
            self.odometer += math.hypot(x - self.x, y - self.y)
            self.x, self.y, self.at = x, y, ""
            odometer = self.odometer
        for listener in list(self.listeners):
            listener()
        return odometer


class SimModule(BasicModule):
    """Common part of the simulated modules: the world, the robot state, fault injection."""

    module_name = ""

    def __init__(self, world: Optional[World] = None, state: Optional[RobotState] = None):
        super().__init__()
        self.world = world or World.load()
        x, y = self.world.rooms[self.world.start]
        self.state = state or RobotState(self.world.start, x, y)
        self.faults: Dict[str, Fault] = {}
        self._rospy: Any = None  # set in setup(): the room then comes from the parameter server
        self._say = SayLimit()    # a master away is said once, then at most every few seconds
        prefix = self.module_name + "."
        for key, fault in self.world.faults.items():
            if key.startswith(prefix):
                self.faults[key[len(prefix):]] = fault

    def _share(self, *params: Any) -> None:
        """Set ``(name, value)`` pairs on the parameter server, where the other simulated modules read the
        robot's state. With the master away (a rehearsed master fault) the call goes on with this
        process's own state, as a real robot's drivers would; the next write after it is back shares it."""
        try:
            for name, value in params:
                self._rospy.set_param(name, value)
        except OSError as exc:
            self._master_away(exc)

    def _shared(self, name: str, default: Any) -> Any:
        """A parameter another simulated module set; ``default`` with the master away."""
        try:
            return self._rospy.get_param(name, default)
        except OSError as exc:
            self._master_away(exc)
            return default

    def _master_away(self, exc: OSError) -> None:
        more = self._say.due("master away")
        if more is not None:
            log.warning("the ROS master does not answer (%s): the simulated robot's state is not shared with the "
                        "other simulated modules until it does%s", exc, more)

    def before_call(self, function: str, inputs: Dict[str, Any]) -> Optional[Outcome]:
        """An injected fault's outcome replaces the function's answer (the runtime carries it out)."""
        fault = self.faults.get(function)
        if fault is None or not fault.take():
            return None
        return fault.answer("%s.%s" % (self.definition.name, function), self.context.call_id)

    def setup(self, node: Any) -> None:
        import rospy

        self._rospy = rospy  # the node's own ~faults are applied by the module node, as for any module
        publisher = getattr(node, "event_publisher", None)
        if publisher is None:
            self._start()
            return

        def start_when_heard() -> None:  # an event emitted before anyone listens is lost
            while publisher.get_num_connections() < 1 and not rospy.is_shutdown():
                time.sleep(0.02)
            if not rospy.is_shutdown():
                self._start()

        threading.Thread(target=start_when_heard, name="%s-events" % self.module_name, daemon=True).start()

    def _start(self) -> None:
        """Schedule this module's events of the world's ``events`` on the module's clock, from now."""
        assert self._server is not None, "module not bound to a server"
        for ev in self.world.events:
            if ev.module == self.module_name:
                self._server.scheduler.call_later(ev.at, lambda ev=ev: self._emit_scheduled(ev))

    def _emit_scheduled(self, ev: ScheduledEvent) -> None:
        log.info("the world's scheduled event %s (at %g s): %s", ev.qualified, ev.at, ev.params)
        self.emit(ev.name, **ev.params)

    def _here(self) -> str:
        if self._rospy is not None and not isinstance(self, Navigation):
            loc = self.world.locate(str(self._shared(ROOM_PARAM, "")))
            if loc:
                with self.state.lock:
                    self.state.room, self.state.x, self.state.y = loc
        with self.state.lock:
            return self.state.room


class Navigation(SimModule):
    """Drives between places; time = distance / speed, cancellable midway."""

    module_name = "navigation"
    step = 0.02

    def __init__(self, world: Optional[World] = None, state: Optional[RobotState] = None):
        super().__init__(world, state)
        self._odometer_pub: Any = None

    def setup(self, node: Any) -> None:
        from std_msgs.msg import Float64

        super().setup(node)
        self._odometer_pub = self._rospy.Publisher(ODOMETER_TOPIC, Float64, queue_size=100)
        with self.state.lock:
            odometer, at = self.state.odometer, self.state.at
        self._rospy.set_param(ODOMETER_PARAM, odometer)
        self._rospy.set_param(AT_PARAM, at)
        self._rospy.set_param(ROOM_PARAM, self._here())
        from comm.masterwatch import watch_master

        watch = watch_master()   # a restarted master knows no room: vision would look in its own stale one
        for param, now in ((ROOM_PARAM, self._here), (ODOMETER_PARAM, lambda: self.state.odometer),
                           (AT_PARAM, lambda: self.state.at)):
            watch.keep_param(param, now)

    def shutdown(self) -> None:
        if self._rospy is not None:  # a later graph on this master must not see a stale room
            for param in (ROOM_PARAM, ODOMETER_PARAM, AT_PARAM):
                try:
                    self._rospy.delete_param(param)
                except (KeyError, OSError):
                    pass
        super().shutdown()

    def _drive(self, x: float, y: float) -> bool:
        ctx = self.context
        with self.state.lock:
            x0, y0 = self.state.x, self.state.y
        total = self.world.travel_time((x0, y0), (x, y))
        if not total <= MAX_SECONDS:  # NaN or a target far beyond any house: never a drive for ever
            raise Failure("cannot drive to (%g, %g): it would take %g s (at most %d)" % (x, y, total, MAX_SECONDS))
        steps = max(1, int(total / self.step))
        try:
            for i in range(1, steps + 1):
                if not ctx.sleep(total / steps):
                    return False
                odometer = self.state.moved(x0 + (x - x0) * i / steps, y0 + (y - y0) * i / steps)
                if self._odometer_pub is not None:
                    from std_msgs.msg import Float64

                    self._odometer_pub.publish(Float64(odometer))
            return True
        finally:
            if self._rospy is not None:  # before the answer, so the battery's next reading counts it
                with self.state.lock:
                    odometer, at = self.state.odometer, self.state.at
                self._share((ODOMETER_PARAM, odometer), (AT_PARAM, at))

    def _where(self) -> Dict[str, Any]:
        with self.state.lock:
            return {"room": self.state.room, "position": {"x": self.state.x, "y": self.state.y, "z": 0.0}}

    def go_to(self, place: Any) -> Dict[str, Any]:
        loc = self.world.locate(place.data)
        if loc is None:
            raise Failure("unknown place %r (known: %s)" % (
                place.data, ", ".join(sorted(list(self.world.rooms) + list(self.world.places)))))
        room, x, y = loc
        if not self._drive(x, y):
            return self._where()
        with self.state.lock:
            self.state.room, self.state.at = room, place.data
        if self._rospy is not None:  # before the answer, so the next call sees it
            self._share((ROOM_PARAM, room), (AT_PARAM, place.data))
        self.emit("arrived", place=place.data)
        return dict(self._where(), success=True)

    def approach(self, target: Any) -> Dict[str, Any]:
        if not self._drive(target.x - 0.5, target.y):
            return dict(self._where(), success=False)
        return {"success": True, "position": self._where()["position"]}

    def where_am_i(self) -> Dict[str, Any]:
        return self._where()


class Vision(SimModule):
    """Finds objects and people, but only those in the robot's current room."""

    module_name = "vision"

    def find_object(self, object: Any) -> Dict[str, Any]:  # noqa: A002 - the definition's name
        room = self._here()
        thing = self.world.objects.get(object.data)
        if thing is None or thing.room != room:
            return {"success": False, "position": {}, "room": room}
        return {"success": True, "position": {"x": thing.x, "y": thing.y, "z": thing.z}, "room": room}

    def find_person(self, name: Any) -> Dict[str, Any]:
        room = self._here()
        for person in self.world.people.values():
            if person.room == room and (not name.data or name.data == person.name):
                position = {"x": person.x, "y": person.y, "z": 0.0}
                self.emit("personSeen", person=person.name, position=position)
                return {"success": True, "person": person.name, "position": position}
        return {"success": False, "person": "", "position": {}}


class Speech(SimModule):
    """Says sentences (recorded in ``said`` and on ``/sim/speech/said``); listens to scripted answers."""

    module_name = "speech"

    def __init__(self, world: Optional[World] = None, state: Optional[RobotState] = None):
        super().__init__(world, state)
        self.said: List[str] = []
        self._heard: Dict[str, int] = {}
        self._said_pub: Any = None

    def setup(self, node: Any) -> None:
        import rospy
        from std_msgs.msg import String

        super().setup(node)
        self._said_pub = rospy.Publisher(SAID_TOPIC, String, queue_size=100, latch=False)

    def say(self, text: Any) -> Dict[str, Any]:
        self.said.append(text.data)
        log.info("says %r", text.data)   # what the robot said, in bm_speech.out of a --sim run
        if self._said_pub is not None:
            from std_msgs.msg import String

            self._said_pub.publish(String(text.data))
        return {"success": True}

    def listen(self, seconds: Any) -> Dict[str, Any]:
        room = self._here()
        for person in self.world.people.values():
            if person.room == room and person.answers:
                i = self._heard.get(person.name, 0)
                self._heard[person.name] = i + 1
                heard = person.answers[min(i, len(person.answers) - 1)]
                log.info("hears %s say %r", person.name, heard)
                return {"success": True, "text": heard}
        self.context.sleep(min(float(seconds.data), 0.2))
        log.info("hears nobody in %s", room)
        return {"success": False, "text": ""}

