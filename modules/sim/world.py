"""The simulated house: rooms, places, objects, people, and injected faults."""
from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

from comm.errors import did_you_mean
from modules.outcome import Outcome, OutcomeError, OutcomeKind, fail, outcome_from_dict
from modules.sim.worldfile import (
    DEFAULT_WORLD,
    MAX_RATE,
    MAX_SECONDS,
    MAX_TIMES,
    MIN_SPEED,
    WHOLE,
    Problems,
    WorldError,
    coordinates,
    default_data,
    is_text,
    name_of,
    number,
    read_world,
    shown,
)

__all__ = ["World", "WorldError", "DEFAULT_WORLD", "Fault", "INJECTED", "describe_faults", "BatterySpec",
           "ScheduledEvent"]

#: ends the answer of every injected fault: on the tree's side it looks like the hardware's own failure otherwise
INJECTED = " (injected fault)"
#: the text of ``crash: true``
CRASH_TEXT = "injected crash"

log = logging.getLogger("bmtree.module")

_default_data = default_data  # the default house's top-level keys (as from_dict's base)



def _crash(text: str) -> Any:
    """A crash answers as a method that raised RuntimeError would, but raises nothing: a traceback
    through the runtime and this file would send the module's author looking for a bug of theirs."""
    def crash(**inputs: Any) -> Any:
        return fail("RuntimeError: %s%s" % (text, INJECTED))
    return crash


def _crashis_text(value: Any) -> str:
    return CRASH_TEXT if value is True or value is None or value == "" else str(value)


_WORLD_KEYS = ("rooms", "places", "objects", "people", "start", "speed", "faults", "battery", "events")


def _sim_functions() -> List[str]:
    """``module.function`` of every simulated module (the keys ``faults`` may have)."""
    from modules.definition import load_definitions

    defs = load_definitions([os.path.dirname(os.path.abspath(__file__))])
    return sorted(fn.qualified for d in defs.values() for fn in d.functions.values())


def _sim_events() -> Dict[str, Any]:
    """``module.event`` -> its EventDefinition, of every simulated module (what ``events`` may emit)."""
    from modules.definition import load_definitions

    defs = load_definitions([os.path.dirname(os.path.abspath(__file__))])
    return {"%s.%s" % (d.name, e.name): e for d in defs.values() for e in d.events.values()}


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


