"""A second C++ audit's findings, each on a real C++ module built with the library (``hooks``, its source
below, -O2 -Werror, and again under ASan/UBSan) and the real bmtree-bridge:

- an onCancel() callback of a cancelled call runs once, always, also when the function sees the cancel
  (sleepFor() returns) and drops its CancelHook before the cancel thread came to the callback;
- a function that throws bmtree::Failure("") or bmtree::Rejected("") answers failed or rejected with a
  text saying that it gave none (it was taken for a success, or for missing outputs);
- bmtree-bridge takes --max-bytes N, as the other module nodes do;
- a bridge stopped at start because its C++ node serves another module's name says the fix first, so
  that ``bmtree run --sim`` (which quotes 200 characters of the bridge's last error) keeps it.

Some tests talk to the C++ node directly as a bridge would (this process publishes ``BM_input`` and
``BM_cancel``), to cancel at chosen moments."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time

import pytest

from tests.conftest import ROOT, until
from tests.integration.conftest import bmtree_cmd, wait_announced
from tests.integration.test_cpp_author import Log
from tests.integration.test_cpp_modules import SANITIZER_ENV, SANITIZERS, _build, _node_log, call_lines, run

HOOKS_CPP = r"""// bmtree's tests only (tests/integration/test_cpp_audit_fixes.py writes this file)
#include <bmtree/basic_module.h>

#include <std_msgs/Bool.h>
#include <std_msgs/String.h>

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <tuple>

static double since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

class Hooks : public bmtree::BasicModule {
 public:
  explicit Hooks(ros::NodeHandle nh) : BasicModule(nh, "hooks") {
    provide("two_hooks", &Hooks::twoHooks, {});
    provide("one_hook", &Hooks::oneHook, {});
    provide("fail_quietly", &Hooks::failQuietly, {});
    provide("reject_quietly", &Hooks::rejectQuietly, {"success"});
    provide("throw_quietly", &Hooks::throwQuietly, {"success"});
    provide("echo", &Hooks::echo, {"text"});
  }

  // The function sees the cancel (sleepFor returns false) and leaves the second callback's scope; should
  // the cancel thread come to the first callback before, it is held there until the second's CancelHook
  // is dropped: either way the cancel thread has not come to the second one then. It must run all the
  // same, once.
  std::tuple<> twoHooks() {
    const auto start = std::chrono::steady_clock::now();
    const std::thread::id me = std::this_thread::get_id();
    std::atomic<int> first{0};
    std::atomic<int> second{0};
    std::atomic<bool> second_here{false};
    std::atomic<bool> second_dropped{false};
    {
      bmtree::CancelHook hold = onCancel([&]() {
        ++first;
        const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(3);
        while (!second_dropped.load() && std::chrono::steady_clock::now() < until) {
          std::this_thread::sleep_for(std::chrono::milliseconds(2));
        }
      });
      {
        bmtree::CancelHook halt = onCancel([&]() {
          ++second;
          second_here = std::this_thread::get_id() == me;
        });
        ROS_INFO("hooks: two_hooks set");
        while (sleepFor(0.01) && since(start) < 10.0) {
        }
      }
      second_dropped = true;
    }
    ROS_INFO("hooks: two_hooks call %s: first ran %d, second ran %d, the second in the function's thread: %d",
             callId().c_str(), first.load(), second.load(), second_here.load() ? 1 : 0);
    return std::tuple<>();
  }

  // the audit's arm: one callback (a driver's halt) and a loop on sleepFor(), which returns at the cancel
  std::tuple<> oneHook() {
    const auto start = std::chrono::steady_clock::now();
    std::atomic<int> ran{0};
    {
      bmtree::CancelHook hook = onCancel([&]() { ++ran; });
      while (sleepFor(0.001) && since(start) < 10.0) {
      }
    }
    ROS_INFO("hooks: one_hook call %s: hook ran %d", callId().c_str(), ran.load());
    return std::tuple<>();
  }

  std::tuple<> failQuietly() { throw bmtree::Failure(""); }
  std::tuple<std_msgs::Bool> rejectQuietly() { throw bmtree::Rejected(""); }
  std::tuple<std_msgs::Bool> throwQuietly() { throw std::runtime_error(""); }
  std::tuple<std_msgs::String> echo(const std_msgs::String& text) { return std::make_tuple(text); }
};

