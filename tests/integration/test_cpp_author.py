"""A C++ author's audit of the library and the bridge: late inputs, ros::spinOnce() inside a
function, exceptions, cancels (onCancel, callId, cancelled() from a helper), events (emit() from a
ros::Timer, and ones the definition does not have), a definition that does not match the node, a C++
node that dies, the --call-timeout message, warnings and the installed CMake package.

One test module (``author``, its source below) is built once, -O2 -Werror, with the build helper of
test_cpp_modules. Some tests talk to it directly as a bridge would (this process publishes the
inputs, ``BM_input`` and ``BM_cancel``), to send what bmtree-bridge never sends."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time

import pytest

from tests.conftest import ROOT, until
from tests.integration.conftest import wait_announced
from tests.integration.test_cpp_modules import CPP, _build, _node_log, call_lines, run

AUTHOR_CPP = r"""// bmtree's tests only (tests/integration/test_cpp_author.py writes this file)
#include <bmtree/basic_module.h>

#include <geometry_msgs/Point.h>
#include <geometry_msgs/Pose.h>
#include <std_msgs/Bool.h>
#include <std_msgs/Float64.h>
#include <std_msgs/String.h>

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <tuple>

#if BMTREE_CPP_API >= 2
// a helper of a function polls the module's cancelled() (public)
class Poller {
 public:
  explicit Poller(const bmtree::BasicModule& module) : module_(module) {}
  bool stop() const { return module_.cancelled(); }

 private:
  const bmtree::BasicModule& module_;
};
#endif

static double since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

class Author : public bmtree::BasicModule {
 public:
  explicit Author(ros::NodeHandle nh) : BasicModule(nh, "author"), nh_(nh) {
    provide("move", &Author::move, {"final_pose", "success"});
    provide("spin", &Author::spin, {"spun"});
    provide("ok", &Author::ok, {"success"});
    provide("throws", &Author::throws, {"success"});
    provide("hooked", &Author::hooked, {"stopped"});
    provide("stubborn", &Author::stubborn, {"slept"});
    provide("nothing", &Author::nothing, {});
    provide("announce", &Author::announce, {});
    provide("misemit", &Author::misemit, {});
  }

  std::tuple<geometry_msgs::Pose, std_msgs::Bool> move(const geometry_msgs::Pose& target,
                                                       const std_msgs::Float64& duration) {
    ROS_INFO("author: move ran to z=%g in %gs", target.position.z, duration.data);
    std_msgs::Bool ok;
    ok.data = true;
    return std::make_tuple(target, ok);
  }

  // spins the global queue inside the function, as the audit's module did
  std::tuple<std_msgs::Float64> spin(const std_msgs::Float64& seconds) {
    ROS_INFO("author: spin started");
    const auto start = std::chrono::steady_clock::now();
    while (since(start) < seconds.data) {
      ros::spinOnce();
      if (!sleepFor(0.02)) break;
    }
    std_msgs::Float64 spun;
    spun.data = since(start);
    ROS_INFO("author: spin returned after %.2fs", spun.data);
    return std::make_tuple(spun);
  }

  std::tuple<std_msgs::Bool> ok() const {  // a const method (a getter)
    std_msgs::Bool b;
    b.data = true;
    return std::make_tuple(b);
  }

  std::tuple<std_msgs::Bool> throws(const std_msgs::String& kind) {
    if (kind.data == "runtime") throw std::runtime_error("below the table");
    if (kind.data == "range") throw std::out_of_range("joint 7 of 6");
    if (kind.data == "int") throw 42;
    if (kind.data == "latin1") throw std::runtime_error(std::string("driver: \xDC") + "berlast am Greifer");
    throw bmtree::Failure("asked to fail");
  }

