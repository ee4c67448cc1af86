"""C++ basic modules: the example built with bmtree's library, behind bmtree-bridge, driven by bmtree run."""
from __future__ import annotations

import functools
import json
import os
import signal
import subprocess
import sys
import time
import xmlrpc.client

import pytest

from tests.conftest import REFERENCE, ROOT, until
from tests.integration.conftest import NODES, bmtree_cmd, wait_announced
from tests.integration.test_master_restart import _restart_master

CPP = os.path.join(ROOT, "modules", "cpp")
GRIPPER_JSON = os.path.join(CPP, "example", "gripper.json")
ODDITIES_CPP = os.path.join(ROOT, "tests", "data", "cpp", "oddities.cpp")
ODDITIES_JSON = os.path.join(ROOT, "tests", "data", "cpp", "oddities.json")
SANITIZERS = "-O1 -g -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all"


def _build(build_dir, *options):
    """Configure and build modules/cpp (incremental: a second session rebuilds nothing)."""
    for cmd in (["cmake", "-S", CPP, "-B", build_dir, "-DBMTREE_WERROR=ON", *options],
                ["cmake", "--build", build_dir]):
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
        assert out.returncode == 0, "%s failed:\n%s%s" % (" ".join(cmd), out.stdout[-4000:], out.stderr[-4000:])
    exe = os.path.join(build_dir, "gripper")
    assert os.access(exe, os.X_OK)
    return exe


@pytest.fixture(scope="session")
def gripper_exe():
    """The example module, -O2, -Wall -Wextra -Wpedantic -Werror."""
    return _build(os.path.join(ROOT, "build", "cpp"), "-DCMAKE_BUILD_TYPE=Release", "-DBMTREE_TEST_MODULE=" + ODDITIES_CPP)


@pytest.fixture(scope="session")
def gripper_asan_exe():
    return _build(os.path.join(ROOT, "build", "cpp-asan"), "-DCMAKE_BUILD_TYPE=None", "-DCMAKE_CXX_FLAGS=" + SANITIZERS)


def start_gripper(ros_graph, exe, env=None):
    cpp = ros_graph.start_node([exe], "/gripper", env=env)
    bridge = ros_graph.start_node(["-m", "modules.bridge", "--definition", GRIPPER_JSON], "/gripper_bridge")
    wait_announced("gripper")
    return cpp, bridge


@pytest.fixture
def gripper(ros_graph, gripper_exe):
    return start_gripper(ros_graph, gripper_exe)


def start_oddities(ros_graph, gripper_exe, *bridge_options):
    """The test module (tests/data/cpp/oddities.cpp) behind its bridge."""
    exe = os.path.join(os.path.dirname(gripper_exe), "test_module")
    cpp = ros_graph.start_node([exe], "/oddities")
    bridge = ros_graph.start_node(["-m", "modules.bridge", "--definition", ODDITIES_JSON, *bridge_options],
                                  "/oddities_bridge")
    wait_announced("oddities")
    return cpp, bridge


def gripper_caller(caller_factory):
    """A Caller that the bridge answers (a connection the probe's publisher holds to an earlier
    test's node of the same name may swallow the first call)."""
    return caller_factory(answering=["gripper"])


def run(*args, timeout=120):
    return subprocess.run(bmtree_cmd(*args), capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ), stdin=subprocess.DEVNULL)


def _node_log(ros_graph, node):
    """What a node started by the graph printed so far."""
    with open(os.path.join(ros_graph.ros_home, "%s.out" % node), errors="replace") as fh:
        return fh.read()


def call_lines(stdout):
    return [line for line in stdout.splitlines() if line.startswith("  +")]


ALL_FUNCTIONS = """format: 1
root:
  sequence:
    - call: gripper.set_fingers
      inputs: {left: 0.02, right: 0.07}
      outputs: {opening: opening}
    - check: 'opening > 0.0499 and opening < 0.0501'
    - call: gripper.reach
      inputs: {target: {x: 0.3, y: -0.1, z: 0.5}}
      outputs: {final_pos: at, distance: d}
    - check: 'at.x == 0.3 and at.y == -0.1 and at.z == 0.5 and d > 0.59 and d < 0.6'
    - call: gripper.squeeze
      inputs: {seconds: 0.0, label: tag}
      outputs: {label: echoed}
    - check: 'echoed == "tag"'
    - call: gripper.ping
    - force_success:
        call: gripper.set_fingers
        name: crossed fingers
        inputs: {left: 0.07, right: 0.02}
    - force_success:
        call: gripper.reach
        name: too far
        inputs: {target: {x: 2.0, y: 0.0, z: 0.0}}
    - force_success:
        call: gripper.squeeze
        name: not a number
        inputs: {seconds: .nan, label: nan}
"""


