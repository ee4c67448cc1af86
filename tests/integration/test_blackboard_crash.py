"""kill -9 of the Blackboard during a stream of results: nothing acknowledged is lost, and a
restarted Blackboard answers at once."""
from __future__ import annotations

import json
import sqlite3
import time

from std_msgs.msg import String

from comm import BlackboardRequest
from tests.integration.faultkit import Publishers, figure, probe_def, scale


def _stored_ids(db):
    con = sqlite3.connect("file:%s?mode=ro" % db, uri=True)
    try:
        return {row[0] for row in con.execute("SELECT DISTINCT call_id FROM value")}
    finally:
        con.close()


def test_acknowledged_results_survive_a_killed_blackboard(ros_graph, ros_probe, tmp_path):
    db = str(tmp_path / "bb.sqlite")
    echo = probe_def().function("echo")
    args = ["-m", "blackboard.node", "--db", db, "__name:=bb_crash"]
    bb = ros_graph.start_node(args, "/bb_crash")
    acks = ros_probe.collect("/blackboard/stored", publishers=1)
    answers = ros_probe.collect("/blackboard/output", publishers=1)
    acked_total, lost_total, answered_after = 0, 0, []
    pubs = Publishers()
    try:
        for round_ in range(scale(2, 10)):
            pub = pubs.get("/function/output", 1)
            texts = [echo.build_result({"tag": "r%d-%d" % (round_, i)}, "s%d-%d" % (round_, i)).encode()
                     for i in range(1000)]
            acks.clear()
            for i, text in enumerate(texts):
                pub.publish(String(text))
                if i == 500:  # kill while results are still streaming in
                    acks.wait_for(lambda t: True, 20)
                    ros_graph.kill_node(bb)
            acked = set()
            for text in acks.items:
                acked.update(json.loads(text).get("call_ids", []))
            assert acked, "nothing was acknowledged before the kill"
            lost = acked - _stored_ids(db)
            acked_total += len(acked)
            lost_total += len(lost)
            assert not lost, "acknowledged but not stored: %s" % sorted(lost)[:5]
            # restarted: a request sent right away is answered (sent again each second while this
            # process's publisher may still count its connection to the dead node)
            bb = ros_graph.start_node(args, "/bb_crash")
            started = time.monotonic()
            req = BlackboardRequest(var_names=["tag"], request_id="after-%d" % round_)
            for _ in range(20):
                pubs.get("/blackboard/input", 1).publish(String(req.encode()))
                try:
                    ans = answers.wait_for(lambda t, r=req.request_id: json.loads(t).get("request_id") == r, 1)[0]
                    break
                except AssertionError:
                    continue
            else:
                raise AssertionError("the restarted Blackboard did not answer")
            assert json.loads(ans)["missing"] == []
            answered_after.append(time.monotonic() - started)
    finally:
        ros_probe.close_collector(acks)
        ros_probe.close_collector(answers)
        pubs.close()
    print("\nFIGURE blackboard kill -9 during 1000-result streams x%d: %d acknowledged, %d of them lost, "
          "%d/%d requests after restart answered" % (len(answered_after), acked_total, lost_total,
                                                     len(answered_after), len(answered_after)))
    figure("first answer after the Blackboard restart", answered_after)