  std::tuple<std_msgs::Bool> hooked(const std_msgs::Float64& seconds) {
    ROS_INFO("author: hooked started");
    std_msgs::Bool stopped;
#if BMTREE_CPP_API >= 2
    const auto start = std::chrono::steady_clock::now();
    const std::string id = callId();
    const std::thread::id me = std::this_thread::get_id();
    std::atomic<int> calls{0};
    std::atomic<bool> elsewhere{false};
    Poller poller(*this);
    bool seen = false;
    {
      bmtree::CancelHook hook = onCancel([&]() {
        elsewhere = std::this_thread::get_id() != me;
        ++calls;
      });
      ROS_INFO("author: hooked hook set");  // a cancel before this runs the hook here, at once
      // stops on the hook alone: a driver's own loop that never looks at cancelled()
      while (calls.load() == 0 && since(start) < seconds.data) {
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(300));  // a second cancel would call it again
      seen = poller.stop();
    }
    stopped.data = calls.load() > 0;
    ROS_INFO("author: hooked call %s: hook ran %d time(s), in another thread: %d, a helper saw cancelled(): %d",
             id.c_str(), calls.load(), elsewhere.load() ? 1 : 0, seen ? 1 : 0);
#else
    stopped.data = !sleepFor(seconds.data);
    ROS_INFO("author: hooked without onCancel()");
#endif
    return std::make_tuple(stopped);
  }

  // never looks at cancels
  std::tuple<std_msgs::Float64> stubborn(const std_msgs::Float64& seconds) {
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds.data));
    return std::make_tuple(seconds);
  }

  std::tuple<> nothing() { return std::tuple<>(); }

  // arms a one-shot ros::Timer (on the node's queue: it fires once this function has returned) that
  // emits personSeen twice: Bob first, then `name`
  std::tuple<> announce(const std_msgs::String& name, const std_msgs::Float64& after) {
    name_ = name.data;
    timer_ = nh_.createTimer(ros::Duration(after.data), &Author::onTimer, this, true);
    return std::tuple<>();
  }

  void onTimer(const ros::TimerEvent&) {
#if BMTREE_CPP_API >= 3
    std_msgs::String bob, name;
    bob.data = "Bob";
    name.data = name_;
    geometry_msgs::Point there, here;
    there.x = -1.0;
    here.x = static_cast<double>(name_.size());
    here.y = 1.0;
    const bool sent = emit("personSeen", {{"name", bob}, {"position", there}}) &&
                      emit("personSeen", {{"name", name}, {"position", here}});
    ROS_INFO("author: emitted personSeen for Bob and %s from a timer: %d", name_.c_str(), sent ? 1 : 0);
#endif
  }

  // what an author gets wrong: the bridge (or emit() itself) refuses each
  std::tuple<> misemit() {
#if BMTREE_CPP_API >= 3
    std_msgs::String ana;
    ana.data = "Ana";
    geometry_msgs::Point point;
    geometry_msgs::Pose pose;
    emit("personSen", {{"name", ana}, {"position", point}});   // no such event
    emit("personSeen", {{"name", ana}, {"position", pose}});   // a Pose, not a Point
    emit("personSeen", {{"name", ana}});                       // no position
    const bool twice = emit("personSeen", {{"name", ana}, {"name", ana}});
    std::vector<bmtree::EventParam> none;
    const bool nameless = emit("", none);
    ROS_INFO("author: misemit sent a name twice: %d, no name: %d", twice ? 1 : 0, nameless ? 1 : 0);
#endif
    return std::tuple<>();
  }

 private:
  ros::NodeHandle nh_;
  ros::Timer timer_;
  std::string name_;
};