def test_cpp_module_through_the_bridge(gripper, tmp_path):
    tree = tmp_path / "all.yaml"
    tree.write_text(ALL_FUNCTIONS)
    out = run("run", str(tree), "-q")
    assert out.returncode == 0, out.stdout + out.stderr
    lines = call_lines(out.stdout)
    assert [line.split()[3] for line in lines[:4]] == ["succeeded"] * 4, out.stdout
    assert "failed" in lines[4] and "the left finger must stay left of the right one" in lines[4]
    assert "rejected" in lines[5] and "out of reach" in lines[5]
    assert "failed" in lines[6] and "seconds must be within 0..60" in lines[6]
    live = run("modules", "--live")
    assert "gripper  (node /gripper_bridge)" in live.stdout
    assert "set_fingers(left: std_msgs/Float64, right: std_msgs/Float64)" in live.stdout


def test_two_inputs_of_one_type_keep_their_values(gripper, caller_factory, tmp_path):
    """left and right travel on the same data topic (/gripper/float64): the order decides."""
    from modules.definition import load_definition

    defs = {"gripper": load_definition(GRIPPER_JSON)}
    caller = gripper_caller(caller_factory)
    for left, right in ((0.01, 0.09), (0.03, 0.04), (-0.2, 0.2)):
        res = caller.call(defs, "gripper.set_fingers", left=left, right=right)
        assert res.status == "succeeded", res.error
        assert res.values["opening"].data == pytest.approx(right - left)
    res = caller.call(defs, "gripper.squeeze", seconds=0.0, label="one")
    assert (res.values["closed_for"].data, res.values["label"].data) == (0.0, "one")


def test_unknown_function_and_bad_inputs_are_rejected_before_the_cpp_node(gripper, caller_factory, ros_probe):
    from comm import FunctionCall

    caller = gripper_caller(caller_factory)
    bm_input = ros_probe.collect("/gripper/BM_input", publishers=1)   # connected to the bridge
    try:
        caller.send(FunctionCall("gripper", "dance", call_id="c-dance"))
        res = caller.result("c-dance")
        assert res.status == "rejected" and "module 'gripper' has no function 'dance'" in res.error
        caller.send(json.dumps({"basic_mod": "gripper", "function": "set_fingers", "call_id": "c-bad",
                                "names": ["left", "right"], "rostypes": ["std_msgs/String", "std_msgs/Float64"],
                                "msgs": ['{"data": "x"}', '{"data": 1.0}']}))
        res = caller.result("c-bad")
        assert res.status == "rejected" and "bad inputs" in res.error and "std_msgs/String" in res.error
        assert bm_input.items == []
    finally:
        ros_probe.close_collector(bm_input)


def test_a_call_while_one_runs_is_rejected_busy(gripper, caller_factory):
    from modules.definition import load_definition

    d = load_definition(GRIPPER_JSON)
    caller = gripper_caller(caller_factory)
    slow = d.function("squeeze").build_call({"seconds": 1.0, "label": "slow"})
    caller.send(slow)
    bm_busy = d.function("set_fingers").build_call({"left": 0.0, "right": 0.01})
    caller.send(bm_busy)
    res = caller.result(bm_busy.call_id)
    assert res.status == "rejected" and "busy with call %s (squeeze)" % slow.call_id in res.error
    res = caller.result(slow.call_id, timeout=20)
    assert res.status == "succeeded" and res.values["label"].data == "slow"


def test_cpp_node_killed_mid_call_fails_within_the_call_timeout(ros_graph, gripper_exe, ros_probe, tmp_path):
    cpp, _bridge = start_gripper(ros_graph, gripper_exe)
    tree = tmp_path / "killed.yaml"
    tree.write_text("format: 1\nroot:\n  call: gripper.squeeze\n  inputs: {seconds: 50.0, label: long}\n"
                    "  timeout: 25\n")
    calls = ros_probe.collect("/gripper/BM_input", publishers=1)   # the bridge's call to the C++ node
    proc = subprocess.Popen(bmtree_cmd("run", str(tree), "-q"), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=dict(os.environ))
    try:
        calls.wait_for(lambda t: '"squeeze"' in t, 60)
        t0 = time.monotonic()
        ros_graph.kill_node(cpp)
        out, err = proc.communicate(timeout=60)
        elapsed = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
        ros_probe.close_collector(calls)
    assert proc.returncode == 1, out + err
    line = call_lines(out)[0]
    assert "failed" in line and "the C++ node /gripper exited during the call" in line, out
    assert elapsed < 25  # answered by the bridge, not by the tree's 25 s timeout


