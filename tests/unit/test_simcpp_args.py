"""``bmtree run --sim --module DEF.json=EXECUTABLE``: the form read, the executable checked before anything
starts (one line, exit 2), the pair's names, and the end of one process of a C++ module's pair ending the
other and said by the first one's end (real processes, no ROS master)."""
from __future__ import annotations

import json
import os
import shutil
import signal
import sys
import threading

import pytest

from coordinator.cli import main
from coordinator.errors import UsageError
from coordinator.simcpp import check_executable, pair_names, watch_pair
from coordinator.simgraph import SimGraph, _Starting
from coordinator.simprocess import process_ends
from coordinator.usermodule import user_module as _user_module
from modules.definition import load_definition
from tests.conftest import ROOT, until

GRIPPER_JSON = os.path.join(ROOT, "modules", "cpp", "example", "gripper.json")


@pytest.fixture
def node_exe(tmp_path):
    exe = tmp_path / "build" / "gripper_node"
    exe.parent.mkdir()
    exe.write_text("#!/bin/sh\nexec sleep 60\n")
    exe.chmod(0o755)
    return exe


@pytest.mark.parametrize("given, python", [
    ("./build/gripper_node", False), ("/opt/arm/bin/arm", False), ("gripper_node", False),
    ("gripper.py:Gripper", True), ("my_pkg.gripper:Gripper", True),
])
def test_the_executable_form_is_told_from_a_python_class_by_its_colon(given, python, monkeypatch):
    seen = []
    monkeypatch.setattr("coordinator.simcpp.check_executable", lambda path, d: seen.append(path) or "/abs/" + path)
    if given.endswith(".py:Gripper"):   # the Python form's own checks
        with pytest.raises(UsageError, match="no such file gripper.py"):
            _user_module("%s=%s" % (GRIPPER_JSON, given))
        assert seen == []
    elif python:
        um = _user_module("%s=%s" % (GRIPPER_JSON, given))
        assert seen == [] and um.executable is None and um.class_spec == given
    else:
        um = _user_module("%s=%s" % (GRIPPER_JSON, given))
        assert seen == [given] and um.executable == "/abs/" + given and um.class_spec == ""


@pytest.mark.parametrize("given", ["g.json=", "gripper_node", "=./x"])
def test_a_module_without_both_sides_says_both_forms(given):
    with pytest.raises(UsageError, match="--module takes DEFINITION.json=FILE.py:CLASS, DEFINITION.json=EXECUTABLE or DEFINITION.json=SCRIPT.yaml"):
        _user_module(given)


def test_runcmd_reads_the_executable_form_as_a_cpp_module(node_exe, monkeypatch):
    monkeypatch.chdir(node_exe.parent.parent)
    um = _user_module("%s=./build/gripper_node" % GRIPPER_JSON)
    assert um.executable == str(node_exe) and um.definition.name == "gripper"
    assert um.definition_path == GRIPPER_JSON
    python = _user_module("%s=modules.sim.navigation:Navigation" % GRIPPER_JSON)
    assert python.executable is None and python.class_spec == "modules.sim.navigation:Navigation"


def test_a_bare_name_is_looked_up_on_path_as_a_shell_does(tmp_path, monkeypatch):
    d = load_definition(GRIPPER_JSON)
    assert check_executable("sh", d) == os.path.abspath(shutil.which("sh"))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "gripper_node").write_text("#!/bin/sh\n")
    (tmp_path / "gripper_node").chmod(0o755)
    with pytest.raises(UsageError) as exc:
        check_executable("gripper_node", d)
    assert str(exc.value) == "--module %s=gripper_node: no executable gripper_node on PATH; for the one in this " \
                             "folder write ./gripper_node" % GRIPPER_JSON


