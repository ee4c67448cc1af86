"""Fuzzed messages on every input topic of every node, a good one after every few:
no node dies, no good message is lost, no traceback is logged."""
from __future__ import annotations

import glob
import json
import os
import random
import subprocess
import sys

from std_msgs.msg import String

from comm import BlackboardRequest, Event, FunctionResult
from tests.integration.faultkit import PROBE_CLASS, PROBE_JSON, Publishers, log_problems, probe_def, scale
from tests.integration.fuzzing import deep_call, hostile, interleave

EVERY = 4


def _payload_has(text, key, value):
    try:
        return json.loads(text).get(key) == value
    except ValueError:
        return False


def _acked(text, call_id):
    try:
        return call_id in json.loads(text).get("call_ids", [])
    except ValueError:
        return False


def _no_tracebacks(ros_graph, names):
    """Tracebacks in the nodes' output and rospy log files (and proof that the logs were there)."""
    found, scanned = [], 0
    for name in names:
        paths = [os.path.join(ros_graph.ros_home, "%s.out" % name)]
        paths += glob.glob(os.path.join(ros_graph.ros_home, "log", "**", "%s*.log" % name), recursive=True)
        for path in paths:
            scanned += os.path.exists(path)
            found += log_problems(path)
    assert scanned >= len(names), "no logs found"
    with open(os.path.join(ros_graph.ros_home, "bm_fuzz.out"), errors="replace") as fh:
        assert "Beautiful is better than ugly" not in fh.read(), "a type name made the module import 'this'"
    return found


def test_fuzzed_topics_stop_no_node_and_lose_no_good_message(ros_graph, ros_probe, tmp_path):
    count = scale(60, 250)
    rng = random.Random(16)
    defs = probe_def()
    echo, work = defs.function("echo"), defs.function("work")
    bb = ros_graph.start_node(["-m", "blackboard.node", "--db", str(tmp_path / "bb.sqlite"), "__name:=bb_fuzz"],
                              "/bb_fuzz")
    mod = ros_graph.start_node(["-m", "modules.node", "--definition", PROBE_JSON, "--class", PROBE_CLASS,
                                "__name:=bm_fuzz"], "/bm_fuzz")
    results = ros_probe.collect("/function/output", publishers=1, nodes=["/bm_fuzz"])
    acks = ros_probe.collect("/blackboard/stored", publishers=1, nodes=["/bb_fuzz"])
    answers = ros_probe.collect("/blackboard/output", publishers=1, nodes=["/bb_fuzz"])
    sent = {}
    pubs = Publishers()
    try:
        # module: /master/output and its own addressed topics ---------------------------------
        for call_topic, cancel_topic, tag in (("/master/output", "/master/cancel", ""),
                                              ("/bmtree/call/probe", "/bmtree/cancel/probe", "addr")):
            calls = pubs.get(call_topic, 1, nodes=["/bm_fuzz"])
            shape = json.loads(echo.build_call({"tag": "x"}, "shape").encode())
            good = 0
            for ok, text in interleave(rng, count, EVERY, lambda shape=shape: hostile(rng, shape),
                                       lambda n, tag=tag: echo.build_call({"tag": "g%d" % n},
                                                                          "gA%s%d" % (tag, n)).encode()):
                calls.publish(String(text))
                if ok:
                    cid = json.loads(text)["call_id"]
                    got = FunctionResult.decode(results.wait_for(lambda t, c=cid: _payload_has(t, "call_id", c),
                                                                 20)[0])
                    assert got.status == "succeeded" and got.values["tag"].data == "g%d" % good, got
                    good += 1
            for n, inner in enumerate((True, False)):  # deep values get an answer, not silence
                cid = "deep%s%d" % (tag, n)
                calls.publish(String(deep_call("probe", "echo", cid, inner)))
                got = FunctionResult.decode(results.wait_for(lambda t, c=cid: _payload_has(t, "call_id", c), 20)[0])
                assert got.status == "rejected" and "nested deeper" in got.error, got
            sent[call_topic] = (count, good)

            cancels = pubs.get(cancel_topic, 1, nodes=["/bm_fuzz"])
            shape = {"call_id": "c", "basic_mod": "probe", "function": "work"}
            good = 0
            for ok, text in interleave(rng, count, EVERY, lambda shape=shape: hostile(rng, shape),
                                       lambda n: "good"):
                if not ok:
                    cancels.publish(String(text))
                    continue
                call = work.build_call({"seconds": 600.0, "tag": "w"}, "gB%s%d" % (tag, good))
                calls.publish(String(call.encode()))
                ping = echo.build_call({"tag": "p"}, "pB%s%d" % (tag, good))  # proves the module took the call
                calls.publish(String(ping.encode()))
                results.wait_for(lambda t, c=ping.call_id: _payload_has(t, "call_id", c), 20)
                cancels.publish(String(json.dumps({"call_id": call.call_id, "basic_mod": "probe",
                                                   "function": "work"})))
                got = FunctionResult.decode(results.wait_for(lambda t, c=call.call_id: _payload_has(t, "call_id", c),
                                                             20)[0])
                assert got.status == "cancelled", got
                good += 1
            sent[cancel_topic] = (count, good)

        # Blackboard: /function/output -------------------------------------------------------
        res_pub = pubs.get("/function/output", 1, nodes=["/bb_fuzz"])
        shape = json.loads(echo.build_result({"tag": "x"}, "shape").encode())
        good = 0
        for ok, text in interleave(rng, count, EVERY, lambda: hostile(rng, shape),
                                   lambda n: echo.build_result({"tag": "v%d" % n}, "gC%d" % n).encode()):
            res_pub.publish(String(text))
            if ok:
                acks.wait_for(lambda t, c="gC%d" % good: _acked(t, c), 20)
                good += 1
        sent["/function/output (Blackboard)"] = (count, good)

        # Blackboard: /blackboard/input ------------------------------------------------------
        req_pub = pubs.get("/blackboard/input", 1, nodes=["/bb_fuzz"])
        shape = json.loads(BlackboardRequest(var_names=["tag"], request_id="r", history=2).encode())
        good = 0
        for ok, text in interleave(rng, count, EVERY, lambda: hostile(rng, shape),
                                   lambda n: BlackboardRequest(var_names=["tag"], request_id="gD%d" % n).encode()):
            req_pub.publish(String(text))
            if ok:
                ans = answers.wait_for(lambda t, c="gD%d" % good: _payload_has(t, "request_id", c), 20)[0]
                assert json.loads(ans)["missing"] == [], ans
                good += 1
        sent["/blackboard/input"] = (count, good)

        # coordinator: /function/output, /event/output, /blackboard/output during a run ------
        good = _fuzz_coordinator(pubs, tmp_path, rng, count, res_pub)
        sent.update(good)
        assert bb.poll() is None and mod.poll() is None, "a node died"
    finally:
        for c in (results, acks, answers):
            ros_probe.close_collector(c)
        pubs.close()
    problems = _no_tracebacks(ros_graph, ["bb_fuzz", "bm_fuzz"])
    for topic, (bad, good) in sent.items():
        print("\nFIGURE fuzz %s: %d malformed, %d good interleaved, %s" % (
            topic, bad, good, "ignored as they must be, the run succeeded" if "coordinator" in topic
            else "all answered"))
    print("FIGURE fuzz: node deaths 0, good lost 0, tracebacks %d" % len(problems))
    assert problems == []


