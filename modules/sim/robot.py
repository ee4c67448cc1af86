"""The simulated modules: navigation, vision and speech over a :class:`World`.

Each runs as its own node. Navigation writes the robot's room to the ROS parameter
``/sim/robot_room`` before it answers, and the others read it when a call needs it: the
master orders the two, so a call made after navigation answered always sees the new room
(a topic would not: ROS orders messages per connection, not across topics).
"""
from __future__ import annotations

import threading
from typing import Any, Dict, List, Optional

from modules.outcome import Outcome
from modules.runtime import BasicModule, Failure
from modules.sim.world import Fault, World

__all__ = ["SimModule", "Navigation", "Vision", "Speech", "SIM_CLASSES", "ROOM_PARAM", "SAID_TOPIC"]

ROOM_PARAM = "/sim/robot_room"
SAID_TOPIC = "/sim/speech/said"


class RobotState:
    """Where the robot is, shared in-process (unit tests) or mirrored from ROS."""

    def __init__(self, room: str, x: float, y: float):
        self.room, self.x, self.y = room, x, y
        self.lock = threading.Lock()


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
        prefix = self.module_name + "."
        for key, fault in self.world.faults.items():
            if key.startswith(prefix):
                self.faults[key[len(prefix):]] = fault

    def before_call(self, function: str, inputs: Dict[str, Any]) -> Optional[Outcome]:
        """An injected fault's outcome replaces the function's answer (the runtime carries it out)."""
        fault = self.faults.get(function)
        if fault is None or not fault.take():
            return None
        return fault.answer("%s.%s" % (self.definition.name, function), self.context.call_id)

    def setup(self, node: Any) -> None:
        import rospy

        self._rospy = rospy  # the node's own ~faults are applied by the module node, as for any module

    def _here(self) -> str:
        if self._rospy is not None and not isinstance(self, Navigation):
            loc = self.world.locate(str(self._rospy.get_param(ROOM_PARAM, "")))
            if loc:
                with self.state.lock:
                    self.state.room, self.state.x, self.state.y = loc
        with self.state.lock:
            return self.state.room


class Navigation(SimModule):
    """Drives between places; time = distance / speed, cancellable midway."""

    module_name = "navigation"
    step = 0.02

    def setup(self, node: Any) -> None:
        super().setup(node)
        self._rospy.set_param(ROOM_PARAM, self._here())

    def shutdown(self) -> None:
        if self._rospy is not None:  # a later graph on this master must not see a stale room
            try:
                self._rospy.delete_param(ROOM_PARAM)
            except (KeyError, OSError):
                pass
        super().shutdown()

    def _drive(self, x: float, y: float) -> bool:
        ctx = self.context
        with self.state.lock:
            x0, y0 = self.state.x, self.state.y
        total = self.world.travel_time((x0, y0), (x, y))
        steps = max(1, int(total / self.step))
        for i in range(1, steps + 1):
            if not ctx.sleep(total / steps):
                return False
            with self.state.lock:
                self.state.x = x0 + (x - x0) * i / steps
                self.state.y = y0 + (y - y0) * i / steps
        return True

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
            self.state.room = room
        if self._rospy is not None:  # before the answer, so the next call sees it
            self._rospy.set_param(ROOM_PARAM, room)
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
                return {"success": True, "text": person.answers[min(i, len(person.answers) - 1)]}
        self.context.sleep(min(float(seconds.data), 0.2))
        return {"success": False, "text": ""}


SIM_CLASSES = {"navigation": Navigation, "vision": Vision, "speech": Speech}