int main(int argc, char** argv) { return bmtree::run<Hooks>(argc, argv, "hooks"); }
"""


def _function(name, inputs=(), outputs=()):
    def param(p):
        return {"Name": p[0], "Data-type": p[1], "Description": p[0]}

    return {"Name": name, "Exec-condition": "none", "Description": name,
            "Input-params": [param(p) for p in inputs], "Output-params": [param(p) for p in outputs]}


BOOL, STRING = "std_msgs/Bool", "std_msgs/String"
HOOKS = {
    "Basic Module": "hooks",
    "Brief Description": "The C++ test module of test_cpp_audit_fixes.py.",
    "Hardware Required": [],
    "Functions": [
        _function("two_hooks"),
        _function("one_hook"),
        _function("fail_quietly"),
        _function("reject_quietly", outputs=[("success", BOOL)]),
        _function("throw_quietly", outputs=[("success", BOOL)]),
        _function("echo", [("text", STRING)], [("text", STRING)]),
    ],
}


def _hooks_exe(build, *options):
    source = os.path.join(build, "hooks.cpp")
    os.makedirs(build, exist_ok=True)
    if not os.path.exists(source) or open(source).read() != HOOKS_CPP:  # unchanged: nothing to rebuild
        with open(source, "w") as fh:
            fh.write(HOOKS_CPP)
    _build(build, *options, "-DBMTREE_TEST_MODULE=" + source)
    return os.path.join(build, "test_module")


@pytest.fixture(scope="session")
def hooks_exe():
    """The module above, -O2, -Wall -Wextra -Wpedantic -Werror, in build/cpp-hooks."""
    return _hooks_exe(os.path.join(ROOT, "build", "cpp-hooks"), "-DCMAKE_BUILD_TYPE=Release")


@pytest.fixture(scope="session")
def hooks_asan_exe():
    """The same under AddressSanitizer and UndefinedBehaviorSanitizer, in build/cpp-hooks-asan."""
    return _hooks_exe(os.path.join(ROOT, "build", "cpp-hooks-asan"), "-DCMAKE_BUILD_TYPE=None",
                      "-DCMAKE_CXX_FLAGS=" + SANITIZERS)


@pytest.fixture(scope="session")
def hooks_json(tmp_path_factory):
    path = tmp_path_factory.mktemp("hooks") / "hooks.json"
    path.write_text(json.dumps(HOOKS))
    return str(path)


def start_hooks(graph, exe):
    log = Log(graph, "hooks")
    proc = graph.start_node([exe], "/hooks", env=SANITIZER_ENV)
    log.wait("C++ basic module hooks ready")
    return proc, log


class FakeBridge:
    """This test process as the bridge of ``hooks``: it publishes BM_input and BM_cancel itself."""

    _pubs = {}  # one publisher per topic for the whole session (rospy keeps them anyway)

    def __init__(self, ros_probe):
        import rospy
        from std_msgs.msg import String

        from comm import settle_new_connection
        from coordinator.testing.ros import wait_subscribed

        self.probe = ros_probe
        for topic in ("/hooks/BM_input", "/hooks/BM_cancel"):
            if topic not in self._pubs:
                self._pubs[topic] = rospy.Publisher(topic, String, queue_size=100)
            wait_subscribed(self._pubs[topic], ["/hooks"])
        self.outputs = ros_probe.collect("/hooks/BM_output", nodes=["/hooks"])
        settle_new_connection()

    def close(self):
        self.probe.close_collector(self.outputs)

    def call(self, function, call_id):
        from std_msgs.msg import String

        self._pubs["/hooks/BM_input"].publish(String(json.dumps(
            {"function": function, "inparam_topics": [], "call_id": call_id, "inparam_names": []})))

    def cancel(self, call_id):
        from std_msgs.msg import String

        self._pubs["/hooks/BM_cancel"].publish(String(json.dumps({"call_id": call_id})))

    def answer(self, call_id, timeout=10.0):
        found = self.outputs.wait_for(lambda t: json.loads(t).get("call_id") == call_id, timeout)
        return json.loads(found[0])


@pytest.mark.parametrize("build", ["hooks_exe", "hooks_asan_exe"])
def test_a_callback_whose_hook_the_function_dropped_after_the_cancel_still_runs_once(ros_graph, ros_probe, build,
                                                                                     request):
    """The audit's race, made certain: the function, which saw the cancel through sleepFor(), drops the
    second callback's CancelHook before the cancel thread came to it (held in the first callback, if it
    got there at all). Before, such a callback never ran (hooks=18 of 20 cancels in the audit, where only
    the threads' scheduling decided); now the CancelHook's destructor runs it, in the function's thread,
    once. Under ASan too."""
    proc, log = start_hooks(ros_graph, request.getfixturevalue(build))
    bridge = FakeBridge(ros_probe)
    try:
        for i in range(3):
            call_id = "two-%d" % i
            bridge.call("two_hooks", call_id)
            until(lambda n=i: log.text().count("hooks: two_hooks set") > n, 10, lambda: log.text()[-3000:])
            bridge.cancel(call_id)
            out = bridge.answer(call_id, timeout=8.0)
            assert out["status"] == "cancelled", out
            log.wait("hooks: two_hooks call %s: first ran 1, second ran 1, the second in the function's thread: 1"
                     % call_id)
    finally:
        bridge.close()
    text = _node_log(ros_graph, "hooks")
    assert "AddressSanitizer" not in text and "runtime error" not in text, text[-4000:]
    assert proc.poll() is None


def test_every_cancel_of_a_sleeping_function_runs_its_callback_once(ros_graph, ros_probe, hooks_exe):
    """The audit's arm.move_to, cancelled at once 30 times: each call's callback ran exactly once."""
    _proc, log = start_hooks(ros_graph, hooks_exe)
    bridge = FakeBridge(ros_probe)
    try:
        for i in range(30):
            call_id = "one-%d" % i
            bridge.call("one_hook", call_id)
            time.sleep(0.02 + 0.01 * (i % 5))
            bridge.cancel(call_id)
            assert bridge.answer(call_id)["status"] == "cancelled"
            log.wait("hooks: one_hook call %s: hook ran" % call_id)
    finally:
        bridge.close()
    ran = re.findall(r"hooks: one_hook call one-\d+: hook ran (\d+)", log.text())
    assert ran == ["1"] * 30, ran


@pytest.fixture
def hooks_bridge(ros_graph, hooks_exe, hooks_json):
    """The module behind bmtree-bridge, given --max-bytes 4000000."""
    proc, log = start_hooks(ros_graph, hooks_exe)
    ros_graph.start_node(["-m", "modules.bridge", "--definition", hooks_json, "--max-bytes", "4000000"],
                         "/hooks_bridge")
    wait_announced("hooks")
    return proc, log


def _run_tree(tmp_path, hooks_json, body, *options):
    tree = tmp_path / "tree.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n" + body)
    out = run("run", str(tree), "-q", "--modules", hooks_json, *options)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return call_lines(out.stdout)


def test_a_function_that_throws_with_an_empty_text_fails_or_is_rejected_saying_so(hooks_bridge, hooks_json,
                                                                                  tmp_path):
    """bmtree::Failure("") in a function with no outputs was answered succeeded; bmtree::Rejected("") in one
    with outputs failed, blaming the definition for a missing output."""
    _, log = hooks_bridge
    lines = _run_tree(tmp_path, hooks_json, "".join("    - force_success:\n        call: hooks.%s\n" % f for f in (
        "fail_quietly", "reject_quietly", "throw_quietly")))
    assert len(lines) == 3, lines
    assert lines[0].split()[3] == "failed" and \
        'the C++ function gave no message (it threw bmtree::Failure(""))' in lines[0], lines
    assert lines[1].split()[3] == "rejected" and \
        'the C++ function gave no message (it threw bmtree::Rejected(""))' in lines[1], lines
    assert lines[2].split()[3] == "failed" and "std::runtime_error, with no message" in lines[2], lines
    assert not any("does not match the definition" in line for line in lines), lines
    log.wait('bmtree: fail_quietly (call ')
    assert 'failed: the C++ function gave no message (it threw bmtree::Failure(""))' in log.text(), log.text()


def test_the_bridge_takes_max_bytes(hooks_bridge, hooks_json, tmp_path):
    """bmtree-bridge --max-bytes 4000000 (it was refused: unrecognized arguments): a call of 2.5 MB is
    taken and answered, where 1 MiB, the default, would refuse it."""
    text = "x" * 2500000
    lines = _run_tree(tmp_path, hooks_json, "    - call: hooks.echo\n      inputs: {text: %s}\n"
                      "      outputs: {text: back}\n    - check: 'len(back) == %d'\n" % (text, len(text)),
                      "--max-bytes", "8000000")
    assert len(lines) == 1 and lines[0].split()[3] == "succeeded", [line[:300] for line in lines]


def test_bridge_help_lists_max_bytes():
    out = subprocess.run([sys.executable, "-m", "modules.bridge", "--help"], capture_output=True, text=True,
                         timeout=60, cwd=ROOT, stdin=subprocess.DEVNULL)
    assert out.returncode == 0 and "--max-bytes" in out.stdout, out.stdout + out.stderr


def test_a_misnamed_cpp_node_under_run_sim_is_said_with_its_fix(hooks_exe, tmp_path):
    """The C++ code names its module 'hooks', the definition 'hand': ``bmtree run --sim`` quotes the bridge's
    last error line cut to 200 characters, which cut off the fix (BasicModule(nh, "hand")) when the
    definition's path was long."""
    folder = tmp_path / ("a_rather_long_folder_name_for_the_definitions_of_the_robots_modules_" * 2)
    folder.mkdir()
    hand = dict(HOOKS, **{"Basic Module": "hand"})
    (folder / "hand.json").write_text(json.dumps(hand))
    tree = tmp_path / "hand.yaml"
    tree.write_text("format: 1\nname: hand\nroot:\n  call: hand.fail_quietly\n")
    out = subprocess.run(bmtree_cmd("run", "--sim", "--module", "%s=%s" % (folder / "hand.json", hooks_exe),
                                    str(tree)), capture_output=True, text=True, timeout=180, cwd=str(tmp_path),
                         env=dict(os.environ, ROS_HOME=str(tmp_path / "ros")), stdin=subprocess.DEVNULL)
    assert out.returncode in (2, 3), out.stdout + out.stderr
    quoted = [line for line in out.stderr.splitlines() if "serves module 'hooks'" in line]
    assert quoted and 'BasicModule(nh, "hand")' in quoted[0], out.stderr
    assert quoted[0].strip().startswith("error: node /hand serves module 'hooks', but the definition is module "
                                        "'hand': the name given to BasicModule in the C++ code must be the "
                                        "definition's"), out.stderr