@dataclass
class Fault:
    """An outcome that replaces a function's own answer, for ``times`` calls (None: all).

    Written ``{fail: reason}``, ``{reject: reason}``, ``{hang: true}``, ``{crash: text}`` (the
    function raises), ``{die: reason}`` (the node's process is killed mid-call) or ``{delay: s}``
    alone (the function answers, ``s`` seconds late); ``delay`` also delays the others. It is the testing kit's outcome type, carried out by the runtime.
    """

    outcome: Outcome
    times: Optional[int] = None
    what: str = ""  # as written, for the module's log: "fail 'wheel motor overheated' after 2 s"

    @classmethod
    def parse(cls, key: str, raw: Any, problems: Optional[Problems] = None, where: Any = None) -> Optional[Fault]:
        """The fault ``raw`` of function ``key``; WorldError naming every problem, or with ``problems``
        they are added there (then None). ``where``: the mapping holding ``raw`` (its position)."""
        own = problems is None
        found = Problems(None) if problems is None else problems
        before = len(found.lines)
        fault = cls._parse(key, raw, found, where)
        if own:
            found.check()
        return fault if len(found.lines) == before else None

    @classmethod
    def _parse(cls, key: str, raw: Any, problems: Problems, where: Any) -> Optional[Fault]:
        if not isinstance(raw, dict):
            problems.add("faults.%s must be a mapping (%s)" % (key, ", ".join(_FAULT_KEYS)), where, key)
            return None
        before = len(problems.lines)
        for k in raw:
            if k not in _FAULT_KEYS:
                problems.add("faults.%s: unknown keys %s (use %s)" % (key, k, ", ".join(_FAULT_KEYS)), raw, k, True)
        times = raw.get("times")
        if times is not None and (isinstance(times, bool) or not isinstance(times, int) or not 0 <= times <= MAX_TIMES):
            problems.add("faults.%s.times must be a whole number from 0 to %d, got %s" % (key, MAX_TIMES, shown(times)),
                         raw, "times")
        delay = number(raw.get("delay", 0.0), 0.0, MAX_SECONDS)
        if delay is None:
            problems.add("faults.%s.delay must be a number of seconds from 0 to %d (a day), got %s" % (
                key, MAX_SECONDS, shown(raw.get("delay"))), raw, "delay")
        for k in ("fail", "reject", "crash", "die"):
            if k in raw and not is_text(raw[k]):
                problems.add("faults.%s.%s must be a text (the reason), got %s" % (key, k, shown(raw[k])), raw, k)
        if len(problems.lines) > before or delay is None:
            return None
        spec = {k: v for k, v in raw.items() if k != "times" and not (k in ("hang", "crash", "die") and v is False)}
        later = " after %g s" % delay if delay else ""
        if "crash" in spec:
            if len(spec) > (2 if "delay" in spec else 1):
                problems.add("faults.%s: crash goes alone (with delay, times)" % key, where, key)
                return None
            text = _crashis_text(spec["crash"])
            return cls(Outcome(OutcomeKind.RESPOND, fn=_crash(text), delay=delay), times,
                       ("crash" if text == CRASH_TEXT else "crash %r" % text) + later)
        if set(spec) <= {"delay"}:
            return cls(Outcome(OutcomeKind.RESPOND, delay=delay), times, "delay %g s" % delay)
        for kind, default in (("fail", "failed"), ("reject", "rejected")):
            if kind in spec and (spec[kind] is True or spec[kind] is None or spec[kind] == ""):
                spec[kind] = default  # not "True" (injected fault)
        spec["delay"] = delay
        try:
            outcome = outcome_from_dict(spec)
        except OutcomeError as exc:
            problems.add("faults.%s: %s" % (key, exc), where, key)
            return None
        if outcome.kind in (OutcomeKind.FAIL, OutcomeKind.REJECT):
            what = "%s %r" % (outcome.kind.value, outcome.reason)
            outcome.reason += INJECTED
        elif outcome.kind == OutcomeKind.DIE and isinstance(spec.get("die"), str) and spec["die"]:
            what = "die %r" % spec["die"]   # why it died, as the world says, in the line that lists the faults
        else:
            what = outcome.kind.value
        return cls(outcome, times, what + later)

    def answer(self, target: str, call_id: Optional[str]) -> Outcome:
        """The outcome for call ``call_id`` of ``target`` (taken), noted in the module's log."""
        log.info("call %s of %s: an injected fault answers (%s)", call_id, target, self.what)
        return self.outcome

    def take(self) -> bool:
        """True if this fault applies to the next call (and count it)."""
        if self.times is None:
            return True
        if self.times <= 0:
            return False
        self.times -= 1
        return True


_FAULT_KEYS = ("fail", "reject", "crash", "hang", "die", "delay", "times")


def describe_faults(module: str, faults: Dict[str, Fault]) -> str:
    """``faults injected: navigation.go_to: fail 'wheel motor overheated' ×5; …`` for a module's log at
    start-up ("" for none): its answers would otherwise pass for the hardware's own failures."""
    if not faults:
        return ""
    return "faults injected: " + "; ".join("%s.%s: %s%s" % (module, fn, f.what, "" if f.times is None else " ×%d" % f.times)
                                           for fn, f in sorted(faults.items()))


@dataclass
class Thing:
    name: str
    room: str
    x: float
    y: float
    z: float = 0.0
    answers: List[str] = field(default_factory=list)


