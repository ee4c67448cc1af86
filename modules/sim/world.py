"""The simulated house: rooms, places, objects, people, and injected faults."""
from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

import yaml

from comm.errors import did_you_mean
from modules.outcome import Outcome, OutcomeError, OutcomeKind, fail, outcome_from_dict

__all__ = ["World", "WorldError", "DEFAULT_WORLD", "Fault", "INJECTED", "describe_faults", "BatterySpec",
           "ScheduledEvent"]

DEFAULT_WORLD = os.path.join(os.path.dirname(__file__), "world.yaml")

#: ends the answer of every injected fault: on the tree's side it looks like the hardware's own failure otherwise
INJECTED = " (injected fault)"
#: the text of ``crash: true``
CRASH_TEXT = "injected crash"

log = logging.getLogger("bmtree.module")


class WorldError(ValueError):
    """A world file that cannot be used (the message names the key)."""


def _crash(text: str) -> Any:
    """A crash answers as a method that raised RuntimeError would, but raises nothing: a traceback
    through the runtime and this file would send the module's author looking for a bug of theirs."""
    def crash(**inputs: Any) -> Any:
        return fail("RuntimeError: %s%s" % (text, INJECTED))
    return crash


def _crash_text(value: Any) -> str:
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


def _default_data() -> Dict[str, Any]:
    """The default house's top-level keys, as its file writes them."""
    with open(DEFAULT_WORLD, encoding="utf-8") as fh:
        data = yaml.safe_load(fh)
    return data if isinstance(data, dict) else {}


@dataclass
class Fault:
    """An outcome that replaces a function's own answer, for ``times`` calls (None: all).

    Written ``{fail: reason}``, ``{reject: reason}``, ``{hang: true}``, ``{crash: text}`` (the
    function raises) or ``{delay: s}`` alone (the function answers, ``s`` seconds late); ``delay``
    also delays the others. It is the testing kit's outcome type, carried out by the runtime.
    """

    outcome: Outcome
    times: Optional[int] = None
    what: str = ""  # as written, for the module's log: "fail 'wheel motor overheated' after 2 s"

    @classmethod
    def parse(cls, key: str, raw: Any) -> Fault:
        if not isinstance(raw, dict):
            raise WorldError("faults.%s must be a mapping" % key)
        unknown = set(raw) - set(_FAULT_KEYS)
        if unknown:
            raise WorldError("faults.%s: unknown keys %s (use %s)" % (
                key, ", ".join(sorted(map(str, unknown))), ", ".join(_FAULT_KEYS)))
        times = raw.get("times")
        if times is not None and (not isinstance(times, int) or times < 0):
            raise WorldError("faults.%s.times must be a non-negative integer" % key)
        spec = {k: v for k, v in raw.items() if k != "times" and not (k in ("hang", "crash") and v is False)}
        try:
            delay = float(spec.get("delay", 0.0))
        except (TypeError, ValueError):
            raise WorldError("faults.%s.delay must be a number of seconds" % key)
        later = " after %g s" % delay if delay else ""
        if "crash" in spec:
            if len(spec) > (2 if "delay" in spec else 1):
                raise WorldError("faults.%s: crash goes alone (with delay, times)" % key)
            text = _crash_text(spec["crash"])
            return cls(Outcome(OutcomeKind.RESPOND, fn=_crash(text), delay=delay), times,
                       ("crash" if text == CRASH_TEXT else "crash %r" % text) + later)
        if set(spec) <= {"delay"}:
            return cls(Outcome(OutcomeKind.RESPOND, delay=delay), times, "delay %g s" % delay)
        for kind, default in (("fail", "failed"), ("reject", "rejected")):
            if kind in spec and (spec[kind] is True or spec[kind] is None or spec[kind] == ""):
                spec[kind] = default  # not "True" (injected fault)
        try:
            outcome = outcome_from_dict(spec)
        except OutcomeError as exc:
            raise WorldError("faults.%s: %s" % (key, exc))
        if outcome.kind in (OutcomeKind.FAIL, OutcomeKind.REJECT):
            what = "%s %r" % (outcome.kind.value, outcome.reason)
            outcome.reason += INJECTED
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