#: the end of a tree whose first stubborn call was given up on while the C++ node still ran it
THEN_A_SECOND_CALL_GETS_ITS_OWN_OUTPUTS = """    - retry: 100
      child:
        sequence:
          - wait: 0.1
          - call: oddities.stubborn
            name: second
            inputs: {seconds: 0.1}
            outputs: {slept: secs}
    - check: 'secs == 0.1'
"""


def stubborn_first(timeout, then=""):
    """A tree: a 1.5 s ``oddities.stubborn`` given up on after ``timeout`` s, the steps ``then``
    (YAML, as items of the root sequence), and a second stubborn call that must get its own outputs."""
    return ("format: 1\nroot:\n  sequence:\n    - force_success:\n        call: oddities.stubborn\n"
            "        name: first\n        inputs: {seconds: 1.5}\n        outputs: {slept: wrong}\n"
            "        timeout: %s\n%s" % (timeout, then)) + THEN_A_SECOND_CALL_GETS_ITS_OWN_OUTPUTS


def test_a_halted_calls_late_answer_is_not_taken_for_the_next_call(ros_graph, gripper_exe, tmp_path):
    """A function that does not look at cancels runs on after its call was halted: the node is
    busy until it answers, and that answer is never given to the next call."""
    start_oddities(ros_graph, gripper_exe)
    tree = tmp_path / "late.yaml"
    tree.write_text(stubborn_first(0.3, "    - force_success:\n        call: oddities.ok\n        name: while busy\n"))
    lines, _ = timed_run(tree)
    assert "timeout" in lines[0] or "halted" in lines[0], lines
    assert "rejected" in lines[1] and "busy with call" in lines[1], lines
    assert "succeeded" in lines[-1] and all("stubborn" in line for line in lines[2:]), lines


def long_squeeze_then(seconds, timeout, then):
    """A tree: a squeeze of ``seconds`` given up on after ``timeout`` s, then the call leaf ``then``
    (its YAML lines, without indentation) tried every 0.1 s until it succeeds (100 tries)."""
    leaf = "".join("          %s%s\n" % ("- " if i == 0 else "  ", line) for i, line in enumerate(then))
    return ("format: 1\nroot:\n  sequence:\n    - force_success:\n        call: gripper.squeeze\n"
            "        name: long\n        inputs: {seconds: %s, label: long}\n        timeout: %s\n"
            "    - retry: 100\n      child:\n        sequence:\n          - wait: 0.1\n%s" % (seconds, timeout, leaf))


def timed_run(tree):
    """``bmtree run -q`` of a tree that must succeed: (its call lines, seconds it took)."""
    t0 = time.monotonic()
    out = run("run", str(tree), "-q")
    elapsed = time.monotonic() - t0
    assert out.returncode == 0, out.stdout + out.stderr
    return call_lines(out.stdout), elapsed


def test_a_halted_cpp_function_stops_at_once_and_the_module_takes_calls_again(gripper, tmp_path):
    """The library's sleepFor() returns when the bridge forwards the cancel of a halted call, so
    the 30 s squeeze ends just after the tree's 0.3 s timeout; the next call, sent at once while the
    squeeze is still stopping, waits for it (not refused busy) and succeeds on its first try."""
    tree = tmp_path / "halt.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n    - force_success:\n        call: gripper.squeeze\n"
                    "        inputs: {seconds: 30.0, label: long}\n        timeout: 0.3\n"
                    "    - call: gripper.set_fingers\n      inputs: {left: 0.0, right: 0.01}\n")
    lines, elapsed = timed_run(tree)
    assert len(lines) == 2 and ("timeout" in lines[0] or "halted" in lines[0]), lines
    assert "succeeded" in lines[1] and "set_fingers" in lines[1], lines
    assert elapsed < 20, elapsed  # not after the squeeze's 30 s


def test_the_bridges_call_timeout_cancels_the_cpp_function(ros_graph, gripper_exe, tmp_path):
    """The bridge gives up on a call after --call-timeout and cancels it on the C++ node: a function
    that takes cancels stops, and the module takes calls again without waiting out its 50 s."""
    ros_graph.start_node([gripper_exe], "/gripper")
    ros_graph.start_node(["-m", "modules.bridge", "--definition", GRIPPER_JSON, "--call-timeout", "0.5"],
                         "/gripper_bridge")
    wait_announced("gripper")
    tree = tmp_path / "given_up.yaml"
    tree.write_text(long_squeeze_then(50.0, 60, ["call: gripper.squeeze", "inputs: {seconds: 0.1, label: next}",
                                                 "outputs: {label: got}"]) + "    - check: 'got == \"next\"'\n")
    lines, elapsed = timed_run(tree)
    assert "failed" in lines[0] and "no BM_output from the C++ node /gripper within 0.5s" in lines[0], lines
    assert "succeeded" in lines[-1], lines
    assert elapsed < 30, elapsed  # not after the first squeeze's 50 s


