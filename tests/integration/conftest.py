"""Integration tests: a real rosmaster (session), real nodes as processes, real topics."""
from __future__ import annotations

import json
import os
import signal
import sys
import time

import pytest
import yaml

from comm import FunctionCall, FunctionResult

NODES = os.path.join(os.path.dirname(__file__), "nodes")

# A shell starts a background job (`make test &`, a CI step run in the background) with SIGINT
# ignored, and its children inherit that: Python then installs no KeyboardInterrupt handler, and
# the tests' Ctrl-C to `bmtree run` would be ignored as the user asked. The processes these tests
# start get the disposition of an interactive shell's.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_modifyitems(items):
    for item in items:
        if "integration" in str(item.fspath):
            item.add_marker(pytest.mark.ros)


@pytest.fixture
def slow_world(tmp_path):
    """The shipped house at 2 m/s: going to the kitchen takes about 4 s."""
    from modules.sim import DEFAULT_WORLD

    with open(DEFAULT_WORLD) as fh:
        world = yaml.safe_load(fh)
    world["speed"] = 2.0
    path = tmp_path / "slow_world.yaml"
    path.write_text(yaml.safe_dump(world))
    return str(path)


def start_sim_module(ros_graph, module, world=None, *params, node=None):
    """Start a sim module; private parameters stay on the master after the node ends, so a node
    given parameters should get its own ``node`` name."""
    from modules.sim import DEFAULT_WORLD

    node = node or "bm_" + module
    args = ["-m", "modules.sim", module, "--world", world or DEFAULT_WORLD, "__name:=" + node, *params]
    proc = ros_graph.start_node(args, "/" + node)
    wait_announced(module)
    return proc


def wait_announced(*modules, timeout=30.0):
    """Until each of ``modules`` is announced: a bridge announces once its C++ node is connected, which it
    waits for up to its --wait, 30 s (under a suite's load, with C++ builds beside it, a start took over 15)."""
    from modules.discovery import live_modules

    end = time.monotonic() + timeout
    while set(modules) - set(live_modules()):
        assert time.monotonic() < end, "modules %s did not announce themselves" % (modules,)
        time.sleep(0.05)


class Caller:
    """Sends calls from the test process and waits for their results on /function/output."""

    def __init__(self, probe, subscribers=1):
        self.probe = probe
        self.results = probe.collect("/function/output")
        self.subscribers = subscribers
        self._pub = probe.publisher("/master/output", subscribers)

    def wait_connected(self, publishers, nodes=()):
        """``publishers`` connected to the results topic and, by name, each of ``nodes`` connected
        both ways: a count alone may be made up by other tests' nodes still running."""
        from rospy.impl.registration import get_topic_manager

        from coordinator.testing.ros import node_uris, wait_subscribed

        # a publisher of /function/output in this process (other tests' probes) connects too
        publishers += 1 if get_topic_manager().has_publication("/function/output") else 0
        wait_subscribed(self._pub, nodes, 10)  # an earlier node of the same name does not pass for one
        uris = node_uris(nodes)
        end = time.monotonic() + 10
        while True:
            results_from = {c.endpoint_id for c in self.results.sub.impl.connections}  # publishers' URIs
            if self.results.sub.get_num_connections() >= publishers and uris <= results_from:
                return
            assert time.monotonic() < end, "result publishers did not connect (%s)" % ", ".join(nodes)
            time.sleep(0.02)

    def wait_answering(self, module, timeout=30.0):
        """Ping ``module`` (the preflight's reserved function) until it answers, as ``bmtree run``
        does before its first call: a first message can be lost to a connection still being set
        up, or held by an earlier test's node of the same name."""
        from comm.addressing import PING_FUNCTION
        from comm.messages import new_id

        end = time.monotonic() + timeout
        while True:
            ping = FunctionCall(module, PING_FUNCTION, [], names=[], call_id=new_id())
            self.send(ping)
            try:
                self.result(ping.call_id, timeout=1.0)
                return self
            except AssertionError:
                assert time.monotonic() < end, "module %s never answered a ping" % module

    def send(self, call):
        from std_msgs.msg import String

        self._pub.publish(String(call.encode() if isinstance(call, FunctionCall) else call))
        return getattr(call, "call_id", None)

    def call(self, defs, qualified, timeout=10.0, **inputs):
        mod, fn = qualified.split(".")
        call = defs[mod].function(fn).build_call(inputs)
        self.send(call)
        return self.result(call.call_id, timeout)

    def result(self, call_id, timeout=10.0):
        text = self.results.wait_for(lambda t: json.loads(t).get("call_id") == call_id, timeout)[0]
        return FunctionResult.decode(text)

    def close(self):
        self.probe.close_collector(self.results)


@pytest.fixture
def caller_factory(ros_probe):
    made = []

    def make(subscribers=1, publishers=1, nodes=(), answering=()):
        """A Caller connected to ``nodes`` whose ``answering`` modules have answered a ping."""
        c = Caller(ros_probe, subscribers)
        made.append(c)
        c.wait_connected(publishers, nodes)
        for module in answering:
            c.wait_answering(module)
        return c

    yield make
    for c in made:
        c.close()


def processes_running(text):
    """Pids of live processes whose command line contains ``text`` (read from /proc: a minimal
    Debian has no pgrep)."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            with open("/proc/%s/cmdline" % entry, "rb") as fh:
                cmdline = fh.read().replace(b"\0", b" ").decode("utf-8", "replace")
            with open("/proc/%s/stat" % entry) as fh:
                state = fh.read().rsplit(")", 1)[1].split()[0]
        except OSError:  # ended meanwhile
            continue
        if text in cmdline and state != "Z":
            found.append(int(entry))
    return found


def bmtree_cmd(*args):
    return [sys.executable, "-m", "coordinator", *args]


@pytest.fixture
def own_graph(tmp_path):
    """A master of the test's own, to kill and restart (the session's must not die)."""
    from coordinator.graph import RosGraph

    graph = RosGraph(str(tmp_path / "ros"))
    graph.start_master()
    try:
        yield graph
    finally:
        graph.close()