@pytest.mark.parametrize("path, said", [
    ("./nothere", "no such file"),
    ("./build/gripper_node --verbose", "no such file (bmtree starts it with no arguments but __name:=; for more, "
                                       "give a script that runs it with them)"),
    ("./build", "a folder, not an executable"),
    ("./gripper.json", "not executable (chmod +x it, or give FILE.py:CLASS for a Python module)"),
    ("./gripper.py", "a Python file: name its class (gripper.json=./gripper.py:CLASS); an executable, given "
                     "without :CLASS, runs as a C++ module's node"),
    ("./gripper.cpp", "a source file: build it and give the executable (README, C++ modules)"),
])
def test_a_wrong_executable_is_one_line_and_exit_2_before_anything_starts(path, said, node_exe, monkeypatch, capsys):
    monkeypatch.chdir(node_exe.parent.parent)
    shutil.copy(GRIPPER_JSON, "gripper.json")
    (node_exe.parent.parent / "t.yaml").write_text("format: 1\nroot: {call: gripper.ping}\n")
    code = main(["run", "--sim", "--no-record", "--module", "gripper.json=" + path, "t.yaml"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err == "error: --module gripper.json=%s: %s\n" % (path, said)


def test_a_definition_the_cpp_protocol_cannot_serve_is_refused_before_anything_starts(node_exe, tmp_path):
    with open(GRIPPER_JSON) as fh:
        data = json.load(fh)
    data["Functions"][0]["Concurrent"] = True
    (tmp_path / "c.json").write_text(json.dumps(data))
    with pytest.raises(UsageError, match="a C\\+\\+ module runs one function at a time .* cannot be Concurrent"):
        _user_module("%s=%s" % (tmp_path / "c.json", node_exe))


def test_the_pair_is_named_as_bmtree_run_names_a_cpp_node_unless_the_graph_has_that_name():
    taken = {"/blackboard", "/bm_navigation"}
    assert pair_names("gripper", taken) == ("/gripper", "/gripper_bridge")
    assert pair_names("blackboard", taken) == ("/blackboard_cpp", "/blackboard_cpp_bridge")
    assert pair_names("gripper", taken) == ("/gripper_cpp", "/gripper_cpp_bridge")  # a second one


def test_a_cpp_node_still_starting_says_how_far_it_got():
    s = _Starting("/gripper", None, "gripper", True, "cpp")
    assert s.what == "your module gripper's C++ node /gripper"
    assert s.state(10.0) == "its C++ node's process is still running, but its node /gripper has not registered " \
                            "with the master (its main() has not made a ros::NodeHandle)"
    s.registered = 7.5
    assert s.state(10.0) == "its C++ node /gripper registered with the master 2.5 s ago but does not subscribe " \
                            "/gripper/BM_input (its module not constructed yet)"
    s.serving = 8.0
    assert s.state(10.0) == "its C++ node /gripper registered with the master 2.5 s ago and subscribes " \
                            "/gripper/BM_input, but its bridge has not connected to it (is its constructor still " \
                            "running?)"
    assert _Starting("/gripper_bridge", None, "gripper", True, "bridge").what == \
        "your module gripper's bridge /gripper_bridge"


def _graph(tmp_path, cpp, bridge):
    graph = SimGraph(str(tmp_path / "sim"))
    graph.start_node(cpp, "/gripper", wait=False)
    graph.start_node(bridge, "/gripper_bridge", wait=False)
    return graph


def test_a_cpp_node_that_ends_mid_run_ends_its_bridge_and_is_said_for_it(tmp_path):
    script = "echo '[ INFO] [1.0]: bmtree: C++ basic module gripper ready'; echo '[FATAL] [2.0]: no arm'; exit 7"
    graph = _graph(tmp_path, ["sh", "-c", "sleep 0.3; " + script], ["sleep", "60"])
    try:
        watch_pair(graph, "/gripper", "/gripper_bridge")
        bridge = graph.procs["/gripper_bridge"]
        until(lambda: bridge.poll() is not None)
        assert bridge.returncode == -signal.SIGKILL  # as a crash: the run finds the module gone
        assert process_ends(graph)("/gripper_bridge") == \
            "its C++ node /gripper stopped: its process exited with code 7; its log's last error: no arm"
    finally:
        graph.close()


def test_a_bridge_that_ends_mid_run_ends_its_cpp_node(tmp_path):
    graph = _graph(tmp_path, ["sleep", "60"], [sys.executable, "-c", "import os; os.kill(os.getpid(), 9)"])
    try:
        watch_pair(graph, "/gripper", "/gripper_bridge")
        cpp = graph.procs["/gripper"]
        until(lambda: cpp.poll() is not None)
        assert cpp.returncode == -signal.SIGKILL
        assert process_ends(graph)("/gripper_bridge") == "its process was killed by SIGKILL"
    finally:
        graph.close()


def test_the_end_of_the_run_is_no_death_of_the_pair(tmp_path):
    graph = _graph(tmp_path, ["sleep", "60"], ["sleep", "60"])
    watch_pair(graph, "/gripper", "/gripper_bridge")
    procs = list(graph.procs.values())
    graph.close()
    assert all(p.returncode is not None for p in procs)
    for t in threading.enumerate():  # the watchers, told of the ends, did nothing
        if t.name.startswith("bmtree-pair-"):
            t.join(10)
    assert graph.ended_with == {}


def test_a_cpp_nodes_uncaught_exception_is_its_last_error(tmp_path):
    from coordinator.simprocess import ended_text

    log = tmp_path / "gripper.out"
    log.write_text("[ INFO] [1.5]: bmtree: C++ basic module gripper ready\n[ERROR] [2.5]: bmtree: lost the arm\n"
                   "terminate called after throwing an instance of 'std::runtime_error'\n  what():  no /dev/ttyUSB0\n")
    assert ended_text(-signal.SIGABRT, str(log)) == "its process was killed by SIGABRT; its log's last error: terminate " \
        "called after throwing an instance of 'std::runtime_error' (what(): no /dev/ttyUSB0)"
    log.write_text("[ INFO] [1.5]: bmtree: C++ basic module gripper ready\n[ERROR] [2.5]: bmtree: lost the arm\n")
    assert ended_text(-signal.SIGSEGV, str(log)) == "its process was killed by SIGSEGV; its log's last error: bmtree: " \
        "lost the arm"


def test_a_long_last_error_keeps_its_end_where_the_fix_is(tmp_path):
    from coordinator.simprocess import last_error

    log = tmp_path / "hand_bridge.out"
    said = ("error: node /hand serves module 'gripper', but the definition %s is module 'hand': the name given to "
            "BasicModule in the C++ code must be the definition's (BasicModule(nh, \"hand\"))" % ("/very/long" * 40))
    log.write_text("[ INFO] [1.5]: starting\n" + said + "\n")
    got = last_error(str(log))
    assert got.startswith("error: node /hand serves module 'gripper'") and " … " in got and len(got) <= 400, got
    assert got.endswith("must be the definition's (BasicModule(nh, \"hand\"))"), got