def test_after_the_bridges_call_timeout_the_late_answer_is_not_taken_for_the_next_call(ros_graph, gripper_exe,
                                                                                       tmp_path):
    """The bridge gives up on a call (--call-timeout) while the C++ node still runs it (a function
    that does not look at cancels): the node stays busy until its late BM_output, which no later
    call is given."""
    start_oddities(ros_graph, gripper_exe, "--call-timeout", "0.5")
    tree = tmp_path / "stale.yaml"
    tree.write_text(stubborn_first(10))
    lines, _ = timed_run(tree)
    assert "failed" in lines[0] and "no BM_output from the C++ node /oddities within 0.5s" in lines[0], lines
    assert "rejected" in lines[1] and "still runs oddities.stubborn" in lines[1], lines
    assert "succeeded" in lines[-1], lines


def test_a_concurrent_function_in_a_cpp_definition_is_refused(tmp_path):
    with open(GRIPPER_JSON) as fh:
        data = json.load(fh)
    data["Functions"][0]["Concurrent"] = True
    bad = tmp_path / "gripper.json"
    bad.write_text(json.dumps(data))
    out = subprocess.run([sys.executable, "-m", "modules.bridge", "--definition", str(bad)], capture_output=True,
                         text=True, timeout=60, cwd=ROOT, stdin=subprocess.DEVNULL)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "cannot be Concurrent" in out.stderr and data["Functions"][0]["Name"] in out.stderr, out.stderr


def test_a_cpp_function_that_throws_anything_fails_and_the_node_lives_on(ros_graph, gripper_exe, tmp_path):
    start_oddities(ros_graph, gripper_exe)
    tree = tmp_path / "odd.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n    - force_success:\n        call: oddities.vendor\n"
                    "    - call: oddities.ok\n")
    out = run("run", str(tree), "-q")
    assert out.returncode == 0, out.stdout + out.stderr
    lines = call_lines(out.stdout)
    assert "failed" in lines[0] and "an exception that is not a std::exception" in lines[0], lines
    assert "succeeded" in lines[1], lines


def test_output_names_that_do_not_match_the_outputs_stop_the_cpp_node_at_start(ros_graph, gripper_exe):
    exe = os.path.join(os.path.dirname(gripper_exe), "test_module")
    out = subprocess.run([exe, "--bad-names", "__name:=odd_names"], capture_output=True, text=True, timeout=60,
                         env=ros_graph.env, stdin=subprocess.DEVNULL)
    assert out.returncode == 2, out.stdout + out.stderr
    assert 'provide("two"): the function returns 2 outputs, so it needs 2 non-empty output names' in (
        out.stdout + out.stderr), out.stdout + out.stderr


def test_basic_mod_renames_the_cpp_node_too(ros_graph, gripper_exe):
    """Two copies of one C++ module, told apart by _basic_mod:= alone, both stay up."""
    import rosgraph

    from tests.conftest import until

    left = ros_graph.start_node([gripper_exe, "_basic_mod:=left_gripper"], "/left_gripper")
    right = ros_graph.start_node([gripper_exe, "_basic_mod:=right_gripper"], "/right_gripper")

    def inputs_now():
        return {t: n for t, n in rosgraph.Master("/test").getSystemState()[1] if t.endswith("/BM_input")}

    # a node is registered before its subscriptions are (under load, one had none yet)
    until(lambda: len(inputs_now()) >= 2, 20, inputs_now)
    inputs = inputs_now()
    assert inputs.get("/left_gripper/BM_input") == ["/left_gripper"], inputs
    assert inputs.get("/right_gripper/BM_input") == ["/right_gripper"], inputs
    assert left.poll() is None and right.poll() is None


