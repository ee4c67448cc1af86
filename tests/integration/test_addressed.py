"""Addressed calls over real topics: own topics announced, run once, a stopped module, many calls."""
from __future__ import annotations

import json
import os
import signal
import threading

from bench.scale import check_round, module_name, round_tree, write_definitions
from comm import FunctionCall, FunctionResult
from coordinator.builder import build_tree
from coordinator.clock import RealClock
from coordinator.context import RunContext
from coordinator.language import load_tree
from coordinator.ros_transport import RosTransport
from coordinator.runner import TreeRunner
from modules.definition import load_definition
from tests.integration.conftest import wait_announced


def _start_modules(ros_graph, tmp_path, n):
    paths = write_definitions(str(tmp_path / "defs"), n)
    procs = [ros_graph.start_node(["-m", "bench.scale", "module", p], "/bm_%s" % module_name(i))
             for i, p in enumerate(paths)]
    wait_announced(*[module_name(i) for i in range(n)])
    return procs, {module_name(i): load_definition(p) for i, p in enumerate(paths)}


def _run(tree_text, tmp_path, transport, defs, given=None, name="tree.yaml"):
    path = tmp_path / name
    path.write_text("format: 1\n" + tree_text)
    tree = load_tree(str(path), defs, given=set(given or {}))
    ctx = RunContext(transport, RealClock(), defs, default_timeout=120)
    return TreeRunner(build_tree(tree, ctx, given), ctx, period=1.0).run()


def test_a_module_announces_its_topics_and_runs_a_call_sent_on_both_once(ros_graph, ros_probe, tmp_path):
    from modules.discovery import live_modules

    _, defs = _start_modules(ros_graph, tmp_path, 1)
    live = live_modules()["scale00"]
    assert (live.call_topic, live.cancel_topic) == ("/bmtree/call/scale00", "/bmtree/cancel/scale00")
    results = ros_probe.collect("/function/output", publishers=1)
    try:
        shared, own = ros_probe.publisher("/master/output"), ros_probe.publisher("/bmtree/call/scale00")
        from std_msgs.msg import String

        twice = FunctionCall("scale00", "f00", [String("once")], names=["text"], call_id="twice")
        for pub in (shared, own):
            pub.publish(String(twice.encode()))
        for i, pub in enumerate((shared, own)):  # each topic's own order: these come after the duplicates
            pub.publish(String(FunctionCall("scale00", "f01", [String("s")], names=["text"],
                                            call_id="after%d" % i).encode()))
        results.wait_for(lambda t: json.loads(t).get("call_id") in ("after0", "after1", "twice"), 30, count=3)
        answers = [FunctionResult.decode(t) for t in results.items]
        assert [a.call_id for a in answers].count("twice") == 1
        assert {a.values["text"].data for a in answers if a.call_id == "twice"} == {"once"}
    finally:
        ros_probe.close_collector(results)


def test_a_stopped_module_does_not_stall_calls_to_the_others(ros_graph, tmp_path):
    """scale02 is stopped (SIGSTOP) mid-run, just after answering its first call; the tree then
    sends it 200 calls of 100 kB each, far more than the sockets hold, while a sequence of 20
    calls to the other two modules must still be answered and end the run."""
    procs, defs = _start_modules(ros_graph, tmp_path, 3)
    stopped = procs[2]
    transport = RosTransport("test_sigstop")
    transport.wait_ready(list(defs), 60, defs)
    connect = transport.connect

    def connect_and_stop_on_first_answer(deliver):
        def first(item):
            if isinstance(item, FunctionResult) and item.basic_mod == "scale02" and stopped.poll() is None:
                if not getattr(first, "done", False):
                    first.done = True
                    os.kill(stopped.pid, signal.SIGSTOP)  # before the runner sees the answer
            deliver(item)
        connect(first)

    transport.connect = connect_and_stop_on_first_answer
    big = "".join("                - call: scale02.f01\n                  inputs: {text: $big}\n" for _ in range(200))
    small = "".join("              - call: scale%02d.f02\n                inputs: {text: s%d}\n" % (i % 2, i)
                    for i in range(20))
    tree = ("inputs:\n  big: {}\nroot:\n  sequence:\n    - call: scale02.f00\n      inputs: {text: before}\n"
            "    - parallel:\n        policy: one\n        children:\n"
            "          - parallel:\n              policy: all\n              children:\n" + big +
            "          - sequence:\n" + small)
    out = {}
    runner = threading.Thread(target=lambda: out.setdefault("result", _run(tree, tmp_path, transport, defs,
                                                                         {"big": "x" * 100000})), daemon=True)
    try:
        runner.start()
        runner.join(180)  # a stall would hang here (no timing is asserted: this only bounds a hang)
        assert not runner.is_alive(), "the run stalled behind the stopped module"
        result = out["result"]
        assert result.succeeded, result.reason
        with open("/proc/%d/stat" % stopped.pid) as fh:
            assert fh.read().rsplit(")", 1)[1].split()[0] == "T"  # still stopped all along
        others = [c for c in result.calls if not c.target.startswith("scale02.")]
        assert [c.status for c in others] == ["succeeded"] * 20
        assert [c.result.values["text"].data for c in others] == ["s%d" % i for i in range(20)]
        to_stopped = [c for c in result.calls if c.target == "scale02.f01"]
        assert len(to_stopped) == 200 and {c.status for c in to_stopped} == {"halted"}
    finally:
        transport.close()
        ros_graph.kill_node(stopped)


def test_many_calls_over_five_modules_are_all_answered_and_correlated(ros_graph, tmp_path):
    _, defs = _start_modules(ros_graph, tmp_path, 5)
    transport = RosTransport("test_scale")
    try:
        transport.wait_ready(list(defs), 60, defs)
        assert transport.topics_of("scale03") == ("/bmtree/call/scale03", "/bmtree/call/scale03")
        result = _run(round_tree(5, 3), tmp_path, transport, defs)
        assert result.succeeded, result.reason
        assert len(result.calls) == 300
        assert check_round(result.calls) == (0, 0)
        assert len({c.call_id for c in result.calls}) == 300
    finally:
        transport.close()


def test_a_cancel_sent_right_behind_its_call_stops_it(ros_graph, slow_world):
    """The cancel travels on the module's call topic, so it cannot overtake its call."""
    from comm import CancelRequest
    from modules.sim import definition_path
    from tests.integration.conftest import start_sim_module

    start_sim_module(ros_graph, "navigation", slow_world)
    defs = {"navigation": load_definition(definition_path("navigation"))}
    transport = RosTransport("test_cancel")
    results = []
    done = threading.Event()

    def deliver(item):
        if isinstance(item, FunctionResult):
            results.append(item)
            done.set()

    try:
        transport.connect(deliver)
        transport.wait_ready(["navigation"], 60, defs)
        call = defs["navigation"].function("go_to").build_call({"place": "kitchen"})  # about 4 s of driving
        transport.send_call(call)
        transport.send_cancel(CancelRequest(call.call_id, "navigation", "go_to"))
        assert done.wait(30), "no answer"
        assert [(r.call_id, r.status) for r in results] == [(call.call_id, "cancelled")]
    finally:
        transport.close()