def _fuzz_coordinator(pubs, tmp_path, rng, count, res_pub):
    tree = tmp_path / "wait.yaml"
    tree.write_text("""format: 1
root:
  sequence:
    - call: probe.echo
      inputs: {tag: before}
      outputs: {tag: t1}
    - wait_event: probe.done
      outputs: {tag: got}
      timeout: 600
    - call: probe.echo
      inputs: {tag: after}
    - recall: {t2: tag}
    - check: 'got == "go" and t2 == "after"'
""")
    run = subprocess.Popen([sys.executable, "-m", "coordinator", "run", str(tree), "--modules", PROBE_JSON],
                           env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seen = []
    try:
        for line in run.stdout:
            seen.append(line)
            if "RUNNING" in line and "done" in line:
                break
        defs = probe_def()
        topics = {
            "/function/output": (res_pub, json.loads(defs.function("echo").build_result({"tag": "x"}, "s").encode()),
                                 lambda n: defs.function("echo").build_result({"tag": "z"}, "nobody%d" % n).encode()),
            "/event/output": (pubs.get("/event/output", 1),
                              json.loads(Event("probe", "done", ["tag"], [String("x")]).encode()),
                              lambda n: Event("other", "thing", [], []).encode()),
            "/blackboard/output": (pubs.get("/blackboard/output", 1),
                                   {"names": ["tag"], "rostypes": ["std_msgs/String"], "msgs": ['{"data": "x"}'],
                                    "request_id": "q", "missing": [], "error": "", "sources": []},
                                   lambda n: json.dumps({"names": [], "rostypes": [], "msgs": [], "request_id": "n%d" % n,
                                                         "missing": [], "error": "", "sources": []})),
        }
        for _topic, (pub, shape, make_good) in topics.items():
            for _ok, text in interleave(rng, count, EVERY, lambda s=shape: hostile(rng, s), make_good):
                pub.publish(String(text))
        topics["/event/output"][0].publish(String(Event("probe", "done", ["tag"], [String("go")]).encode()))
        out, _ = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(10)
    out = "".join(seen) + out
    assert run.returncode == 0, out
    assert "Traceback" not in out, out
    # good messages here are ones no call waits for (ignored by design); the run's own messages must all arrive
    return {"%s (coordinator)" % t: (count, count // EVERY) for t in topics}
