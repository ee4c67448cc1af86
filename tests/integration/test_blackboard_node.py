"""The Blackboard node as a process on a real master: storage, queries, durability, robustness."""
from __future__ import annotations

import json
import random
import threading
import time

import pytest
from std_msgs.msg import Int64, String

from comm import BlackboardAnswer, BlackboardRequest, FunctionResult, commBM


@pytest.fixture
def bb_db(tmp_path):
    return str(tmp_path / "bb.sqlite")


def start_bb(ros_graph, db, *extra):
    return ros_graph.start_node(["-m", "blackboard.node", "--db", db, *extra], "/blackboard")


class Asker:
    def __init__(self, probe):
        self.probe = probe
        self.answers = probe.collect("/blackboard/output", publishers=1)
        self.pub = probe.publisher("/blackboard/input", 1)

    def ask(self, timeout=10.0, **kw):
        req = BlackboardRequest(**kw)
        self.pub.publish(String(req.encode()))
        text = self.answers.wait_for(lambda t: json.loads(t).get("request_id") == req.request_id, timeout)[0]
        return BlackboardAnswer.decode(text)


def result(seq, call_id=None, mod="counter", fn="count", **extra):
    names = ["seq"] + list(extra)
    msgs = [Int64(seq)] + [String(v) for v in extra.values()]
    return FunctionResult(names, msgs, call_id=call_id or "c%d" % seq, basic_mod=mod, function=fn).encode()


def wait_stored(acks, total, timeout=20.0):
    acks.wait_for(lambda t: json.loads(t)["total"] >= total, timeout)


def test_results_are_stored_and_answered(ros_graph, ros_probe, bb_db):
    start_bb(ros_graph, bb_db)
    acks = ros_probe.collect("/blackboard/stored", publishers=1)
    results = ros_probe.publisher("/function/output", 1)
    results.publish(String(result(1, mod="vision", fn="find_object", success="yes")))
    results.publish(String(result(2, mod="navigation", fn="go_to", success="no")))
    results.publish(String(commBM.writeMsgFromRos([String("legacy")], ["note"])))   # an original module
    wait_stored(acks, 5)
    a = Asker(ros_probe)
    ans = a.ask(var_names=["success", "vision/find_object/success", "note", "ghost", "bad//name"])
    assert [(n, m.data) for n, m in zip(ans.names, ans.msgs)] == [
        ("success", "no"), ("vision/find_object/success", "yes"), ("note", "legacy")]
    assert ans.missing == ["ghost", "bad//name"] and "invalid name 'bad//name'" in ans.error
    assert [m.data for m in a.ask(var_names=["seq"], history=5).msgs] == [2, 1]
    assert sorted(a.ask(call_id="c1").names) == ["seq", "success"]
    # the original request format gets the documented answer
    a.pub.publish(String(commBM.writeVarRequest(["note", "nope"])))
    text = a.answers.wait_for(lambda t: json.loads(t).get("request_id") is None)[0]
    raw = json.loads(text)
    assert raw["names"] == ["note"] and raw["msgs"] == ['{"data": "legacy"}'] and raw["missing"] == ["nope"]
    ros_probe.close_collector(acks)
    ros_probe.close_collector(a.answers)


def test_acknowledged_results_survive_kill_9(ros_graph, ros_probe, bb_db):
    proc = start_bb(ros_graph, bb_db)
    acks = ros_probe.collect("/blackboard/stored", publishers=1)
    pub = ros_probe.publisher("/function/output", 1)
    sent = []

    def flood():
        for i in range(1000):
            try:
                pub.publish(String(result(i)))
            except Exception:
                return
            sent.append(i)
            time.sleep(0.002)

    t = threading.Thread(target=flood)
    t.start()
    acks.wait_for(lambda x: json.loads(x)["total"] >= 300, 20)
    ros_graph.kill_node(proc)                       # SIGKILL while results are still arriving
    kill_at = len(sent)
    t.join()
    acked = {cid for a in acks.items for cid in json.loads(a)["call_ids"]}
    assert 300 <= len(acked) < 1000 and kill_at < 1000
    ros_probe.close_collector(acks)
    start_bb(ros_graph, bb_db)
    a = Asker(ros_probe)
    ans = a.ask(var_names=["seq"], history=2000)
    stored = {s["call_id"] for s in ans.sources}
    assert acked <= stored, "lost: %s" % sorted(acked - stored)[:10]
    pub2 = ros_probe.publisher("/function/output", 1)
    pub2.publish(String(result(5000, call_id="after-restart")))
    end = time.monotonic() + 10
    while not a.ask(call_id="after-restart").names:
        assert time.monotonic() < end, "new results are not stored after the restart"
        time.sleep(0.1)
    ros_probe.close_collector(a.answers)


def test_a_thousand_bad_payloads_on_both_topics(ros_graph, ros_probe, bb_db):
    proc = start_bb(ros_graph, bb_db)
    a = Asker(ros_probe)
    results = ros_probe.publisher("/function/output", 1)
    rng = random.Random(3)
    bad = ["", "{", "[]", "null", '{"names": 3}', '{"names": ["a"], "rostypes": ["no/Type"], "msgs": ["{}"]}',
           '{"var_names": [1, 2]}', '{"var_names": "x"}', '{"history": -1, "var_names": ["a"]}',
           '{"names": ["a"], "rostypes": ["std_msgs/String"], "msgs": ["{\\"data\\": 1}"]}']
    good_requests = []
    for i in range(1000):
        junk = rng.choice(bad) if i % 3 else "".join(chr(rng.randrange(1, 0x500)) for _ in range(30))
        results.publish(String(junk))
        a.pub.publish(String(junk))
        if i % 50 == 0:
            results.publish(String(result(i, call_id="good-%d" % i)))
            req = BlackboardRequest(var_names=["seq"], history=1000)
            a.pub.publish(String(req.encode()))
            good_requests.append(req.request_id)
    for rid in good_requests:
        a.answers.wait_for(lambda t, rid=rid: json.loads(t).get("request_id") == rid, 20)
    final = a.ask(var_names=["seq"], history=1000)
    assert sorted(m.data for m in final.msgs) == list(range(0, 1000, 50))
    assert proc.poll() is None
    ros_probe.close_collector(a.answers)


@pytest.mark.parametrize("name", [[], ["__name:=blackboard2"]])
def test_a_second_blackboard_on_the_master_refuses_to_start_and_the_first_goes_on(ros_graph, ros_probe, bb_db,
                                                                                   tmp_path, name):
    """Of the same name it would stop the first (the master keeps one node per name), of another
    name both would store every result and answer every request."""
    import subprocess
    import sys

    first = start_bb(ros_graph, bb_db)
    second = subprocess.run([sys.executable, "-m", "blackboard.node", "--db", str(tmp_path / "second.sqlite"), *name],
                            env=ros_graph.env, capture_output=True, text=True, timeout=60)
    assert second.returncode == 3, second.stderr
    assert "error: a Blackboard node already runs on this master (/blackboard)" in second.stderr, second.stderr
    assert "Traceback" not in second.stderr and not (tmp_path / "second.sqlite").exists()
    assert first.poll() is None
    acks = ros_probe.collect("/blackboard/stored", publishers=1)
    ros_probe.publisher("/function/output", 1).publish(String(result(7, call_id="after-refused")))
    wait_stored(acks, 1)
    a = Asker(ros_probe)
    assert a.ask(call_id="after-refused").names == ["seq"]
    ros_probe.close_collector(acks)
    ros_probe.close_collector(a.answers)
