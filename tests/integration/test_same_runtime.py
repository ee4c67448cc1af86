"""The same trees and scripts through the in-process runtime (simulated clock) and through real
module processes (mock module nodes, a real rosmaster): the call records must agree."""
from __future__ import annotations

import os
import re

import pytest

from coordinator.builder import build_tree
from coordinator.clock import RealClock
from coordinator.context import RunContext
from coordinator.language import load_tree
from coordinator.runner import TreeRunner
from coordinator.testing import Mocks, TreeTest, fail, hang, reject, succeed
from coordinator.testing.mocknode import start_mock_node
from modules.definition import default_module_paths, load_definitions
from tests.conftest import DATA, TREES

# two non-concurrent functions of one module at once: the issue's case
with open(os.path.join(DATA, "parallel_go_to_approach.yaml")) as _fh:
    PARALLEL = _fh.read()

MIXED = """format: 1
root:
  sequence:
    - selector:
        - call: speech.say
          inputs: {text: first}
        - call: speech.say
          inputs: {text: second}
    - parallel:
        policy: all
        children:
          - call: speech.listen
            inputs: {seconds: 1.0}
          - call: speech.say
            inputs: {text: while listening}
    - force_success:
        call: navigation.go_to
        inputs: {place: hall}
        timeout: 1.0
    - wait: 0.5          # the cancel travels on /master/cancel: let it reach navigation first
    - call: vision.find_person
      inputs: {name: Ana}
    - call: navigation.go_to
      inputs: {place: kitchen}
    - call: vision.find_object
      inputs: {object: apple}
"""


def script_parallel(mocks):
    """The issue's case: a drive takes time, so approaching meanwhile is refused as busy."""
    mocks["navigation.go_to"].succeed(delay=1.0, room="kitchen")


def script_find_apple(mocks):
    mocks["navigation.go_to"].script(fail("door closed"), succeed(room="living_room"), succeed(room="kitchen"))
    mocks["vision.find_object"].script(succeed(success=False), succeed(success=True, position={"x": 8.6, "y": 2.3}))


def script_mixed(mocks):
    """Rejection, a concurrent function beside a delayed one, a hang ended by a timeout, a failure."""
    mocks["speech.say"].script(reject("not now"), succeed())
    mocks["speech.listen"].succeed(delay=0.5, text="yes")
    mocks["navigation.go_to"].script(hang(), succeed(room="kitchen"))
    mocks["vision.find_person"].succeed(person="Ana")
    mocks["vision.find_object"].fail("camera unplugged")


def records(result):
    """(target, status, error) of every call in order, call ids replaced by their call's position."""
    ids = {c.call_id: "#%d" % i for i, c in enumerate(result.calls)}
    pattern = re.compile("|".join(re.escape(i) for i in ids)) if ids else None

    def norm(text):
        return pattern.sub(lambda m: ids[m.group(0)], text) if pattern else text

    return [(c.target, str(c.status), norm(c.error)) for c in result.calls], result.status.value, norm(result.reason)


def run_on_module_processes(ros_graph, path, mocks, defs):
    from coordinator.ros_transport import RosTransport

    for module in ("navigation", "vision", "speech"):
        start_mock_node(ros_graph, mocks, module)
    transport = RosTransport()
    try:
        transport.wait_ready(["navigation", "vision", "speech"], 30.0, defs)
        ctx = RunContext(transport, RealClock(), defs)
        return TreeRunner(build_tree(load_tree(path, defs), ctx), ctx).run(120.0)
    finally:
        transport.close()


@pytest.mark.parametrize("tree,script", [
    ("parallel", script_parallel),
    ("find_apple", script_find_apple),
    ("mixed", script_mixed),
])
def test_in_process_and_module_processes_record_the_same_calls(ros_graph, ros_probe, tmp_path, tree, script):
    defs = load_definitions(default_module_paths())
    if tree == "find_apple":
        path = os.path.join(TREES, "find_apple.yaml")
    else:
        path = str(tmp_path / ("%s.yaml" % tree))
        with open(path, "w") as fh:
            fh.write(PARALLEL if tree == "parallel" else MIXED)

    t = TreeTest(path, definitions=defs)
    script(t.mocks)
    in_process = records(t.run().result)

    mocks = Mocks(defs)
    script(mocks)
    on_nodes = records(run_on_module_processes(ros_graph, path, mocks, defs))

    assert on_nodes == in_process
    if tree == "parallel":
        assert in_process == ([("navigation.go_to", "halted", "halted by the tree"),
                               ("navigation.approach", "rejected", "busy with call #0 (go_to)")],
                              "FAILURE", in_process[2])
        assert "busy with call #0 (go_to)" in in_process[2]
    if tree == "mixed":
        calls, status, reason = in_process
        assert [s for _, s, _ in calls] == ["rejected", "succeeded", "succeeded", "succeeded", "timeout",
                                            "succeeded", "succeeded", "failed"]
        assert status == "FAILURE" and "camera unplugged" in reason


def test_the_issue_case_default_mocks_and_the_simulated_robot_agree(tmp_path):
    """A new user's mocked test (default scripts, instant answers) and ``bmtree run --sim`` both
    refuse the approach while the drive runs."""
    import subprocess

    from tests.integration.conftest import bmtree_cmd

    path = tmp_path / "parallel.yaml"
    path.write_text(PARALLEL)
    mocked = TreeTest(str(path)).run()
    assert mocked.failed
    assert [(c.target, c.status) for c in mocked.calls()] == [("navigation.go_to", "halted"),
                                                              ("navigation.approach", "rejected")]
    out = subprocess.run(bmtree_cmd("run", "--sim", str(path), "-q"), capture_output=True, text=True, timeout=120,
                         env=dict(os.environ), stdin=subprocess.DEVNULL)
    assert out.returncode == 1, out.stdout + out.stderr
    calls = [line.strip()[1:].split(None, 4) for line in out.stdout.splitlines() if line.startswith("  +")]
    assert [(c[1], c[2]) for c in calls] == [(c.target, c.status) for c in mocked.calls()]
    busy = re.compile(r"busy with call [0-9a-f]{16} \(go_to\)$")
    # the failing call's line of the summary also says what it was asked
    assert re.match(busy.pattern[:-1] + r'  inputs \{"target":\{"x":1\.0,"y":0\.0,"z":0\.0\}\}$', calls[1][4]), calls
    assert busy.match(mocked.calls()[1].error)
