"""The testing kit's scripted mocks as real module nodes, driven by bmtree run; the Blackboard client."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest
from std_msgs.msg import Float64, String

from coordinator.testing import MockError, Mocks, fail, reject, respond, succeed
from coordinator.testing.mocknode import start_mock_node
from modules.definition import default_module_paths, load_definitions
from tests.conftest import ROOT, TREES
from tests.integration.conftest import bmtree_cmd

pytest_plugins = ["pytester"]


def test_find_apple_against_mock_module_nodes(ros_graph):
    mocks = Mocks(load_definitions(default_module_paths()))
    mocks["navigation.go_to"].script(fail("door closed"), succeed(room="living_room"), succeed(room="kitchen"))
    mocks["vision.find_object"].script(succeed(success=False), succeed(success=True, position={"x": 8.6, "y": 2.3}))
    for module in ("navigation", "vision", "speech"):
        start_mock_node(ros_graph, mocks, module)
    out = subprocess.run(bmtree_cmd("run", os.path.join(TREES, "find_apple.yaml"), "-q"), capture_output=True,
                         text=True, timeout=60, env=dict(os.environ))
    assert out.returncode == 0, out.stdout + out.stderr
    calls = [line.split()[2:4] for line in out.stdout.splitlines() if line.startswith("  +")]
    assert calls == [["speech.say", "succeeded"], ["navigation.go_to", "failed"], ["navigation.go_to", "succeeded"],
                     ["vision.find_object", "failed"], ["navigation.go_to", "succeeded"],
                     ["vision.find_object", "succeeded"], ["navigation.approach", "succeeded"],
                     ["speech.say", "succeeded"]]


def test_mock_node_events_rejections_and_hangs(ros_graph, tmp_path):
    defs = load_definitions(default_module_paths())
    mocks = Mocks(defs)
    mocks["navigation.go_to"].hang()
    mocks["speech.say"].script(reject("not now"), succeed())
    start_mock_node(ros_graph, mocks, "navigation")
    start_mock_node(ros_graph, mocks, "speech")
    start_mock_node(ros_graph, mocks, "vision", events=[{"at": 2.0, "event": "lostPerson",
                                                         "params": {"person": "Ana"}}])
    tree = tmp_path / "t.yaml"
    tree.write_text("""format: 1
inputs:
  lost: {default: nobody}
root:
  sequence:
    - selector:
        - call: speech.say
          inputs: {text: first}
        - call: speech.say
          inputs: {text: second}
    - parallel:
        policy: one
        children:
          - wait_event: vision.lostPerson
            outputs: {person: lost}
            timeout: 20
          - call: navigation.go_to
            inputs: {place: kitchen}
    - check: 'lost == "Ana"'
""")
    out = subprocess.run(bmtree_cmd("run", str(tree), "-q"), capture_output=True, text=True, timeout=60,
                         env=dict(os.environ))
    assert out.returncode == 0, out.stdout + out.stderr
    lines = [line for line in out.stdout.splitlines() if line.startswith("  +")]
    assert "rejected" in lines[0] and "not now" in lines[0]
    assert "navigation.go_to" in lines[2] and "halted" in lines[2]


def test_callables_cannot_be_sent_to_a_node(ros_graph):
    mocks = Mocks(load_definitions(default_module_paths()))
    mocks["speech.say"].script(respond(lambda text: {}))
    with pytest.raises(MockError, match="cannot be sent to a mock node"):
        start_mock_node(ros_graph, mocks, "speech")


def test_blackboard_client(ros_graph, ros_probe, tmp_path):
    from blackboard.client import BlackboardClient, BlackboardError
    from comm import FunctionResult

    ros_graph.start_node(["-m", "blackboard.node", "--db", str(tmp_path / "bb.sqlite")], "/blackboard")
    acks = ros_probe.collect("/blackboard/stored", publishers=1)
    pub = ros_probe.publisher("/function/output", 1)
    for i, room in enumerate(("kitchen", "bedroom")):
        pub.publish(String(FunctionResult(["room", "speed"], [String(room), Float64(i)], call_id="c%d" % i,
                                          basic_mod="navigation", function="go_to").encode()))
    acks.wait_for(lambda t: '"total": 4' in t)
    client = BlackboardClient()
    try:
        assert client.get(["room", "navigation/go_to/speed"]) == {"room": String("bedroom"),
                                                                   "navigation/go_to/speed": Float64(1.0)}
        assert [m.data for m in client.history("room", 5)] == ["bedroom", "kitchen"]
        with pytest.raises(BlackboardError, match="missing: ghost"):
            client.get(["room", "ghost"])
    finally:
        client.close()
        ros_probe.close_collector(acks)


def test_no_blackboard_node_is_a_clear_timeout(ros_probe):  # the probe: this process's rospy node
    from blackboard.client import BlackboardClient, BlackboardError

    client = BlackboardClient(connect_timeout=0.2)
    try:
        with pytest.raises(BlackboardError, match="no answer from the Blackboard node within 0.3 s"):
            client.get(["room"], timeout=0.3)
    finally:
        client.close()


def test_the_readme_example_against_module_processes_runs(pytester, monkeypatch):
    """The README's second example, as written (only the tree's path made absolute): its own
    master, three mock module processes, and a real ``bmtree run`` against them."""
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        section = fh.read().split("## Testing your trees without a robot", 1)[1]
    code = section.split("```python")[2].split("```", 1)[0]
    assert "def test_against_module_processes(ros_graph)" in code
    code = code.replace('"trees/find_apple.yaml"', repr(os.path.join(TREES, "find_apple.yaml")))
    monkeypatch.setenv("PATH", os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    pytester.makepyfile(test_readme_processes=code)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider")
    result.assert_outcomes(passed=1)