int main(int argc, char** argv) { return bmtree::run<Author>(argc, argv, "author"); }
"""


def _param(name, rostype):
    return {"Name": name, "Data-type": rostype, "Description": name}


def _function(name, inputs, outputs):
    return {"Name": name, "Exec-condition": "none", "Description": name,
            "Input-params": [_param(*p) for p in inputs], "Output-params": [_param(*p) for p in outputs]}


POSE, FLOAT, BOOL, STRING = "geometry_msgs/Pose", "std_msgs/Float64", "std_msgs/Bool", "std_msgs/String"
AUTHOR = {
    "Basic Module": "author",
    "Brief Description": "The C++ test module of test_cpp_author.py.",
    "Hardware Required": [],
    "Functions": [
        _function("move", [("target", POSE), ("duration", FLOAT)], [("final_pose", POSE), ("success", BOOL)]),
        _function("spin", [("seconds", FLOAT)], [("spun", FLOAT)]),
        _function("ok", [], [("success", BOOL)]),
        _function("throws", [("kind", STRING)], [("success", BOOL)]),
        _function("hooked", [("seconds", FLOAT)], [("stopped", BOOL)]),
        _function("stubborn", [("seconds", FLOAT)], [("slept", FLOAT)]),
        _function("nothing", [], []),
        _function("announce", [("name", STRING), ("after", FLOAT)], []),
        _function("misemit", [], []),
    ],
    "Events": [
        {"Name": "personSeen", "Description": "Someone was seen.",
         "Event-params": [_param("name", STRING), _param("position", "geometry_msgs/Point")]},
    ],
}


@pytest.fixture(scope="session")
def author_exe():
    """The module above, built once (-O2, -Wall -Wextra -Wpedantic -Werror) in build/cpp-author."""
    build = os.path.join(ROOT, "build", "cpp-author")
    source = os.path.join(build, "author.cpp")
    os.makedirs(build, exist_ok=True)
    if not os.path.exists(source) or open(source).read() != AUTHOR_CPP:  # unchanged: nothing to rebuild
        with open(source, "w") as fh:
            fh.write(AUTHOR_CPP)
    _build(build, "-DCMAKE_BUILD_TYPE=Release", "-DBMTREE_TEST_MODULE=" + source)
    return os.path.join(build, "test_module")


@pytest.fixture(scope="session")
def author_json(tmp_path_factory):
    path = tmp_path_factory.mktemp("author") / "author.json"
    path.write_text(json.dumps(AUTHOR))
    return str(path)


class Log:
    """What a node started by the graph prints from now on (its log file is shared by the session)."""

    def __init__(self, graph, node):
        self.graph, self.node = graph, node
        self.start = len(_node_log(graph, node)) if os.path.exists(self._path()) else 0

    def _path(self):
        return os.path.join(self.graph.ros_home, "%s.out" % self.node)

    def text(self):
        return _node_log(self.graph, self.node)[self.start:]

    def wait(self, text, timeout=10.0):
        until(lambda: text in self.text(), timeout, lambda: "no %r in the log of %s:\n%s" % (
            text, self.node, self.text()[-3000:]))


def start_author(graph, exe, *args):
    log = Log(graph, "author")
    proc = graph.start_node([exe, *args], "/author")
    log.wait("C++ basic module author ready")
    return proc, log


class FakeBridge:
    """This test process as a bridge: it publishes the inputs and BM_input itself."""

    _pubs = {}  # one publisher per topic for the whole session (rospy keeps them anyway)

    def __init__(self, ros_probe):
        import rospy
        from geometry_msgs.msg import Pose
        from std_msgs.msg import Float64, String

        from comm import settle_new_connection
        from coordinator.testing.ros import wait_subscribed

        self.probe = ros_probe
        for topic, cls in (("/author/BM_input", String), ("/author/BM_cancel", String), ("/author/float64", Float64),
                           ("/author/pose", Pose)):
            if topic not in self._pubs:
                self._pubs[topic] = rospy.Publisher(topic, cls, queue_size=100)
            wait_subscribed(self._pubs[topic], ["/author"])
        self.outputs = ros_probe.collect("/author/BM_output", nodes=["/author"])
        settle_new_connection()

    def close(self):
        self.probe.close_collector(self.outputs)

    def value(self, seconds):
        from std_msgs.msg import Float64

        self._pubs["/author/float64"].publish(Float64(seconds))

    def call(self, function, topics, call_id=None, names=None):
        from std_msgs.msg import String

        sync = {"function": function, "inparam_topics": topics}
        if call_id is not None:
            sync["call_id"] = call_id
        if names is not None:
            sync["inparam_names"] = names
        self._pubs["/author/BM_input"].publish(String(json.dumps(sync)))

    def cancel(self, call_id):
        from std_msgs.msg import String

        self._pubs["/author/BM_cancel"].publish(String(json.dumps({"call_id": call_id})))

    def answer(self, call_id, timeout=10.0):
        """The BM_output of call ``call_id`` (None: the original protocol's, which has no call id)."""
        found = self.outputs.wait_for(lambda t: json.loads(t).get("call_id") == call_id, timeout)
        return json.loads(found[0])

    def answered(self):
        return [json.loads(t).get("call_id") for t in self.outputs.items]


@pytest.fixture
def fake_bridge(ros_graph, author_exe, ros_probe):
    """The author module (its input wait shortened to 0.3 s) and this process as its bridge."""
    _proc, log = start_author(ros_graph, author_exe, "_input_wait:=0.3")
    bridge = FakeBridge(ros_probe)
    try:
        yield bridge, log
    finally:
        bridge.close()


def test_a_call_whose_inputs_do_not_arrive_fails_and_does_not_run(fake_bridge):
    """bmtree-bridge's call (with a call_id) whose target never came: answered failed, the inputs
    named, and the function (a motion to a zero pose) not run. The original bridge's call (no
    call_id) runs on the last values, as the original library did, with a warning."""
    bridge, log = fake_bridge
    bridge.value(2.0)  # the duration; the target never comes
    bridge.call("move", ["/author/pose", "/author/float64"], "late-1", ["target", "duration"])
    out = bridge.answer("late-1")
    assert out["status"] == "failed", out
    assert out["error"] == "input 'target' did not arrive within input_wait (0.3s): move was not run", out
    bridge.call("move", ["/author/pose", "/author/float64"], "late-2", ["target", "duration"])
    out = bridge.answer("late-2")
    assert out["error"] == "inputs 'target', 'duration' did not arrive within input_wait (0.3s): move was not run"
    assert "author: move ran" not in log.text()

    bridge.value(3.0)
    bridge.call("move", ["/author/pose", "/author/float64"])  # the original bridge: no call_id, no names
    out = bridge.answer(None)
    assert "error" not in out and out["outparam_names"] == ["final_pose", "success"], out
    log.wait("author: move ran to z=0 in 3s")
    log.wait("move (no call id): input 1 (on /author/pose) did not arrive within input_wait (0.3s): it runs with "
             "the last value received on its topic")


def test_spin_once_inside_a_function_does_not_lose_a_later_cancel(fake_bridge):
    """A BM_input that arrives while a function spins the queue waits until the function has
    returned: run inside it, it took the running call's place, and the cancel that came next was lost."""
    bridge, log = fake_bridge
    bridge.value(8.0)
    bridge.call("spin", ["/author/float64"], "spin-1")
    log.wait("author: spin started")
    bridge.call("ok", [], "ok-1")  # received by the spinOnce() inside spin
    time.sleep(0.5)
    bridge.cancel("spin-1")
    out = bridge.answer("spin-1", timeout=4.0)  # not after the 8 s
    assert out["status"] == "cancelled", out
    assert "error" not in bridge.answer("ok-1"), bridge.outputs.items
    assert bridge.answered() == ["spin-1", "ok-1"]  # one call after the other


def test_on_cancel_runs_once_in_the_cancel_thread_and_call_id_names_the_call(fake_bridge):
    bridge, log = fake_bridge
    bridge.value(10.0)
    bridge.call("hooked", ["/author/float64"], "hook-1")
    log.wait("author: hooked hook set")   # (a cancel that came before would run the hook in the call's thread)
    bridge.cancel("hook-1")
    time.sleep(0.1)
    bridge.cancel("hook-1")  # a cancel sent twice: the callback still runs once
    out = bridge.answer("hook-1", timeout=4.0)
    assert out["status"] == "cancelled", out
    log.wait("author: hooked call hook-1: hook ran 1 time(s), in another thread: 1, a helper saw cancelled(): 1")


@pytest.fixture
def author(ros_graph, author_exe, author_json):
    """The author module behind bmtree-bridge (--call-timeout 0.5)."""
    proc, log = start_author(ros_graph, author_exe)
    bridge_log = Log(ros_graph, "author_bridge")
    ros_graph.start_node(["-m", "modules.bridge", "--definition", author_json, "--call-timeout", "0.5"],
                         "/author_bridge")
    wait_announced("author")
    return proc, log, bridge_log


def _run_tree(tmp_path, modules, body):
    tree = tmp_path / "tree.yaml"
    tree.write_text("format: 1\nroot:\n  sequence:\n" + body)
    out = run("run", str(tree), "-q", "--modules", modules)
    assert out.returncode == 0, out.stdout + out.stderr
    return call_lines(out.stdout)


def test_an_exception_is_logged_and_answered_with_its_type(author, author_json, tmp_path):
    _, log, _ = author
    lines = _run_tree(tmp_path, author_json, "".join(
        "    - force_success:\n        call: author.throws\n        inputs: {kind: %s}\n" % kind
        for kind in ("runtime", "range", "int", "latin1")) + "    - call: author.nothing\n")
    assert "failed" in lines[0] and "std::runtime_error: below the table" in lines[0], lines
    assert "std::out_of_range: joint 7 of 6" in lines[1], lines
    assert "int: an exception that is not a std::exception" in lines[2], lines
    # a Latin-1 what() (a vendor's driver): before, nlohmann's dump() threw out of the callback, the node died
    assert "std::runtime_error: driver: \ufffdberlast am Greifer" in lines[3], lines
    assert "succeeded" in lines[4], lines  # a function with no outputs (std::tuple<>); the node lives
    text = log.text()
    assert re.search(r"ERROR.*bmtree: throws \(call \w+\) threw std::runtime_error: below the table", text), text
    assert re.search(r"ERROR.*bmtree: throws \(call \w+\) threw int, which is not a std::exception", text), text


def test_the_call_timeout_message_says_what_happened(author, author_json, tmp_path):
    """A function that honours the cancel stopped; one that does not look at it has not answered."""
    lines = _run_tree(tmp_path, author_json,
                      "    - force_success:\n        call: author.spin\n        inputs: {seconds: 30.0}\n"
                      "    - force_success:\n        call: author.stubborn\n        inputs: {seconds: 1.5}\n")
    said = "no BM_output from the C++ node /author within 0.5s (the bridge's --call-timeout): author.%s exceeded " \
           "the call timeout and was cancelled"
    assert said % "spin" + "; the function stopped" in lines[0], lines
    assert said % "stubborn" + ", but the C++ node did not answer within 0.5s of the cancel" in lines[1], lines
    assert not any("hangs or crashed" in line for line in lines), lines


def test_the_bridge_logs_the_death_of_its_cpp_node(ros_graph, author):
    cpp, _, bridge_log = author
    ros_graph.kill_node(cpp)
    bridge_log.wait("the C++ node /author of module 'author' died (killed or crashed: nothing listens at http", 10)
    time.sleep(1.5)
    assert bridge_log.text().count("died") == 1, bridge_log.text()  # one line, not one a second
    assert "and it is still registered with the master); calls are refused until it is started again" in \
        bridge_log.text()


def test_an_event_emitted_from_a_timer_is_taken_by_a_wait_event(author, author_json, tmp_path):
    """emit() in a ros::Timer's callback: one BM_event message per event, which the bridge reads
    (genpy), checks against the definition and passes on; the wait_event's where: skips Bob's."""
    _, log, bridge_log = author
    lines = _run_tree(tmp_path, author_json,
                      "    - call: author.announce\n      inputs: {name: Ana, after: 0.5}\n"
                      "    - wait_event: author.personSeen\n      where: 'name == \"Ana\"'\n"
                      "      outputs: {position: at, name: who}\n      timeout: 10\n"
                      "    - check: 'who == \"Ana\" and at.x == 3.0 and at.y == 1.0 and at.z == 0.0'\n")
    assert len(lines) == 1 and "succeeded" in lines[0], lines
    log.wait("author: emitted personSeen for Bob and Ana from a timer: 1")
    assert "dropped an event" not in bridge_log.text(), bridge_log.text()


def test_events_that_the_definition_does_not_have_are_dropped_with_a_warning(author, author_json, tmp_path,
                                                                            ros_probe):
    """A BM_event published by hand (not JSON, and a well-formed one from another node) and the
    author's mistakes (an unknown event, a param of another type, a missing param) are each dropped
    with a warning that names the node that sent it; the bridge serves on. emit() itself refuses a
    param given twice and an event without a name."""
    from std_msgs.msg import String

    from comm import settle_new_connection
    from coordinator.testing.ros import wait_subscribed

    _, log, bridge_log = author
    by_hand = ros_probe.publisher("/author/BM_event", 0)
    wait_subscribed(by_hand, ["/author_bridge"])
    settle_new_connection()
    by_hand.publish(String("{not json"))
    by_hand.publish(String(json.dumps({"event": "personSeen", "params": [
        {"name": "name", "type": STRING, "md5sum": "992ce8a1687cec8c8bd883ec73ca41d1", "data": "AwAAAEFuYQ=="},
        {"name": "position", "type": "geometry_msgs/Point", "md5sum": "4a842b65f413084dc2b10fb484ea7f17",
         "data": "A" * 32}]})))
    bridge_log.wait("on /author/BM_event, which is not the C++ node of module 'author' (/author): payload is not "
                    "valid JSON")
    bridge_log.wait("which is not the C++ node of module 'author' (/author): events are taken from the C++ node only")

    lines = _run_tree(tmp_path, author_json, "    - call: author.misemit\n    - call: author.ok\n")
    assert len(lines) == 2 and all("succeeded" in line for line in lines), lines  # it serves on
    said = "dropped an event from the C++ node /author of module 'author': "
    bridge_log.wait(said + "module 'author' has no event 'personSen' (did you mean 'personSeen'?)")
    bridge_log.wait(said + "event 'personSeen': param 'position' is a geometry_msgs/Pose in the C++ node, but the "
                    "definition's Event-params say geometry_msgs/Point")
    bridge_log.wait(said + "event 'personSeen': missing param 'position'")
    log.wait("author: misemit sent a name twice: 0, no name: 0")
    text = log.text()
    assert "bmtree: emit(\"personSeen\"): param 'name' is given twice; nothing sent" in text, text
    assert "bmtree: emit(): an event needs a name; nothing sent" in text, text
    assert "Traceback" not in bridge_log.text()


def test_a_definition_that_does_not_match_the_node_stops_the_bridge_at_once(ros_graph, author_exe, tmp_path):
    """An output of another type is a data topic the node never publishes: the bridge compares the
    node's BM_info first and exits 2 naming every difference, instead of waiting --wait (30 s) for
    that topic and exiting 3."""
    start_author(ros_graph, author_exe)
    data = json.loads(json.dumps(AUTHOR))
    functions = {f["Name"]: f for f in data["Functions"]}
    functions["spin"]["Output-params"][0]["Data-type"] = "std_msgs/Int64"       # -> /author/int64
    functions["move"]["Output-params"][0]["Name"] = "pose"
    functions["move"]["Input-params"].reverse()
    bad = tmp_path / "author.json"
    bad.write_text(json.dumps(data))
    t0 = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "modules.bridge", "--definition", str(bad)], capture_output=True,
                         text=True, timeout=60, env=ros_graph.env, stdin=subprocess.DEVNULL)
    assert out.returncode == 2, out.stdout + out.stderr
    assert time.monotonic() - t0 < 15
    err = out.stderr
    assert "error: %s does not match the C++ node: " % bad in err, err
    assert "function 'spin' returns spun on /author/float64 in the C++ node /author, but the definition's " \
           "Output-params are spun on /author/int64 (spun on /author/float64 there, /author/int64 in the " \
           "definition)" in err, err
    assert "function 'move' takes its inputs on [\"/author/pose\", \"/author/float64\"] in the C++ node" in err, err
    assert "function 'move' returns final_pose on /author/pose, success on /author/bool in the C++ node /author, " \
           "but the definition's Output-params are pose on /author/pose, success on /author/bool (only in the " \
           "C++ node: final_pose; only in the definition: pose)" in err, err
    assert "Traceback" not in err


