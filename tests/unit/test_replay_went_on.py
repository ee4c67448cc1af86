"""``bmtree replay --failure`` names the node that went on past an earlier failure: in a "storing
groceries" tree (per object a selector: grasp with ``retry``, else skip it), the selector that took
the skip branch, not the tree's top node when that branch failed in the same tick, nor a retry that
succeeded only for a later object (no ROS master)."""
from __future__ import annotations

import io
from typing import List

import pytest

from coordinator.replay import Replay, _jump_to_failure
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runstream import RunStream
from coordinator.testing.kit import TreeTest
from coordinator.testing.mocks import fail, succeed

GROCERIES = """format: 1
name: storing_groceries
inputs:
  objects: {default: [milk, cereal]}
root:
  sequence:
    name: store and report
    children:
      - for_each: $objects
        as: obj
        name: store each object
        child:
          selector:
            name: grasp or skip
            children:
              - sequence:
                  name: grasp and place
                  children:
                    - retry: 2
                      name: grasp (retrying)
                      child:
                        call: navigation.go_to
                        name: grasp
                        inputs: {place: $obj}
                    - call: speech.say
                      name: place
                      inputs: {text: placed}
              - %s
      - call: navigation.approach
        name: report
        inputs: {target: {x: 0, y: 0, z: 0}}
"""
# the skip branch: one that fails in the tick the selector takes it, or one that succeeds (a call)
SKIP_FAILS = """sequence:
                  name: skip the object
                  children:
                    - set: {skipped: $obj}
                    - fail: "{obj} must be stored"
"""
SKIP_SAYS = """call: speech.say
                name: skip the object
                inputs: {text: skipping}
"""
CLEANUP = """cleanup:
  call: speech.say
  inputs: {text: bye}
"""


def _earlier(tmp_path, sim_defs, text: str, script) -> List[str]:
    """The ``--failure`` lines of the failures before the one that ended the run."""
    path = tmp_path / "groceries.yaml"
    path.write_text(text)
    t = TreeTest(str(path), definitions=sim_defs)
    script(t.mocks)
    log = str(tmp_path / "run.jsonl")
    t.run(observers=[RunStream([RunLogWriter(log, fsync=False)])])
    out = io.StringIO()
    _jump_to_failure(Replay(read_log(log)), out)
    text = out.getvalue()
    assert "before it, the tree recovered from or went on past" in text, text
    return [line for line in text.split("went on past", 1)[1].splitlines()[1:] if line.startswith("  +")]


@pytest.mark.parametrize("cleanup", [False, True])
@pytest.mark.parametrize("delay", [0.0, 1.0])
def test_the_selector_that_took_the_skip_branch_went_on_even_if_that_branch_failed_in_the_same_tick(
        tmp_path, sim_defs, cleanup, delay):
    def script(m):
        m["navigation.go_to"].script(*[fail("arm fault", delay=delay)] * 2)

    lines = _earlier(tmp_path, sim_defs, GROCERIES % SKIP_FAILS + (CLEANUP if cleanup else ""), script)
    assert len(lines) == 2, lines
    assert lines[0].endswith("arm fault (moved past: 'grasp (retrying)' [retry] went on)"), lines
    assert lines[1].endswith("arm fault (moved past: 'grasp or skip' [selector] went on)"), lines
    assert "with_cleanup" not in "".join(lines)


@pytest.mark.parametrize("cleanup", [False, True])
def test_a_retry_that_gave_up_did_not_recover_because_it_succeeded_for_a_later_object(tmp_path, sim_defs, cleanup):
    def script(m):
        m["navigation.go_to"].script(fail("arm fault"), fail("arm fault"), succeed(room="kitchen"))
        m["navigation.approach"].fail("no table in sight")

    lines = _earlier(tmp_path, sim_defs, GROCERIES % SKIP_SAYS + (CLEANUP if cleanup else ""), script)
    assert len(lines) == 2, lines
    assert lines[0].endswith("arm fault (moved past: 'grasp (retrying)' [retry] went on)"), lines
    assert lines[1].endswith("arm fault (recovered: 'grasp or skip' [selector] succeeded after it)"), lines
