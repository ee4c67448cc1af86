"""The measures of ``make bench``. Each returns Rows; baselines are measured in the same run."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from typing import Any, Callable, Dict, List

import py_trees

from bench.stats import Row, summary
from coordinator.builder import build_tree
from coordinator.clock import RealClock
from coordinator.context import RunContext
from coordinator.graph import RosGraph
from coordinator.language import load_tree
from coordinator.runner import TreeRunner

__all__ = ["call_latency", "cpp_call_latency", "tick_cost", "load_cost", "blackboard_throughput", "blackboard_latency",
           "mocked_tree_tests", "memory", "record_cost"]

PING_TEXT = "x" * 64


def _rss_kib(pid: int = 0) -> int:
    with open("/proc/%s/status" % (pid or "self")) as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


def _raw_pingpong(payload: str, n: int) -> List[float]:
    """Round trips of a std_msgs/String between this process and the echo node."""
    import rospy
    from std_msgs.msg import String

    got = threading.Event()
    sub = rospy.Subscriber("/bench/pong", String, lambda m: got.set(), queue_size=100, tcp_nodelay=True)
    pub = rospy.Publisher("/bench/ping", String, queue_size=100, tcp_nodelay=True)
    while pub.get_num_connections() < 1 or sub.get_num_connections() < 1:
        time.sleep(0.01)
    msg = String(payload)
    out = []
    for i in range(n + 20):
        got.clear()
        t0 = time.perf_counter()
        pub.publish(msg)
        if not got.wait(5):
            raise RuntimeError("echo node did not answer")
        if i >= 20:
            out.append(time.perf_counter() - t0)
    sub.unregister()
    pub.unregister()
    return out


def _action_client() -> Any:
    """A SimpleActionClient of the bench's action server, connected."""
    import actionlib
    from move_base_msgs.msg import MoveBaseAction

    from bench.nodes import ACTION

    client = actionlib.SimpleActionClient(ACTION, MoveBaseAction)
    if not client.wait_for_server(_ros_duration(30.0)):
        raise RuntimeError("the actionlib bench server did not come up")
    return client


def _ros_duration(seconds: float) -> Any:
    import rospy

    return rospy.Duration.from_sec(seconds)


def _actionlib_goals(client: Any, n: int) -> List[float]:
    """Goal round trips: from sending a goal to its DONE transition (the result arrived).

    Sent through the SimpleActionClient's ActionClient with a transition callback, which is
    what ``SimpleActionClient.send_goal`` does minus its race: it records the goal handle only
    after publishing the goal, so a result that comes back first is dropped ("a goal handle
    that we're not tracking") and the goal never ends; with a server that answers at once this
    hung the first bench run.
    """
    from actionlib import CommState
    from move_base_msgs.msg import MoveBaseGoal

    goal = MoveBaseGoal()
    goal.target_pose.header.frame_id = "map"
    goal.target_pose.pose.position.x = 8.6
    goal.target_pose.pose.orientation.w = 1.0
    done = threading.Event()

    def transition(gh: Any) -> None:
        if gh.get_comm_state() == CommState.DONE:
            done.set()

    out = []
    for i in range(n + 20):
        done.clear()
        t0 = time.perf_counter()
        handle = client.action_client.send_goal(goal, transition)  # noqa: F841 - kept alive until done
        if not done.wait(5):
            raise RuntimeError("the actionlib server did not answer")
        if i >= 20:
            out.append(time.perf_counter() - t0)
    _drain_status(client)
    return out


def _drain_status(client: Any, timeout: float = 15.0) -> None:
    """Wait until the server's status array is empty again: it lists every goal of the last 5 s and
    is republished (5 Hz and on every transition), which would load the measures that follow."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        last = client.action_client.last_status_msg
        if last is not None and not last.status_list:
            return
        time.sleep(0.1)


def _tree_file(tmp: str, name: str, body: str) -> str:
    path = os.path.join(tmp, name)
    with open(path, "w") as fh:
        fh.write("format: 1\n" + body)
    return path


def _calls_in_running_tree_records(tree: Any, transport: Any, defs: Dict[str, Any]) -> List[Any]:
    ctx = RunContext(transport, RealClock(), defs)
    result = TreeRunner(build_tree(tree, ctx), ctx, period=1.0).run()
    if not result.succeeded:
        raise RuntimeError("bench tree failed: %s" % result.reason)
    return result.calls


def _calls_in_running_tree(tree: Any, transport: Any, defs: Dict[str, Any]) -> List[float]:
    """Durations of every call of one run: from the leaf sending to the leaf's SUCCESS."""
    return [c.ended - c.started for c in _calls_in_running_tree_records(tree, transport, defs)]