_FAULT_KEYS = ("fail", "reject", "crash", "hang", "delay", "times")


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
    def parse(cls, raw: Any, source: str) -> BatterySpec:
        if raw is None:
            return cls()
        if not isinstance(raw, dict):
            raise WorldError("%s: battery must be a mapping of %s" % (source, ", ".join(_BATTERY_KEYS)))
        values: Dict[str, Any] = {}
        for key, value in raw.items():
            if key not in _BATTERY_KEYS:
                raise WorldError("%s: battery.%s: unknown key%s (battery has %s)" % (
                    source, key, did_you_mean(str(key), _BATTERY_KEYS), ", ".join(_BATTERY_KEYS)))
            if key == "dock":
                values[key] = "" if value is None else str(value)
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
                raise WorldError("%s: battery.%s must be a non-negative number, got %r" % (source, key, value))
            values[key] = float(value)
        spec = cls(**values)
        if spec.level > 100 or spec.low > 100:
            raise WorldError("%s: battery.level and battery.low are percentages (0-100)" % source)
        return spec


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


def _parse_events(raw: Any, source: str) -> List[ScheduledEvent]:
    """The world's ``events:``, each checked against its simulated module's definition."""
    if raw is None:
        return []
    if not isinstance(raw, list):
        raise WorldError("%s: events must be a list of {at: seconds, event: module.event, params: {...}}" % source)
    known = _sim_events()
    out = []
    for i, entry in enumerate(raw):
        where = "%s: events[%d]" % (source, i)
        if not isinstance(entry, dict):
            raise WorldError("%s must be a mapping {at: seconds, event: module.event, params: {...}}" % where)
        unknown = sorted(str(k) for k in entry if k not in ("at", "event", "params"))
        if unknown:
            raise WorldError("%s: unknown key %r%s (an event has at, event, params)" % (
                where, unknown[0], did_you_mean(unknown[0], ("at", "event", "params"))))
        at = entry.get("at")
        if isinstance(at, bool) or not isinstance(at, (int, float)) or at < 0:
            raise WorldError("%s.at must be a non-negative number of seconds, got %r" % (where, at))
        name = str(entry.get("event", ""))
        ev = known.get(name)
        if ev is None:
            raise WorldError("%s.event: %r is not an event of the simulated robot%s (its events: %s)" % (
                where, name, did_you_mean(name, sorted(known)), ", ".join(sorted(known))))
        params = entry.get("params") or {}
        if not isinstance(params, dict):
            raise WorldError("%s.params must be a mapping of the event's parameters" % where)
        try:
            ev.build_values(params)
        except ValueError as exc:
            raise WorldError("%s.params: %s" % (where, exc))
        module, event = name.split(".", 1)
        out.append(ScheduledEvent(float(at), module, event, dict(params)))
    return out


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
        """The world in ``path``; WorldError says where when it cannot be read or is not valid.
        Each top-level key the file leaves out is the default house's (``DEFAULT_WORLD``), so a
        file of ``faults:`` alone is the default house with those faults (see ``from_dict``'s ``base``).
        ``others``: the ``module.function`` of the user's own modules its faults may name too (the
        ``--module`` of ``bmtree run --sim``), or True for any function of a module that is not
        simulated (a simulated module's node, which knows only its own)."""
        try:
            with open(path, encoding="utf-8") as fh:
                data = yaml.safe_load(fh)
        except OSError as exc:
            raise WorldError("%s: cannot read: %s" % (path, exc.strerror or exc))
        except UnicodeDecodeError as exc:
            raise WorldError("%s: not UTF-8 text (byte %d)" % (path, exc.start))
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = "%s:%d:%d" % (path, mark.line + 1, mark.column + 1) if mark is not None else path
            raise WorldError("%s: not valid YAML: %s" % (where, getattr(exc, "problem", None) or exc))
        if data is None:  # an empty file: the default house as it is
            data = {}
        base = None
        if not _same_file(path, DEFAULT_WORLD):
            base = _default_data()
        return cls.from_dict(data, path, others, base=base)

    @classmethod
    def from_dict(cls, data: Any, source: str = "<world>", others: Any = (), base: Optional[Dict[str, Any]] = None
                  ) -> World:
        """The world ``data`` describes (``source`` names it in errors; ``others`` as in ``load``).

        ``base``: a world (the default house) whose value of each top-level key ``data`` leaves out is
        taken as it is; a key ``data`` gives replaces it whole. So ``data`` that gives ``rooms`` is a
        house of its own: the places, objects, people and start it takes from ``base`` must be in its
        rooms, and an error says which key came from ``base`` and that it must be given too.
        """
        if not isinstance(data, dict):
            raise WorldError("%s: the world must be a mapping" % source)
        for key in data:  # a misspelt key would silently leave its part of the world out
            if key not in _WORLD_KEYS:
                raise WorldError("%s: unknown key %r%s (a world has %s)" % (
                    source, key, did_you_mean(str(key), _WORLD_KEYS), ", ".join(_WORLD_KEYS)))
        inherited = set()  # the top-level keys taken from base
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
        known = _sim_functions()
        simulated = {f.split(".")[0] for f in known}
        for key in data.get("faults") or {}:
            if str(key) in known or (others is True and str(key).split(".")[0] not in simulated):
                continue
            if others is not True and str(key) in set(others):
                continue
            mine = [] if others is True else sorted(others)
            raise WorldError("%s: faults.%s: not a function of the simulated robot%s%s" % (
                source, key, " or of your --module" if mine else "", did_you_mean(str(key), known + mine)))
        try:
            rooms = {n: (float(r["x"]), float(r["y"])) for n, r in (data.get("rooms") or {}).items()}

            def things(key: str) -> Dict[str, Thing]:
                out = {}
                for n, t in (data.get(key) or {}).items():
                    if t["room"] not in rooms:
                        raise WorldError("%s: %s.%s.room: unknown room %r%s" % (source, key, n, t["room"], why(key)))
                    out[n] = Thing(n, t["room"], float(t["x"]), float(t["y"]), float(t.get("z", 0.0)),
                                   [str(a) for a in t.get("answers", [])])
                return out

            world = cls(rooms=rooms, places=things("places"), objects=things("objects"), people=things("people"),
                        start=str(data.get("start", next(iter(rooms), ""))), speed=float(data.get("speed", 1.0)),
                        faults={k: Fault.parse(k, v) for k, v in (data.get("faults") or {}).items()},
                        written_faults={str(k): v for k, v in (data.get("faults") or {}).items()},
                        battery=BatterySpec.parse(data.get("battery"), source),
                        events=_parse_events(data.get("events"), source))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            if isinstance(exc, WorldError):
                raise
            raise WorldError("%s: malformed world: %s" % (source, exc))
        if world.start not in rooms:
            raise WorldError("%s: start: unknown room %r%s" % (source, world.start, why("start")))
        if world.speed <= 0:
            raise WorldError("%s: speed must be positive" % source)
        if not world.battery.dock:
            world.battery.dock = world.start
        elif world.locate(world.battery.dock) is None:
            raise WorldError("%s: battery.dock: unknown room or place %r%s" % (
                source, world.battery.dock, did_you_mean(world.battery.dock, list(rooms) + list(world.places))))
        return world

    def locate(self, place: str) -> Optional[Tuple[str, float, float]]:
        """(room, x, y) of a room or a place, None if unknown."""
        if place in self.rooms:
            x, y = self.rooms[place]
            return place, x, y
        p = self.places.get(place)
        return (p.room, p.x, p.y) if p else None

    def travel_time(self, a: Tuple[float, float], b: Tuple[float, float]) -> float:
        return math.hypot(b[0] - a[0], b[1] - a[1]) / self.speed