def test_original_cpp_module_runs_unchanged_behind_the_bridge(ros_graph, tmp_path):
    """DEMO_BM as the original C++ node behaves (last value per topic, no call ids, silence for
    unknown functions): the bridge speaks its protocol with an input gap.

    The original protocol orders nothing across topics, and the node hears its own outputs: on a
    loaded machine a 10 ms gap leaves about 1% of calls on stale inputs (README, C++ modules).
    This test is about compatibility, not that race, so it leaves the node and the bridge time
    to spare: the node's own 1 s wait shortened to 0.2 s, a 0.2 s input gap (50 ms lost an
    input once in CI-like load: the node's own echo of an output can land after the next
    call's input; under make test's full load the node's echo of functionA's text once landed after
    functionB's Contexto, 0.4 s on: the tree leaves it half a second to arrive between calls)."""
    ros_graph.start_node([sys.executable, os.path.join(NODES, "original_cpp_demo_bm.py"), "_delay:=0.2"], "/DEMO_BM")
    definition = os.path.join(REFERENCE, "DEMO_BM.json")
    ros_graph.start_node(["-m", "modules.bridge", "--definition", definition, "--input-gap", "0.2"],
                         "/DEMO_BM_bridge")
    wait_announced("DEMO_BM")
    tree = tmp_path / "demo.yaml"
    tree.write_text("""format: 1
root:
  sequence:
    - call: DEMO_BM.functionA
      inputs: {Aviso: hola, Bandera: true}
      outputs: {status: s1}
    - wait: 0.5
    - call: DEMO_BM.functionB
      inputs: {LSB: true, Contexto: invert}
      outputs: {flag: f}
    - wait: 0.5
    - call: DEMO_BM.functionA
      inputs: {Aviso: adios, Bandera: false}
      outputs: {status: s2}
    - check: 's1 == "hola:si" and f == False and s2 == "adios:no"'
""")
    log = tmp_path / "demo.jsonl"
    out = run("run", str(tree), "-q", "--record", str(log))
    assert out.returncode == 0, out.stdout + out.stderr + (log.read_text() if log.exists() else "")
    assert len([line for line in call_lines(out.stdout) if "succeeded" in line]) == 3


def test_a_definition_that_does_not_match_the_cpp_node_stops_the_bridge_at_start(ros_graph, gripper_exe, tmp_path):
    """The library's BM_info lists each function's input topics and output names: the bridge
    compares them with its definition before it serves anything (exit 2, every difference named)."""
    with open(GRIPPER_JSON) as fh:
        data = json.load(fh)
    reach = next(f for f in data["Functions"] if f["Name"] == "reach")
    reach["Output-params"][1]["Name"] = "dist"
    data["Functions"].append({"Name": "open", "Exec-condition": "", "Description": "Not in the C++ code.",
                              "Input-params": [], "Output-params": []})
    bad = tmp_path / "gripper.json"
    bad.write_text(json.dumps(data))
    ros_graph.start_node([gripper_exe], "/gripper")
    out = subprocess.run(bmtree_cmd_of_bridge(str(bad)), capture_output=True, text=True, timeout=60,
                         env=dict(os.environ), stdin=subprocess.DEVNULL)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "error: %s does not match the C++ node: " % bad in out.stderr, out.stderr
    assert "function 'open' is not provided by the C++ node /gripper (it provides ping, reach, set_fingers, " \
           "squeeze)" in out.stderr, out.stderr
    assert "function 'reach' returns distance on /gripper/float64, final_pos on /gripper/point in the C++ node " \
           "/gripper, but the definition's Output-params are dist on /gripper/float64" in out.stderr, out.stderr
    assert "Traceback" not in out.stderr


def bmtree_cmd_of_bridge(definition, *options):
    return [sys.executable, "-m", "modules.bridge", "--definition", definition, "--wait", "10", *options]


def test_bridge_without_its_cpp_node_says_what_is_missing(ros_master):
    out = subprocess.run([sys.executable, "-m", "modules.bridge", "--definition", GRIPPER_JSON, "--wait", "0.5",
                          "__name:=lonely_bridge"], capture_output=True, text=True, timeout=60,
                         env=dict(os.environ, ROS_IP="127.0.0.1"))
    assert out.returncode == 3, out.stdout + out.stderr
    assert "the C++ node of module 'gripper' is not ready after 0.5s: no node subscribes /gripper/BM_input" in out.stderr
    assert "Traceback" not in out.stderr


def test_example_runs_clean_under_address_and_undefined_sanitizers(ros_graph, gripper_asan_exe, tmp_path):
    cpp, _bridge = start_gripper(ros_graph, gripper_asan_exe,
                                 env={"ASAN_OPTIONS": "detect_leaks=1",
                                      "UBSAN_OPTIONS": "print_stacktrace=1"})
    tree = tmp_path / "all.yaml"
    tree.write_text(ALL_FUNCTIONS + """    - force_success:
        call: gripper.squeeze
        name: cancelled
        inputs: {seconds: 30.0, label: cancelled}
        timeout: 0.3
""")
    out = run("run", str(tree), "-q")
    assert out.returncode == 0, out.stdout + out.stderr
    assert "timeout" in call_lines(out.stdout)[-1], out.stdout
    time.sleep(0.5)  # the cancel's way to the C++ node
    cpp.send_signal(signal.SIGINT)
    assert cpp.wait(30) == 0
    ros_graph.nodes.remove(cpp)
    log = _node_log(ros_graph, "gripper")
    assert "squeeze cancelled, fingers stopped" in log, log[-4000:]  # the cancel thread ran, under ASan
    assert "AddressSanitizer" not in log and "runtime error" not in log, log[-4000:]


