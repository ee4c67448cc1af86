"""Hostile payloads for every input topic: invalid JSON, wrong types, > 1 MiB, depth 10,000,
unknown and hostile ROS type names, NaN and huge numbers, lone surrogates, missing keys."""
from __future__ import annotations

import json
import random
from typing import Callable, List

__all__ = ["hostile", "deep_call"]

_TYPES = ["this/Zen", "os/path", "antigravity/X", "json/decoder", "../../etc/passwd", "std_msgs/String\x00",
          "a" * 5000 + "/B", "__import__('os')/X", "std_msgs/Nope", "std_msgs/", "/String", "std_msgs/String/x",
          "subprocess/Popen", "ctypes/CDLL"]
_JUNK = ["", "{", "}", "[]", "null", "42", '"text"', "{\"a\": }", "\x00\x01", "{'single': 'quotes'}", "NaN",
         "[" * 50 + "]" * 49, "{\"a\":1}garbage", "\"\\ud800\""]


def _deep(n: int) -> str:
    return "[" * n + "]" * n


def deep_call(module: str, function: str, call_id: str, inner: bool) -> str:
    """A call whose value (inner) or whose whole payload (outer) is nested 10,000 deep."""
    if inner:
        return json.dumps({"basic_mod": module, "function": function, "call_id": call_id, "names": ["tag"],
                           "rostypes": ["std_msgs/String"], "msgs": [_deep(10000)]})
    return ('{"basic_mod": "%s", "function": "%s", "call_id": "%s", "names": ["tag"], '
            '"rostypes": ["std_msgs/String"], "msgs": %s}' % (module, function, call_id, _deep(10000)))


def hostile(rng: random.Random, shape: dict) -> str:
    """One malformed payload derived from a valid ``shape`` (a payload dict of this topic)."""
    kind = rng.randrange(12)
    d = json.loads(json.dumps(shape))
    keys = list(d)
    if kind == 0:
        return rng.choice(_JUNK)
    if kind == 1:  # wrong types
        k = rng.choice(keys)
        d[k] = rng.choice([5, 1.5, True, None, {"x": 1}, [1, 2], "x", [], -(2 ** 70)])
        return json.dumps(d)
    if kind == 2:  # too big
        d[rng.choice(keys)] = "x" * ((1 << 20) + 10)
        return json.dumps(d)
    if kind == 3:  # deep
        return _deep(10000) if rng.random() < 0.5 else json.dumps(d)[:-1] + ', "deep": %s}' % _deep(10000)
    if kind == 4:  # hostile type names
        if "rostypes" in d:
            d["rostypes"] = [rng.choice(_TYPES) for _ in d["rostypes"]] or [rng.choice(_TYPES)]
            d["msgs"] = d.get("msgs") or ["{}"]
            d["names"] = d.get("names") or ["x"]
        else:
            d[rng.choice(keys)] = rng.choice(_TYPES)
        return json.dumps(d)
    if kind == 5:  # NaN and huge numbers
        if not keys:
            return "NaN"
        return json.dumps(d)[:-1] + ', "n": NaN, "big": 1e999, "int": %s}' % ("9" * 5000)
    if kind == 6:  # lone surrogates, in keys and values
        k = rng.choice(keys)
        v = d[k]
        d[k] = ["\ud800"] if isinstance(v, list) else "\udfff"
        d["\ud800"] = "x"
        return json.dumps(d)
    if kind == 7:  # missing keys
        for k in rng.sample(keys, rng.randint(1, len(keys))):
            del d[k]
        return json.dumps(d)
    if kind == 8:  # values that do not fit their type
        if "msgs" in d and d["msgs"]:
            d["msgs"] = [rng.choice(['{"data": NaN}', '{"data": 1e999}', '{"data": %s}' % ("9" * 400),
                                     '{"data": [1, 2]}', '{"nope": 1}', '{"data": "\\ud800"}', "not json",
                                     _deep(5000), '{"data": {"data": {"data": 1}}}']) for _ in d["msgs"]]
        return json.dumps(d)
    if kind == 9:  # truncated
        text = json.dumps(d)
        return text[: rng.randrange(max(1, len(text)))]
    if kind == 10:  # length mismatches
        for k in ("names", "rostypes", "msgs", "var_names", "call_ids"):
            if k in d and isinstance(d[k], list):
                d[k] = d[k] + d[k] + ["extra"]
        return json.dumps(d)
    # byte flips
    text = bytearray(json.dumps(d).encode())
    for _ in range(rng.randint(1, 5)):
        text[rng.randrange(len(text))] = rng.randrange(32, 127)
    return text.decode("ascii", "replace")


def interleave(rng: random.Random, count: int, every: int, make_bad: Callable[[], str],
               make_good: Callable[[int], str]) -> List[tuple]:
    """``count`` bad payloads with a good one after every ``every``: [(is_good, text)]."""
    out: List[tuple] = []
    good = 0
    for i in range(count):
        out.append((False, make_bad()))
        if (i + 1) % every == 0:
            out.append((True, make_good(good)))
            good += 1
    return out
