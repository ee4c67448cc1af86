"""Mutated tree and definition files through the loaders: exit 0 or 2, a clean message, never a
crash or traceback (``BMTREE_RELIABILITY=1`` for the full count of ``make reliability``)."""
from __future__ import annotations

import contextlib
import io
import os
import random
import shutil
import time

import pytest

from coordinator.cli import main
from tests.conftest import ROOT, TREES

FULL = os.environ.get("BMTREE_RELIABILITY") == "1"
SIM = os.path.join(ROOT, "modules", "sim")

_TAGS = [b"!!python/object/apply:os.system [\"true\"]", b"!!python/name:os.system", b"!!binary aGVsbG8=",
         b"!!set {a, b}", b"!!omap [a: 1]", b"!!float", b"!!timestamp 2001-12-14", b"!<tag:x> 1", b"!local 3"]


def _mutate(rng: random.Random, data: bytes, yaml_file: bool) -> bytes:
    kind = rng.randrange(10)
    if kind == 0:  # byte flips
        b = bytearray(data)
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b)
    if kind == 1:  # truncation
        return data[: rng.randrange(len(data))]
    if kind == 2:  # deep nesting, at a random place
        n = rng.choice([100, 1000, 20000, 50000, 200000])
        at = rng.randrange(len(data))
        opener = rng.choice([b"[", b"{", b"- "] if yaml_file else [b"[", b"{\"a\":"])
        closer = {b"[": b"]", b"{": b"}", b"- ": b"", b"{\"a\":": b"}"}[opener]
        return data[:at] + opener * n + b"1" + closer * n + data[at:]
    if kind == 3 and yaml_file:  # alias bombs
        bomb = b"a: &a [x, x, x, x, x, x, x, x, x, x]\n"
        for i in range(1, rng.randint(5, 12)):
            bomb += b"a%d: &a%d [*a%s, *a%s, *a%s, *a%s, *a%s, *a%s, *a%s, *a%s, *a%s, *a%s]\n" % (
                (i, i) + ((b"" if i == 1 else str(i - 1).encode()),) * 10)
        return bomb + data
    if kind == 4:  # huge numbers
        big = rng.choice([b"9" * 100000, b"1e999", b"-1e999", b".nan", b"0x" + b"f" * 5000, b"1" * 4301])
        lines = data.split(b"\n")
        i = rng.randrange(len(lines))
        lines[i] = lines[i] + (b" " + big if yaml_file else big)
        return b"\n".join(lines)
    if kind == 5 and yaml_file:  # unsafe and odd tags
        lines = data.split(b"\n")
        i = rng.randrange(len(lines))
        if b":" in lines[i]:
            head, _, tail = lines[i].partition(b":")
            lines[i] = head + b": " + rng.choice(_TAGS) + b" " + tail.strip()
        return b"\n".join(lines)
    if kind == 6:  # non-UTF-8 and control bytes
        at = rng.randrange(len(data))
        return data[:at] + rng.choice([b"\xff\xfe", b"\x00", b"\xc3\x28", b"\xed\xa0\x80", b"\x1b[2J"]) + data[at:]
    if kind == 7:  # line shuffles and duplicates
        lines = data.split(b"\n")
        for _ in range(rng.randint(1, 4)):
            i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
            lines.insert(j, lines[i])
        return b"\n".join(lines)
    if kind == 8:  # indentation broken
        lines = data.split(b"\n")
        i = rng.randrange(len(lines))
        lines[i] = rng.choice([b"\t", b"   ", b""]) + lines[i].lstrip()
        return b"\n".join(lines)
    # a huge line
    return data + b"\n" + rng.choice([b"x" * 3000000, b"#" * 100000, b"\"" + b"a" * 100000])


def _run(argv):
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        code = main(argv)
    return code, err.getvalue()