def _wait_until(what, check, graph, node, proc, timeout=20.0):
    """Until ``check()``; fails at once, with its log, if the node ``node`` (process ``proc``) ends."""
    def ready():
        assert proc.poll() is None, "%s exited with %s before %s:\n%s" % (
            node, proc.returncode, what, _node_log(graph, node)[-3000:])
        return check()

    until(ready, timeout, lambda: "no %s:\n%s" % (what, _node_log(graph, node)[-3000:]))


def _wait_served(graph, bridge, uri):
    """Until the bridge ``bridge`` (at ``uri``) announces the gripper (it found and checked the C++ node)."""
    from modules.discovery import live_modules

    _wait_until("announcement", lambda: getattr(live_modules(graph.uri).get("gripper"), "uri", None) == uri, graph,
                "gripper_bridge", bridge, 30)


def _start_bridge(graph, *options):
    bridge = graph.start_node(["-m", "modules.bridge", "--definition", GRIPPER_JSON, *options], "/gripper_bridge")
    _, _, uri = xmlrpc.client.ServerProxy(graph.uri).lookupNode("/t", "/gripper_bridge")
    _wait_served(graph, bridge, uri)
    return bridge, uri


def _inbound(node_uri, publisher_uri):
    """The topics on which the node at ``node_uri`` is connected to the publisher ``publisher_uri``."""
    _, _, links = xmlrpc.client.ServerProxy(node_uri).getBusInfo("/t")
    return {link[4] for link in links if link[2] == "i" and link[1] == publisher_uri}


GRIP = ALL_FUNCTIONS.split("    - call: gripper.reach")[0]  # set_fingers and its check


@pytest.mark.parametrize("build", ["gripper_exe", "gripper_asan_exe"])
def test_a_cpp_module_registers_again_after_a_master_restart(own_graph, build, request, tmp_path):
    """kill -9 of rosmaster and a new one on the same port: the C++ node registers its topics again
    (roscpp never does), keeping its connections to a bridge that has not registered again yet; a
    run through that bridge goes on, and a bridge started afterwards finds the C++ node. Its prints
    reach its log file while it runs (stdout line-buffered), and it stops clean (ASan too)."""
    graph = own_graph
    cpp = graph.start_node([request.getfixturevalue(build)], "/gripper",
                           env={"ASAN_OPTIONS": "detect_leaks=1", "UBSAN_OPTIONS": "print_stacktrace=1"})
    log = functools.partial(_node_log, graph, "gripper")
    _wait_until("'ready' line in the log while it runs", lambda: "C++ basic module gripper ready" in log(), graph,
                "gripper", cpp, 10)
    bridge, bridge_uri = _start_bridge(graph)
    master = xmlrpc.client.ServerProxy(graph.uri)
    cpp_uri = master.lookupNode("/t", "/gripper")[2]
    linked = _inbound(cpp_uri, bridge_uri)
    assert {"/gripper/BM_input", "/gripper/float64"} <= linked, linked
    tree = tmp_path / "grip.yaml"
    tree.write_text(GRIP)

    bridge.send_signal(signal.SIGSTOP)  # so that it cannot register again before the C++ node does
    try:
        _restart_master(graph)
        _wait_until("new registration", lambda: "registered again with the restarted ROS master" in log(), graph,
                    "gripper", cpp, 10)
        _, _, (_, subs, _) = master.getSystemState("/t")
        assert ["/gripper/BM_input", ["/gripper"]] in subs, subs
        assert _inbound(cpp_uri, bridge_uri) == linked  # roscpp drops a publisher missing from an update
    finally:
        bridge.send_signal(signal.SIGCONT)
    for new_bridge in (False, True):  # the bridge that ran on, then one started after the restart
        if new_bridge:
            graph.stop_node(bridge)
            _start_bridge(graph, "--wait", "10")
        else:
            _wait_served(graph, bridge, bridge_uri)  # registered again, announcement set again
        out = subprocess.run(bmtree_cmd("run", str(tree), "-q"), capture_output=True, text=True, timeout=120,
                             env=graph.env, stdin=subprocess.DEVNULL)
        assert out.returncode == 0, out.stdout + out.stderr + _node_log(graph, "gripper_bridge")[-3000:]
    cpp.send_signal(signal.SIGINT)
    assert cpp.wait(30) == 0, log()[-4000:]
    graph.nodes.remove(cpp)
    assert "AddressSanitizer" not in log() and "runtime error" not in log(), log()[-4000:]


