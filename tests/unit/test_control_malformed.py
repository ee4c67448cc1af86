"""A malformed control request is refused with why and the run goes on (an audit crashed or froze
``bmtree run --control`` with each of these: applied unguarded in the ticking thread)."""
from __future__ import annotations

import pytest

from coordinator.testing.kit import TreeTest
from tests.unit.test_control_stop import Timed, _run

TREE = """format: 1
name: go
root:
  sequence:
    - set: {x: [1, 2]}
    - call: navigation.go_to
      inputs: {place: kitchen}
cleanup:
  call: speech.say
  inputs: {text: bye}
"""


@pytest.fixture
def go_cleanup(tmp_path, sim_defs):
    path = tmp_path / "go.yaml"
    path.write_text(TREE)
    return TreeTest(str(path), definitions=sim_defs)

BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n" + "".join(
    "%s: &%s [*%s, *%s, *%s, *%s, *%s, *%s, *%s, *%s, *%s]\n" % ((chr(99 + i), chr(99 + i)) + (chr(98 + i),) * 9)
    for i in range(8))


def test_malformed_commands_are_refused_and_the_run_ends_as_it_would(go_cleanup, monkeypatch):
    go_cleanup.mocks["navigation.go_to"].succeed(room="kitchen", delay=2.0)
    script = [(0.5, {"id": "list", "command": ["pause"]}),
              (0.5, {"id": "map", "command": {}}),
              (0.5, {"id": "sup", "command": "break", "node": "speech.say@\u00b2"}),
              (0.5, {"id": "long", "command": "break", "node": "speech.say@" + "9" * 5000}),
              (0.5, {"id": "cycle", "command": "set", "key": "x", "value": "&a [*a]"}),
              (0.5, {"id": "deep", "command": "set", "key": "x", "value": "[" * 20000 + "]" * 20000}),
              (0.5, {"id": "bomb", "command": "set", "key": "x", "value": BOMB}),
              (0.5, {"id": "notext", "command": "set", "key": "x", "value": {"a": 1}})]
    control = Timed(script)
    run = _run(go_cleanup, control, monkeypatch)
    answers = {cid: (ok, answer) for cid, ok, answer in control.answers()}
    assert set(answers) == {c["id"] for _, c in script} and not any(ok for ok, _ in answers.values())
    assert answers["list"][1].startswith("malformed command: 'command' is text (one of: pause, resume, step, stop, ")
    assert answers["map"][1].endswith("got dict")
    for cid in ("cycle", "deep", "bomb"):
        assert answers[cid][1].startswith("the value is not YAML bmtree reads: "), answers[cid]
    assert answers["notext"][1] == "the value is YAML text (as 'bmtree control set KEY VALUE' sends it), got dict"
    assert run.succeeded and run.cleanup_status == "SUCCESS"   # it went on, and its cleanup ran