STRICT = ["-Wall", "-Wextra", "-Wpedantic", "-Wshadow", "-Wconversion", "-Wsign-conversion", "-Wold-style-cast",
          "-Werror"]


def test_the_header_is_clean_under_strict_warnings(tmp_path):
    """A module built with -Wsign-conversion and friends gets no warning from the library's headers."""
    source = tmp_path / "strict.cpp"
    source.write_text(AUTHOR_CPP)
    out = subprocess.run(["g++", "-std=c++14", "-fsyntax-only", *STRICT, "-I", os.path.join(CPP, "include"),
                          "-isystem", "/usr/include/xmlrpcpp", str(source)], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-4000:]


def test_output_names_written_as_a_list_are_counted_when_the_module_is_compiled(tmp_path):
    """provide("x", &C::f, {"reached"}) for a function of two outputs compiled, and the node stopped at
    start on the robot; the braced list's length is now checked by the compiler."""
    source = tmp_path / "names.cpp"
    source.write_text(AUTHOR_CPP.replace('provide("ok", &Author::ok, {"success"});',
                                         'provide("ok", &Author::ok, {"success", "extra"});'))
    out = subprocess.run(["g++", "-std=c++14", "-fsyntax-only", "-I", os.path.join(CPP, "include"),
                          "-isystem", "/usr/include/xmlrpcpp", str(source)], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode != 0 and "bmtree provide(): give one output name per element of the std::tuple the " \
        "function returns" in out.stderr, out.stderr[-3000:]


def test_the_installed_package_exports_cxx14_system_headers_and_no_paths_of_this_machine(author_exe, tmp_path):
    prefix = tmp_path / "prefix"
    out = subprocess.run(["cmake", "--install", os.path.dirname(author_exe), "--prefix", str(prefix)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    targets = (prefix / "lib" / "cmake" / "bmtree_cpp" / "bmtree_cppTargets.cmake").read_text()
    props = targets.split("set_target_properties(bmtree::module PROPERTIES", 1)[1].split(")", 1)[0]
    assert 'INTERFACE_COMPILE_FEATURES "cxx_std_14"' in props, props
    assert 'INTERFACE_SYSTEM_INCLUDE_DIRECTORIES "${_IMPORT_PREFIX}/include"' in props, props
    assert "/usr/" not in props and ".so" not in props, props  # roscpp is found again where the module is built


def test_the_readme_tells_a_cpp_author_what_the_audit_missed():
    with open(os.path.join(ROOT, "README.md")) as fh:
        readme = fh.read()
    section = readme.split("### C++ modules", 1)[1].split("\n## ", 1)[0]
    for said in ("find_package(catkin REQUIRED COMPONENTS roscpp bmtree_cpp", "<depend>bmtree_cpp</depend>",
                 "${catkin_LIBRARIES}", '<bmtree definitions="arm.json"/>', "ros::spinOnce()", "AsyncSpinner",
                 "onCancel(", "callId()", "std::isfinite", "std::tuple<>", '"Hardware Required"', "input_wait",
                 "MultiThreadedSpinner", "-B", "emit(\"touched\"", "BM_event", "its caller /gripper_bridge is gone"):
        assert said in section, said