@dataclass
class BatterySpec:
    """The world's ``battery:`` (percentages 0-100); a key left out takes the default here."""

    level: float = 100.0            # at start
    drain_per_metre: float = 0.1    # per metre navigation drives
    drain_per_second: float = 0.0   # per second of time (not while charging)
    low: float = 20.0               # battery.low is emitted when the level falls to it or below
    charge_per_second: float = 10.0
    dock: str = ""                  # where battery.charge works: a room or place ("": the start room)

    @classmethod
    def parse(cls, raw: Any, source: str, problems: Optional[Problems] = None, where: Any = None) -> BatterySpec:
        """The battery ``raw``; WorldError naming every problem, or with ``problems`` they are added there
        (then the defaults stand for the bad values). ``where``: the world mapping holding it."""
        found = Problems(source) if problems is None else problems
        before = len(found.lines)
        spec = cls._parse(raw, found, where)
        if problems is None:
            found.check()
        return spec if len(found.lines) == before else cls()

    @classmethod
    def _parse(cls, raw: Any, problems: Problems, where: Any) -> BatterySpec:
        if raw is None:
            return cls()
        if not isinstance(raw, dict):
            problems.add("battery must be a mapping of %s" % ", ".join(_BATTERY_KEYS), where, "battery")
            return cls()
        values: Dict[str, Any] = {}
        for key, value in raw.items():
            if key not in _BATTERY_KEYS:
                problems.add("battery.%s: unknown key%s (battery has %s)" % (
                    key, did_you_mean(str(key), _BATTERY_KEYS), ", ".join(_BATTERY_KEYS)), raw, key, True)
            elif key == "dock":
                if not is_text(value) or isinstance(value, bool):
                    problems.add("battery.dock must be a room or place, got %s" % shown(value), raw, key)
                else:
                    values[key] = "" if value is None else str(value)
            else:
                percent = key in ("level", "low")
                amount = number(value, 0.0, 100.0 if percent else MAX_RATE)
                if amount is None and percent and number(value, 0.0, float("inf")) is not None:
                    problems.add("battery.level and battery.low are percentages (0-100), got %s: %s" % (
                        key, shown(value)), raw, key)
                elif amount is None:
                    problems.add("battery.%s must be a non-negative number%s, got %s" % (
                        key, "" if percent else " (at most %g)" % MAX_RATE, shown(value)), raw, key)
                else:
                    values[key] = amount
        return cls(**values)


_BATTERY_KEYS = ("level", "drain_per_metre", "drain_per_second", "low", "charge_per_second", "dock")


@dataclass
class ScheduledEvent:
    """One entry of the world's ``events:``: ``module.event`` emitted ``at`` seconds after its module
    started emitting (its node heard its first listener: in practice the run's start)."""

    at: float
    module: str
    name: str
    params: Dict[str, Any] = field(default_factory=dict)

    @property
    def qualified(self) -> str:
        return "%s.%s" % (self.module, self.name)


_EVENT_KEYS = ("at", "event", "params")


def _parse_events(raw: Any, problems: Problems, where: Any) -> List[ScheduledEvent]:
    """The world's ``events:``, each checked against its simulated module's definition."""
    if raw is None:
        return []
    if not isinstance(raw, list):
        problems.add("events must be a list of {at: seconds, event: module.event, params: {...}}", where, "events")
        return []
    known = _sim_events()
    out = []
    for i, entry in enumerate(raw):
        path = "events[%d]" % i
        if not isinstance(entry, dict):
            problems.add("%s must be a mapping {at: seconds, event: module.event, params: {...}}" % path, raw, i)
            continue
        before = len(problems.lines)
        for k in entry:
            if k not in _EVENT_KEYS:
                problems.add("%s: unknown key %r%s (an event has at, event, params)" % (
                    path, str(k), did_you_mean(str(k), _EVENT_KEYS)), entry, k, True)
        at = number(entry.get("at"), 0.0, MAX_SECONDS)
        if at is None:
            problems.add("%s.at must be a non-negative number of seconds (at most %d, a day), got %s" % (
                path, MAX_SECONDS, shown(entry.get("at"))), entry, "at" if "at" in entry else WHOLE)
        name = entry.get("event", "")
        ev = known.get(name) if isinstance(name, str) else None
        if ev is None:
            name = str(name)
            problems.add("%s.event: %r is not an event of the simulated robot%s (its events: %s)" % (
                path, name[:60], did_you_mean(name, sorted(known)), ", ".join(sorted(known))), entry,
                "event" if "event" in entry else WHOLE)
        params = entry.get("params") or {}
        if not isinstance(params, dict):
            problems.add("%s.params must be a mapping of the event's parameters" % path, entry, "params")
        elif ev is not None:
            try:
                ev.build_values(params)
            except (ValueError, TypeError, OverflowError) as exc:
                problems.add("%s.params: %s" % (path, exc), entry, "params")
        if len(problems.lines) == before and at is not None and ev is not None:
            module, event = name.split(".", 1)
            out.append(ScheduledEvent(at, module, event, dict(params)))
    return out


_THING_KEYS = ("room", "x", "y", "z", "answers")