def test_a_cpp_node_stopped_during_a_call_stops_the_function_too(ros_graph, gripper_exe, tmp_path):
    """Ctrl-C (SIGINT) to the C++ node during a 30 s squeeze: sleepFor() sees the shutdown, so the
    process ends at once instead of finishing the squeeze (a respawned node would drive the
    fingers beside it)."""
    cpp, _bridge = start_gripper(ros_graph, gripper_exe)
    tree = tmp_path / "long.yaml"
    tree.write_text("format: 1\nroot:\n  call: gripper.squeeze\n  inputs: {seconds: 30.0, label: long}\n")
    run_proc = subprocess.Popen(bmtree_cmd("run", str(tree)), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, env=dict(os.environ), stdin=subprocess.DEVNULL)
    try:
        for line in run_proc.stdout:
            if "RUNNING" in line and "gripper.squeeze" in line:
                break
        time.sleep(0.3)
        cpp.send_signal(signal.SIGINT)
        t0 = time.monotonic()
        assert cpp.wait(30) == 0
        stopped = time.monotonic() - t0
        ros_graph.nodes.remove(cpp)
        out, _ = run_proc.communicate(timeout=60)
    finally:
        if run_proc.poll() is None:
            run_proc.kill()
    assert stopped < 5.0, stopped  # not after the squeeze's 30 s
    assert "the C++ node /gripper exited during the call" in out, out