def call_latency(graph: RosGraph, tmp: str, n: int) -> List[Row]:
    """A call leaf in a running tree → the bench module → SUCCESS, against raw ping-pong;
    then a sequence of 10 such calls, start of the first to end of the last."""
    from std_msgs.msg import String

    from comm import FunctionCall
    from coordinator.ros_transport import RosTransport
    from modules.definition import load_definition

    defs = {"bench": load_definition(os.path.join(os.path.dirname(__file__), "bench_module.json"))}
    transport = RosTransport("bench_coordinator")
    transport.wait_ready(["bench"], 30, defs)
    payload = FunctionCall("bench", "ping", [String(PING_TEXT)], names=["text"]).encode()
    block = n // 4
    loop = load_tree(_tree_file(tmp, "loop.yaml", "root:\n  repeat: %d\n  child:\n    call: bench.ping\n"
                                "    inputs: {text: %s}\n" % (block, PING_TEXT)), defs)
    chain = "root:\n  sequence:\n" + "".join("    - call: bench.ping\n      inputs: {text: %s}\n" % PING_TEXT
                                             for _ in range(10))
    ten = load_tree(_tree_file(tmp, "ten.yaml", chain), defs)
    _calls_in_running_tree(loop, transport, defs)  # warm-up: connections, caches
    client = _action_client()
    _actionlib_goals(client, 20)
    raw, ours, spans, goals = [], [], [], []
    for _ in range(4):  # interleaved, so that machine noise hits all alike
        raw.extend(_raw_pingpong(payload, block))
        ours.extend(_calls_in_running_tree(loop, transport, defs))
        goals.extend(_actionlib_goals(client, block))
        for _ in range(max(5, block // 10)):
            calls = _calls_in_running_tree_records(ten, transport, defs)
            spans.append(calls[-1].ended - calls[0].started)
    r, o, c, a = summary(raw), summary(ours), summary(spans), summary(goals)
    transport.close()  # its subscribers would otherwise also decode the later measures' traffic
    ms = 1000.0
    return [
        Row("call leaf round trip, median", o["median"] * ms, "ms", r["median"] * ms, "<= 1.5x",
            o["median"] <= 1.5 * r["median"], {"ours": o, "raw": r, "actionlib": a, "payload_bytes": len(payload)}),
        Row("call leaf round trip, p99", o["p99"] * ms, "ms", r["p99"] * ms, "<= 2x", o["p99"] <= 2 * r["p99"]),
        Row("sequence of 10 calls, median", c["median"] * ms, "ms", 10 * o["median"] * ms, "<= 1.05x",
            c["median"] <= 1.05 * 10 * o["median"], {"chain": c}),
        Row("call leaf vs actionlib goal round trip, median", o["median"] * ms, "ms", a["median"] * ms, "<= 1x",
            o["median"] <= a["median"], {"actionlib": a}),
        Row("call leaf vs actionlib goal round trip, p99", o["p99"] * ms, "ms", a["p99"] * ms, "<= 1x",
            o["p99"] <= a["p99"]),
    ]


def _build_cpp_example() -> str:
    """The C++ example module, built with cmake (-O2) into build/cpp (incremental)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    build = os.path.join(root, "build", "cpp")
    for cmd in (["cmake", "-S", os.path.join(root, "modules", "cpp"), "-B", build, "-DBMTREE_WERROR=ON",
                 "-DCMAKE_BUILD_TYPE=Release"], ["cmake", "--build", build]):
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return os.path.join(build, "gripper")


def cpp_call_latency(graph: RosGraph, tmp: str, n: int) -> List[Row]:
    """A call leaf → bmtree-bridge → the C++ example module (an immediate function) → SUCCESS,
    against raw ping-pong, interleaved."""
    from std_msgs.msg import String

    from comm import FunctionCall
    from coordinator.ros_transport import RosTransport
    from modules.definition import load_definition

    exe = _build_cpp_example()
    definition = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "modules", "cpp",
                              "example", "gripper.json")
    cpp = graph.start_node([exe], "/gripper")
    bridge = graph.start_node(["-m", "modules.bridge", "--definition", definition], "/gripper_bridge")
    defs = {"gripper": load_definition(definition)}
    transport = RosTransport("bench_coordinator")
    transport.wait_ready(["gripper"], 30, defs)
    payload = FunctionCall("bench", "ping", [String(PING_TEXT)], names=["text"]).encode()
    block = n // 4
    loop = load_tree(_tree_file(tmp, "cpp_loop.yaml", "root:\n  repeat: %d\n  child:\n    call: gripper.ping\n"
                                % block), defs)
    _calls_in_running_tree(loop, transport, defs)  # warm-up
    raw, ours = [], []
    for _ in range(4):
        raw.extend(_raw_pingpong(payload, block))
        ours.extend(_calls_in_running_tree(loop, transport, defs))
    transport.close()
    graph.stop_node(bridge)
    graph.stop_node(cpp)
    r, o = summary(raw), summary(ours)
    ms = 1000.0
    return [Row("C++ call leaf round trip via bmtree-bridge, median", o["median"] * ms, "ms", r["median"] * ms,
                "<= 4x", o["median"] <= 4 * r["median"], {"ours": o, "raw": r})]


def _hand_tree(n: int) -> py_trees.behaviour.Behaviour:
    return py_trees.composites.Sequence("root", memory=False, children=[
        py_trees.behaviours.Success(name="leaf %d" % i) for i in range(n)])


def _yaml_tree_text(n: int) -> str:
    return "root:\n  sequence:\n    memory: false\n    children:\n" + "".join(
        "      - check: 'true'\n        name: leaf %d\n" % i for i in range(n))


def _offline(path: str) -> Any:
    from coordinator.testing.inprocess import InProcessTransport
    from coordinator.testing.mocks import Mocks

    defs: Dict[str, Any] = {}
    tree = load_tree(path, defs)
    ctx = RunContext(InProcessTransport(Mocks(defs), RealClock()), RealClock(), defs)
    root = build_tree(tree, ctx)
    root.setup_with_descendants()
    root.bmtree_ctx = ctx
    return root


def _time_ticks(root: py_trees.behaviour.Behaviour, ticks: int) -> float:
    root.tick_once()
    t0 = time.perf_counter()
    for _ in range(ticks):
        root.tick_once()
    return (time.perf_counter() - t0) / ticks


def tick_cost(tmp: str) -> List[Row]:
    rows = []
    for n, ticks in ((100, 300), (1000, 40)):
        path = _tree_file(tmp, "flat%d.yaml" % n, _yaml_tree_text(n))
        ours_root = _offline(path)
        hand_root = _hand_tree(n)
        hand_root.setup_with_descendants()
        ours, hand = [], []
        for _ in range(15):  # alternate often: this machine's speed drifts within seconds
            hand.append(_time_ticks(hand_root, ticks // 3))
            ours.append(_time_ticks(ours_root, ticks // 3))
        o, h = summary(ours)["median"], summary(hand)["median"]
        rows.append(Row("tick, %d-leaf YAML tree" % n, o * 1000, "ms", h * 1000, "<= 1.1x", o <= 1.1 * h))
    return rows


def record_cost(tmp: str) -> List[Row]:
    """A tick of the 1,000-leaf tree by the runner with the run stream writing a run log (fsync'd
    per tick), against the same runner's tick without them."""
    from coordinator.runevents import notify
    from coordinator.runlog import RunLogWriter
    from coordinator.runstream import RunStream

    path = _tree_file(tmp, "flat1000r.yaml", _yaml_tree_text(1000))
    writer = RunLogWriter(os.path.join(tmp, "bench-run.jsonl"))
    runners = []
    for observers in ([], [RunStream([writer])]):
        root = _offline(path)
        runner = TreeRunner(root, root.bmtree_ctx, observers=observers)
        notify(root.bmtree_ctx.observers, "on_start", None, root, root.bmtree_ctx)
        runners.append(runner)

    def timed(runner: TreeRunner, ticks: int) -> float:
        runner.tick()
        t0 = time.perf_counter()
        for _ in range(ticks):
            runner.tick()
        return (time.perf_counter() - t0) / ticks

    base, ours = [], []
    for _ in range(40):  # alternate often: this machine's speed drifts within seconds
        base.append(timed(runners[0], 5))
        ours.append(timed(runners[1], 5))
    writer.close()
    o, b = summary(ours)["median"], summary(base)["median"]
    return [Row("tick, 1,000-leaf tree, recorded (run log + stream) vs not", o * 1000, "ms", b * 1000, "<= 1.2x",
                o <= 1.2 * b)]


def load_cost(tmp: str) -> List[Row]:
    path = _tree_file(tmp, "load1000.yaml", _yaml_tree_text(999))
    ours, hand = [], []
    for _ in range(21):  # alternate often: this machine's speed drifts within seconds
        t0 = time.perf_counter()
        _offline(path)
        ours.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        _hand_tree(999).setup_with_descendants()
        hand.append(time.perf_counter() - t0)
    o, h = summary(ours)["median"], summary(hand)["median"]
    return [Row("load + validate + build a 1,000-node YAML tree", o * 1000, "ms", h * 1000, "<= 3x", o <= 3 * h)]


def blackboard_throughput(graph: RosGraph, tmp: str, seconds: float = 10.0, rate: float = 2500.0) -> List[Row]:
    """3 publisher processes for ``seconds`` at ``rate`` each; every result must end up in the store."""
    db = os.path.join(tmp, "throughput.sqlite")
    bb = graph.start_node(["-m", "blackboard.node", "--db", db, "--keep", "1000000"], "/blackboard")
    pubs = [subprocess.Popen([sys.executable, "-m", "bench.nodes", "publish", str(i), str(rate), str(seconds)],
                             env=graph.env, stdout=subprocess.PIPE, text=True) for i in range(3)]
    sent = sum(int(p.communicate(timeout=seconds + 60)[0].strip().splitlines()[-1]) for p in pubs)
    from blackboard.store import Store

    end = time.monotonic() + 30
    stored = 0
    while time.monotonic() < end:
        store = Store(db)
        stored = store.count()
        store.close()
        if stored >= sent:
            break
        time.sleep(0.2)
    graph.stop_node(bb)
    per_s = stored / seconds
    return [Row("Blackboard: results stored per second (3 publishers, %gs, WAL)" % seconds, per_s, "/s", None,
                ">= 5000/s, none lost", per_s >= 5000 and stored == sent,
                {"sent": sent, "stored": stored, "lost": sent - stored})]


def blackboard_latency(graph: RosGraph, tmp: str, n: int) -> List[Row]:
    import rospy
    from std_msgs.msg import Float64, String

    from comm import BlackboardAnswer, BlackboardRequest, FunctionResult

    db = os.path.join(tmp, "latency.sqlite")
    bb = graph.start_node(["-m", "blackboard.node", "--db", db], "/blackboard")
    pub_res = rospy.Publisher("/function/output", String, queue_size=100)
    pub = rospy.Publisher("/blackboard/input", String, queue_size=100, tcp_nodelay=True)
    got = threading.Event()
    sub = rospy.Subscriber("/blackboard/output", String, lambda m: got.set(), queue_size=100, tcp_nodelay=True)
    while pub.get_num_connections() < 1 or sub.get_num_connections() < 1 or pub_res.get_num_connections() < 1:
        time.sleep(0.01)
    pub_res.publish(String(FunctionResult(["apple"], [Float64(1.0)], call_id="x").encode()))
    time.sleep(0.5)
    req = BlackboardRequest(["apple"], request_id="r").encode()
    answer_size = len(BlackboardAnswer(["apple"], [Float64(1.0)], request_id="r").encode())
    ours, raw = [], []
    for _ in range(4):  # interleaved blocks, as for calls
        for i in range(n // 4 + 10):
            got.clear()
            t0 = time.perf_counter()
            pub.publish(String(req))
            if not got.wait(5):
                raise RuntimeError("the Blackboard did not answer")
            if i >= 10:
                ours.append(time.perf_counter() - t0)
        raw.extend(_raw_pingpong("x" * answer_size, n // 4))
    sub.unregister()
    graph.stop_node(bb)
    o, r = summary(ours), summary(raw)
    return [Row("Blackboard request -> answer, median", o["median"] * 1000, "ms", r["median"] * 1000, "<= 1.5x",
                o["median"] <= 1.5 * r["median"], {"ours": o, "raw": r})]


def mocked_tree_tests() -> List[Row]:
    """Each shipped tree's mocked-module test, as in tests/unit/test_shipped_trees.py."""
    from coordinator.testing import TreeTest

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

    def scripted(path: str) -> Callable[[], Any]:
        def run() -> Any:
            t = TreeTest(path)
            where = {"room": ""}

            def go_to(place: str) -> Dict[str, Any]:
                where["room"] = place
                return {"room": place}

            t.mocks["navigation.go_to"].respond(go_to)
            t.mocks["vision.find_object"].respond(lambda object: {"success": where["room"] == "bedroom"})
            t.mocks["vision.find_person"].respond(lambda name: {"success": where["room"] == "bedroom"})
            t.mocks["speech.listen"].succeed(text="yes")
            result = t.run()
            assert result.succeeded, result.reason
        return run

    rows = []
    for name in ("find_apple.yaml", "invite_to_dining_room.yaml"):
        fn = scripted(os.path.join(root, "trees", name))
        fn()
        xs = []
        for _ in range(20):
            t0 = time.perf_counter()
            fn()
            xs.append(time.perf_counter() - t0)
        m = summary(xs)["median"] * 1000
        rows.append(Row("mocked test of %s (load + run)" % name, m, "ms", None, "< 50 ms", m < 50))
    return rows


def memory(graph: RosGraph, tmp: str, results: int = 100000) -> List[Row]:
    """RSS of a coordinator holding a 1,000-node tree; the Blackboard's RSS and store after
    ``results`` results, sampled at half-way too: retention must keep both flat."""
    out = subprocess.run([sys.executable, "-m", "bench.nodes", "rss-tree",
                          _tree_file(tmp, "mem1000.yaml", _yaml_tree_text(999))],
                         capture_output=True, text=True, timeout=120, check=True)
    imports_kib, with_tree_kib = map(int, out.stdout.split())
    db = os.path.join(tmp, "memory.sqlite")
    keep = 1000
    bb = graph.start_node(["-m", "blackboard.node", "--db", db, "--keep", str(keep)], "/blackboard")
    from blackboard.store import Store

    samples = []
    sent = 0
    rate, each = 4000.0, results // 4
    for phase in range(2):
        pubs = [subprocess.Popen([sys.executable, "-m", "bench.nodes", "publish", "m%d%d" % (phase, i), str(rate),
                                  "600", str(each)], env=graph.env, stdout=subprocess.PIPE, text=True)
                for i in range(2)]
        sent += sum(int(p.communicate(timeout=600)[0].strip().splitlines()[-1]) for p in pubs)
        time.sleep(2.0)
        store = Store(db)
        samples.append((_rss_kib(bb.pid), store.count()))
        store.close()
    graph.stop_node(bb)
    names = 2 * 2 * 10
    bound = names * keep + 2000  # retention runs every 2,000 stored values
    (rss1, rows1), (rss2, rows2) = samples
    return [
        Row("memory: process with a 1,000-node tree loaded and ticked (RSS)", with_tree_kib / 1024.0, "MiB",
            imports_kib / 1024.0, "report", None, {"after_imports_kib": imports_kib}),
        Row("memory: Blackboard node RSS after %d results" % sent, rss2 / 1024.0, "MiB", rss1 / 1024.0,
            "bounded by retention", rows2 <= bound and rss2 <= rss1 * 1.25,
            {"rss_half_kib": rss1, "rss_end_kib": rss2, "values_kept_half": rows1, "values_kept_end": rows2,
             "retention_bound": bound}),
    ]


def versions() -> Dict[str, str]:
    import platform

    import rospy

    try:
        import py_trees.version as v

        pt = v.__version__
    except ImportError:
        pt = getattr(py_trees, "__version__", "?")
    return {"python": platform.python_version(), "py_trees": pt,
            "rospy": getattr(rospy, "__version__", None) or _pkg_version("rospy")}


def _pkg_version(name: str) -> str:
    try:
        from importlib.metadata import version

        return version(name)
    except Exception:
        return "?"


def dump(rows: List[Row], meta: Dict[str, Any], path: str) -> None:
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as fh:
        json.dump({"meta": meta, "rows": [r.as_dict() for r in rows]}, fh, indent=1)