@dataclass
class World:
    rooms: Dict[str, Tuple[float, float]]
    places: Dict[str, Thing]
    objects: Dict[str, Thing]
    people: Dict[str, Thing]
    start: str
    speed: float = 1.0
    faults: Dict[str, Fault] = field(default_factory=dict)
    written_faults: Dict[str, Any] = field(default_factory=dict)  # as the file writes them (for other nodes)
    battery: BatterySpec = field(default_factory=BatterySpec)
    events: List[ScheduledEvent] = field(default_factory=list)

    def faults_of(self, module: str) -> Dict[str, Any]:
        """The faults of ``module``'s functions, as written, by function name (for its node's ``~faults``)."""
        prefix = module + "."
        return {k[len(prefix):]: v for k, v in self.written_faults.items() if k.startswith(prefix)}

    @classmethod
    def load(cls, path: str = DEFAULT_WORLD, others: Any = ()) -> World:
        """The world in ``path``; WorldError names every problem, each at its ``file:line:column``.
        The file is read bounded (:func:`comm.textfile.read_text`: size, devices, FIFOs; then the
        safe YAML loader's depth and node limits). Each top-level key the file leaves out is the default
        house's (``DEFAULT_WORLD``), so a file of ``faults:`` alone is the default house with those faults
        (see ``from_dict``'s ``base``). ``others``: the ``module.function`` of the user's own modules its
        faults may name too (the ``--module`` of ``bmtree run --sim``), or True for any function of a
        module that is not simulated (a simulated module's node, which knows only its own)."""
        data = read_world(path)
        if data is None:  # an empty file: the default house as it is
            data = {}
        base = None
        if not _same_file(path, DEFAULT_WORLD):
            base = default_data()
        return cls.from_dict(data, path, others, base=base)

    @classmethod
    def from_dict(cls, data: Any, source: str = "<world>", others: Any = (), base: Optional[Dict[str, Any]] = None
                  ) -> World:
        """The world ``data`` describes (``source`` names it in errors; ``others`` as in ``load``).

        ``base``: a world (the default house) whose value of each top-level key ``data`` leaves out is
        taken as it is; a key ``data`` gives replaces it whole. So ``data`` that gives ``rooms`` is a
        house of its own: the places, objects, people and start it takes from ``base`` must be in its
        rooms, and an error says which key came from ``base`` and that it must be given too.
        Every problem is found before WorldError says them all.
        """
        problems = Problems(source)
        if not isinstance(data, dict):
            problems.add("the world must be a mapping (of %s)" % ", ".join(_WORLD_KEYS), data)
            problems.check()
        for key in data:  # a misspelt key would silently leave its part of the world out
            if key not in _WORLD_KEYS:
                problems.add("unknown key %r%s (a world has %s)" % (
                    key, did_you_mean(str(key), _WORLD_KEYS), ", ".join(_WORLD_KEYS)), data, key, True)
        inherited = set()  # the top-level keys taken from base
        top = data
        if base is not None:
            inherited = {k for k in base if k not in data}
            data = dict(data, **{k: base[k] for k in inherited})

        def why(key: str) -> str:
            """What to add to an unknown-room error of ``key``: which part came from the default house."""
            if key in inherited and "rooms" not in inherited:
                return (" (%s is the default house's, %s: a world that gives rooms: must give a consistent house:"
                        " give %s: too%s)" % (key, DEFAULT_WORLD, key,
                                             "" if key == "start" else ", %s: {} for none" % key))
            if key not in inherited and "rooms" in inherited:
                return " (the rooms are the default house's, %s: give rooms: for others)" % DEFAULT_WORLD
            return ""

        def mapping(key: str, what: str) -> Dict[Any, Any]:
            value = data.get(key)
            if value is None:
                return {}
            if not isinstance(value, dict):
                problems.add("%s must be a mapping of %s" % (key, what), top, key)
                return {}
            return value

        rooms: Dict[str, Tuple[float, float]] = {}
        named = set()  # every room written with a name, usable or not: no second error for its things
        raw_rooms = mapping("rooms", "room -> {x: metres, y: metres}")
        for n, r in raw_rooms.items():
            name = name_of(problems, "rooms", n, raw_rooms)
            named.add(n)
            if not isinstance(r, dict):
                problems.add("rooms.%s must be a mapping {x: metres, y: metres}" % n, raw_rooms, n)
                continue
            for k in r:
                if k not in ("x", "y"):
                    problems.add("rooms.%s.%s: unknown key%s (a room has x, y)" % (n, k, did_you_mean(str(k), "xy")),
                                 r, k, True)
            xy = coordinates(problems, "rooms.%s" % n, r, ("x", "y"))
            if name is not None and xy is not None:
                rooms[name] = (xy["x"], xy["y"])

        def things(key: str) -> Dict[str, Thing]:
            out = {}
            raw = mapping(key, "name -> {room: ..., x: metres, y: metres}")
            for n, t in raw.items():
                name = name_of(problems, key, n, raw)
                if not isinstance(t, dict):
                    problems.add("%s.%s must be a mapping {room: ..., x: metres, y: metres}" % (key, n), raw, n)
                    continue
                for k in t:
                    if k not in _THING_KEYS:
                        problems.add("%s.%s.%s: unknown key%s (%s has %s)" % (
                            key, n, k, did_you_mean(str(k), _THING_KEYS), key, ", ".join(_THING_KEYS)), t, k, True)
                room = t.get("room")
                if "room" not in t:
                    problems.add("%s.%s: room is missing" % (key, n), t)
                elif not isinstance(room, str) or room not in named:
                    problems.add("%s.%s.room: unknown room %s%s" % (key, n, shown(room), why(key)), t, "room")
                answers = t.get("answers") or []
                if not isinstance(answers, list) or not all(is_text(a) and a is not None for a in answers):
                    problems.add("%s.%s.answers must be a list of texts" % (key, n), t, "answers")
                    answers = []
                xyz = coordinates(problems, "%s.%s" % (key, n), t, ("x", "y", "z"))
                if name is not None and xyz is not None and room in rooms:
                    out[name] = Thing(name, room, xyz["x"], xyz["y"], xyz.get("z", 0.0), [str(a) for a in answers])
            return out

        places, objects, people = things("places"), things("objects"), things("people")
        start = data.get("start", next(iter(rooms), ""))
        if not isinstance(start, str) or start not in named:
            problems.add("start: unknown room %s%s" % (shown(start), why("start")), top, "start")
        speed = number(data.get("speed", 1.0), MIN_SPEED, float("inf"))
        if speed is None:
            problems.add("speed must be a finite number of metres per second, at least %g, got %s" % (
                MIN_SPEED, shown(data.get("speed"))), top, "speed")
        raw_faults = mapping("faults", "module.function -> fault")
        known = _sim_functions()
        simulated = {f.split(".")[0] for f in known}
        faults = {}
        for key, spec in raw_faults.items():
            key = str(key)
            if not (key in known or (others is True and key.split(".")[0] not in simulated)
                    or (others is not True and key in set(others))):
                mine = [] if others is True else sorted(others)
                problems.add("faults.%s: not a function of the simulated robot%s%s" % (
                    key, " or of your --module" if mine else "", did_you_mean(key, known + mine)), raw_faults, key, True)
                continue
            fault = Fault.parse(key, spec, problems, raw_faults)
            if fault is not None:
                faults[key] = fault
        battery = BatterySpec.parse(data.get("battery"), source, problems, top)
        events = _parse_events(data.get("events"), problems, top)
        if not battery.dock:
            battery.dock = start if isinstance(start, str) else ""
        elif battery.dock not in named and battery.dock not in places:
            problems.add("battery.dock: unknown room or place %r%s" % (
                battery.dock, did_you_mean(battery.dock, list(rooms) + list(places))), data.get("battery"), "dock")
        problems.check()
        return cls(rooms=rooms, places=places, objects=objects, people=people, start=start, speed=speed,
                   faults=faults, written_faults={str(k): v for k, v in raw_faults.items()}, battery=battery,
                   events=events)

    def locate(self, place: str) -> Optional[Tuple[str, float, float]]:
        """(room, x, y) of a room or a place, None if unknown."""
        if place in self.rooms:
            x, y = self.rooms[place]
            return place, x, y
        p = self.places.get(place)
        return (p.room, p.x, p.y) if p else None

    def travel_time(self, a: Tuple[float, float], b: Tuple[float, float]) -> float:
        return math.hypot(b[0] - a[0], b[1] - a[1]) / self.speed