def test_mutated_files_exit_0_or_2_without_traceback(tmp_path):
    rng = random.Random(1616)
    trees_dir = tmp_path / "trees"
    shutil.copytree(TREES, str(trees_dir))
    seeds = [(os.path.join(TREES, f), True) for f in sorted(os.listdir(TREES)) if f.endswith(".yaml")]
    seeds += [(os.path.join(SIM, f), False) for f in sorted(os.listdir(SIM)) if f.endswith(".json")]
    count = 2000 if FULL else 240
    codes = {0: 0, 2: 0}
    slowest = 0.0
    for i in range(count):
        path, yaml_file = seeds[i % len(seeds)]
        with open(path, "rb") as fh:
            data = fh.read()
        for _ in range(rng.choice([1, 1, 2])):
            data = _mutate(rng, data, yaml_file) or b" "
        target = trees_dir / ("m%04d%s" % (i, ".yaml" if yaml_file else ".json"))
        target.write_bytes(data)
        argv = ["check", str(target)] if yaml_file else ["modules", str(target)]
        t0 = time.monotonic()
        code, err = _run(argv)
        slowest = max(slowest, time.monotonic() - t0)
        assert code in (0, 2), (target, code, err[-2000:])
        assert "Traceback" not in err, (target, err[-2000:])
        if code == 2:
            assert err.strip(), (target, "exit 2 without a message")
        codes[code] += 1
        target.unlink()
    print("\nFIGURE loader fuzz: %d mutated files, %d exit 0, %d exit 2, 0 crashes, slowest %.2fs"
          % (count, codes[0], codes[2], slowest))
    if FULL:
        assert slowest < 10.0


def test_hostile_files_are_one_line_errors_with_exit_2(tmp_path):
    """The audit's files: each is exit 2 with one positioned line, no traceback."""
    n = 250
    cases = {
        "deep.yaml": ("format: 1\nname: d\nroot: " + "{inverter: " * n + "{call: speech.say, inputs: {text: hi}}"
                      + "}" * n + "\n", ":3:1107: the tree nests deeper than 100 levels"),
        "ctl.yaml": ('format: 1\nname: x\nroot: {call: speech.say, inputs: {text: "a\x01b"}}\n',
                     ":3:43: YAML error: unacceptable character #x0001"),
        "nul.yaml": ("format: 1\nname: x\n\nroot: {wait: 0}\x00\n", ":4:16: YAML error: unacceptable character #x0000"),
        "many.yaml": ("format: 1\nname: x\ninputs: {a: {default: [" + "1," * 250000 + "1]}}\nroot: {wait: 0}\n",
                      ":3:4000"),   # the item that crosses the limit: column 400,00x
    }
    messages = {"many.yaml": "the document has more than 200000 YAML nodes\n"}   # not blaming aliases
    for name, (text, wanted) in cases.items():
        (tmp_path / name).write_bytes(text.encode("utf-8"))
        code, err = _run(["check", str(tmp_path / name)])
        assert code == 2 and err.startswith(str(tmp_path / name) + wanted), (name, err)
        assert err.endswith(messages.get(name, "\n")) and err.count("\n") == 1, (name, err)
    code, err = _run(["check", "/dev/zero"])   # read without end before
    assert (code, err) == (2, "/dev/zero:1:1: cannot read /dev/zero: not a regular file\n")


def test_set_values_are_loaded_with_the_tree_files_limits(capsys):
    from coordinator.cliutil import set_values
    from coordinator.errors import UsageError

    assert set_values(["a=1", "b={x: [1, two]}", "c="]) == {"a": 1, "b": {"x": [1, "two"]}, "c": ""}
    bomb = "[&a0 [x,x,x,x,x,x,x,x,x,x], " + ", ".join(
        "&a%d [%s]" % (i, ",".join(["*a%d" % (i - 1)] * 10)) for i in range(1, 8)) + "]"
    for value, message in (("&a [*a]", "--set object: not a plain YAML value (column 5): alias *a is inside the node anchored &a"),
                           (bomb, "more than 200000 YAML nodes through its aliases"),
                           ("[" * 500 + "]" * 500, "nested too deeply"),
                           ("[" + "1," * 250000 + "1]", "--set object: not a plain YAML value (column 400000): the "
                                                        "document has more than 200000 YAML nodes"),
                           ("a\nb: [1", "(line 2, column 2): YAML syntax error"),
                           ("x\udcff", "(column 2): not UTF-8 text: byte 0xff")):
        with pytest.raises(UsageError) as info:   # the limit said: refused before it was built whole
            set_values(["object=" + value])
        assert message in str(info.value) and "\n" not in str(info.value)
    # exit 2 before anything starts (no simulated robot)
    assert main(["run", "--sim", os.path.join(TREES, "find_apple.yaml"), "--set", "object=&a [*a]"]) == 2
    out = capsys.readouterr()
    assert "alias *a is inside the node anchored &a" in out.err and "starting" not in out.out