def test_modules_cpp_is_also_a_catkin_package(tmp_path):
    """Configured as catkin configures a package of a workspace; it exports the library's headers."""
    build = tmp_path / "build"
    out = subprocess.run(["cmake", "-S", CPP, "-B", str(build), "-DCATKIN_DEVEL_PREFIX=%s" % (tmp_path / "devel"),
                          "-DPYTHON_EXECUTABLE=/usr/bin/python3"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    config = tmp_path / "devel" / "share" / "bmtree_cpp" / "cmake" / "bmtree_cppConfig.cmake"
    assert os.path.join(CPP, "include") in config.read_text()


def test_an_installed_library_is_found_by_find_package(gripper_exe, tmp_path):
    """cmake --install puts a package config beside the header: another plain-CMake project builds
    a module with find_package(bmtree_cpp) and the target bmtree::module."""
    prefix = tmp_path / "prefix"
    out = subprocess.run(["cmake", "--install", os.path.dirname(gripper_exe), "--prefix", str(prefix)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert not (prefix / "bin").exists(), os.listdir(str(prefix / "bin"))  # the library only: no example in bin
    project = tmp_path / "my_module"
    project.mkdir()
    (project / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.10)\nproject(my_module CXX)\nset(CMAKE_CXX_STANDARD 14)\n"
        "find_package(bmtree_cpp REQUIRED)\nadd_executable(my_module my_module.cpp)\n"
        "target_link_libraries(my_module PRIVATE bmtree::module)\n"
        "target_compile_options(my_module PRIVATE -Wall -Wextra -Werror)\n")
    (project / "my_module.cpp").write_text(
        "#include <bmtree/basic_module.h>\n#include <std_msgs/Bool.h>\n\n"
        "class Mine : public bmtree::BasicModule {\n public:\n"
        "  explicit Mine(ros::NodeHandle nh) : BasicModule(nh, \"mine\") { provide(\"ping\", &Mine::ping, {\"success\"}); }\n"
        "  std::tuple<std_msgs::Bool> ping() { std_msgs::Bool ok; ok.data = !cancelled(); return std::make_tuple(ok); }\n"
        "};\n\nint main(int argc, char** argv) { return bmtree::run<Mine>(argc, argv, \"mine\"); }\n")
    build = tmp_path / "build"
    for cmd in (["cmake", "-S", str(project), "-B", str(build), "-DCMAKE_PREFIX_PATH=%s" % prefix],
                ["cmake", "--build", str(build)]):
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, "%s:\n%s%s" % (" ".join(cmd), out.stdout[-3000:], out.stderr[-3000:])
    assert os.access(build / "my_module", os.X_OK)
    flags = (build / "CMakeFiles" / "my_module.dir" / "flags.make").read_text()
    assert "%s/include" % prefix in flags and CPP not in flags, flags  # the installed header, not the source tree's


SANITIZER_ENV = {"ASAN_OPTIONS": "detect_leaks=1", "UBSAN_OPTIONS": "print_stacktrace=1"}


def _stop_clean(graph, cpp, log):
    """SIGINT to the C++ node: it exits 0, and its log has no sanitizer report."""
    cpp.send_signal(signal.SIGINT)
    assert cpp.wait(30) == 0, log()[-4000:]
    graph.nodes.remove(cpp)
    assert "AddressSanitizer" not in log() and "runtime error" not in log(), log()[-4000:]


TOUCHED = """format: 1
root:
  sequence:
    - call: gripper.reach
      inputs: {target: {x: 0.3, y: -0.1, z: 0.5}}
    - parallel:
        - call: gripper.squeeze
          inputs: {seconds: 30.0, label: hold}
        - sequence:
            - wait_event: gripper.touched
              where: 'force >= 2.0'
              outputs: {force: felt, position: at}
              timeout: 15
            - check: 'felt == 2.5 and at.x == 0.3 and at.y == -0.1 and at.z == 0.5'
      policy: one
"""


@pytest.mark.parametrize("build", ["gripper_exe", "gripper_asan_exe"])
def test_the_example_turns_its_force_sensor_into_events_while_a_function_runs(ros_graph, ros_probe, build, request,
                                                                              tmp_path):
    """emit() from the example's sensor callback (a thread of its own): the event reaches the bridge
    on /gripper/BM_event while squeeze holds the node's spinner thread, the bridge passes it on as
    gripper.touched, and a wait_event takes the one its where: accepts (a lighter touch comes too),
    with the params it gives as outputs; the parallel then halts the squeeze. Under ASan too."""
    import rospy
    from std_msgs.msg import Float64

    from coordinator.testing.ros import wait_subscribed

    cpp = ros_graph.start_node([request.getfixturevalue(build)], "/gripper", env=SANITIZER_ENV)
    log = functools.partial(_node_log, ros_graph, "gripper")
    start = len(log())
    _start_bridge(ros_graph)
    sensor = rospy.Publisher("/gripper/contact", Float64, queue_size=10)
    wait_subscribed(sensor, ["/gripper"])
    tree = tmp_path / "touched.yaml"
    tree.write_text(TOUCHED)
    t0 = time.monotonic()
    proc = subprocess.Popen(bmtree_cmd("run", str(tree), "-q"), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=dict(os.environ), stdin=subprocess.DEVNULL)
    try:
        while proc.poll() is None and time.monotonic() - t0 < 30:  # the sensor until the tree has its touch
            for force in (1.5, 2.5):
                sensor.publish(Float64(force))
            time.sleep(0.2)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out + err + _node_log(ros_graph, "gripper_bridge")[-3000:]
    assert time.monotonic() - t0 < 25  # the squeeze was halted, not waited out
    assert "dropped an event" not in _node_log(ros_graph, "gripper_bridge")
    assert "squeeze cancelled, fingers stopped" in log()[start:], log()[start:]
    _stop_clean(ros_graph, cpp, log)


@pytest.mark.parametrize("build", ["gripper_exe", "gripper_asan_exe"])
def test_a_cpp_call_whose_bridge_is_killed_is_cancelled(ros_graph, build, request, tmp_path):
    """kill -9 of bmtree-bridge a second into a 30 s squeeze: the C++ node sees its caller's connection
    to BM_output drop and its XML-RPC port refuse, and cancels the call as a BM_cancel would (sleepFor
    returns early), saying why; a bridge started again has its calls answered. Under ASan too."""
    import re

    cpp = ros_graph.start_node([request.getfixturevalue(build)], "/gripper", env=SANITIZER_ENV)
    log = functools.partial(_node_log, ros_graph, "gripper")
    start = len(log())
    bridge, _ = _start_bridge(ros_graph)
    tree = tmp_path / "long.yaml"
    tree.write_text("format: 1\nroot:\n  call: gripper.squeeze\n  inputs: {seconds: 30.0, label: long}\n")
    proc = subprocess.Popen(bmtree_cmd("run", str(tree)), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env=dict(os.environ), stdin=subprocess.DEVNULL)
    try:
        for line in proc.stdout:
            if "RUNNING" in line and "gripper.squeeze" in line:
                break
        time.sleep(1.0)
        t0 = time.monotonic()
        ros_graph.kill_node(bridge)
        until(lambda: "squeeze cancelled, fingers stopped" in log()[start:], 10, lambda: log()[start:])
        stopped = time.monotonic() - t0
        out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    said = log()[start:]
    assert stopped < 3.0, (stopped, said)  # not after the squeeze's 30 s
    assert re.search(r"WARN.*bmtree: cancelled call \w+ of gripper\.squeeze: its caller /gripper_bridge is gone "
                     r"\(its process is gone: nothing answers at http://", said), said
    assert said.index("cancelled call") < said.index("squeeze cancelled, fingers stopped"), said
    assert "module_lost" in out, out  # the run lost its module (the bridge)

    _start_bridge(ros_graph)  # a new bridge of the same name: the module takes its calls
    quick = tmp_path / "quick.yaml"
    quick.write_text("format: 1\nroot:\n  call: gripper.squeeze\n  inputs: {seconds: 0.2, label: again}\n"
                     "  outputs: {label: got}\n")
    again = run("run", str(quick), "-q")
    assert again.returncode == 0 and "succeeded" in call_lines(again.stdout)[0], again.stdout + again.stderr
    assert log()[start:].count("cancelled call") == 1, log()[start:]
    _stop_clean(ros_graph, cpp, log)
