"""Reading and checking a world file: the bounded reader, every problem at its ``file:line:column``,
the bounds of a world's numbers (:mod:`modules.sim.world` builds the world)."""
from __future__ import annotations

import math
import os
from typing import Any, Dict, List, Optional, Tuple

__all__ = ["DEFAULT_WORLD", "MAX_METRES", "MAX_RATE", "MAX_SECONDS", "MAX_TIMES", "MAX_WORLD_BYTES", "MIN_SPEED",
           "WHOLE", "Problems", "WorldError", "coordinates", "default_data", "is_text", "name_of", "number", "read_world",
           "shown"]

DEFAULT_WORLD = os.path.join(os.path.dirname(__file__), "world.yaml")

#: bounds of a world's numbers: beyond them a value is a typo or an attack (a delay of 1e300 s would kill
#: the timer thread of its module, a NaN speed every drive)
MAX_SECONDS = 86400.0      # a fault's delay, an event's time: a day
MAX_METRES = 1e6           # a coordinate
MIN_SPEED = 1e-3           # metres per second
MAX_RATE = 1e6             # a battery's drain or charge per metre or second (percent)
MAX_TIMES = 10 ** 9        # a fault's times
MAX_WORLD_BYTES = 4 << 20  # a world file


class WorldError(ValueError):
    """A world that cannot be used: every problem, one per line, each ``file:line:column: message``
    where the file says it (``file: message`` for a value it does not write, ``<world>: …`` for data)."""


def shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def number(value: Any, low: float, high: float) -> Optional[float]:
    """``value`` as a float when it is a number (not a bool) from ``low`` to ``high``, else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    if isinstance(value, int) and abs(value) > 10 ** 15:   # float() of a 400-digit int overflows
        return None
    number = float(value)
    return number if math.isfinite(number) and low <= number <= high else None


class Problems:
    """A world's problems, all of them, each where the file writes it (``file:line:column``) when the data
    came from a file with positions (:mod:`coordinator.yamlsrc`), else where ``source`` says."""

    def __init__(self, source: Optional[str]):
        self.source = source
        self.lines: List[str] = []

    def add(self, message: str, container: Any = None, key: Any = None, on_key: bool = False) -> None:
        where = _position(container, key, on_key) or self.source
        self.lines.append("%s: %s" % (where, message) if where else message)

    def check(self) -> None:
        """Raise WorldError saying every problem: those at a position in file order, then the others."""
        if self.lines:
            raise WorldError("\n".join(sorted(self.lines, key=_line_order)))


def _line_order(line: str) -> Tuple[int, int, int]:
    """(0, line, column) of a problem that starts ``file:line:column:``, else (1, 0, 0) (``sorted`` is stable)."""
    parts = line.split(": ", 1)[0].rsplit(":", 2)
    if len(parts) == 3 and parts[1].isdigit() and parts[2].isdigit():
        return 0, int(parts[1]), int(parts[2])
    return 1, 0, 0


WHOLE = object()


def _position(container: Any, key: Any = WHOLE, on_key: bool = False) -> str:
    """``file:line:column`` of ``container[key]`` (its key with ``on_key``), or of ``container``; "" if unknown."""
    try:
        if key is WHOLE or key is None and not isinstance(container, dict):
            pos = container.pos
        elif isinstance(container, dict):
            pos = (container.key_pos if on_key else container.val_pos)[key]
        else:
            pos = container.item_pos[key]
    except (AttributeError, KeyError, IndexError, TypeError):
        return ""
    return str(pos) if pos is not None else ""


def default_data() -> Dict[str, Any]:
    """The default house's top-level keys, as its file writes them (plain data: a value a world takes
    from it is not written in that world's file, so no position points into it)."""
    from comm.textfile import read_text
    from coordinator.yamlsrc import load_value

    data = load_value(read_text(DEFAULT_WORLD, MAX_WORLD_BYTES), DEFAULT_WORLD)
    return data if isinstance(data, dict) else {}


def read_world(path: str) -> Any:
    """The YAML of the world file ``path``, with positions (bounded: size, depth, nodes; a device or a
    FIFO without a writer is refused, not waited on)."""
    from comm.textfile import read_text, text_pos
    from coordinator.errors import TreeErrors
    from coordinator.yamlsrc import load_yaml

    try:
        text = read_text(path, MAX_WORLD_BYTES)
    except OSError as exc:
        raise WorldError("%s: cannot read: %s" % (path, exc.strerror or exc))
    except UnicodeDecodeError as exc:
        raise WorldError("%s:%d:%d: not UTF-8 text: byte 0x%02x" % ((path,) + text_pos(exc.object, exc.start)
                                                                      + (exc.object[exc.start],)))
    try:
        return load_yaml(text, path)
    except TreeErrors as exc:
        raise WorldError("\n".join("%s: not valid YAML: %s" % (e.pos, e.message.replace("YAML syntax error: ", "", 1))
                                   for e in exc.errors))


def is_text(value: Any) -> bool:
    """A scalar a reason or an answer can be written as."""
    return value is None or isinstance(value, (str, int, float, bool))



def name_of(problems: Problems, part: str, name: Any, container: Any) -> Optional[str]:
    """A room's or a thing's name: text (a number or ``yes`` would never match a call's text)."""
    if isinstance(name, str) and name:
        return name
    problems.add("%s: %s is not a name: write names as text (quote them)" % (part, shown(name)), container, name,
                 True)
    return None


def coordinates(problems: Problems, path: str, raw: Any, keys: Tuple[str, ...]) -> Optional[Dict[str, float]]:
    out = {}
    for k in keys:
        if k not in raw:
            if k != "z":
                problems.add("%s: %s is missing (metres)" % (path, k), raw)
            continue
        v = number(raw[k], -MAX_METRES, MAX_METRES)
        if v is None:
            problems.add("%s.%s must be a number of metres from %g to %g, got %s" % (
                path, k, -MAX_METRES, MAX_METRES, shown(raw[k])), raw, k)
        else:
            out[k] = v
    return out if all(k in out for k in keys if k != "z") and len(out) == sum(1 for k in keys if k in raw) else None
