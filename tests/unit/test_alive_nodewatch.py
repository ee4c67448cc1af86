"""``comm.liveness.NodeWatch``: one node's process watched over a kept connection (the Blackboard
node during a run, the run's node in ``bmtree watch``), against stand-in node processes."""
from __future__ import annotations

import time

from comm.liveness import NodeWatch
from tests.conftest import until
from tests.unit.xmlrpc_standin import StandIn, free_port


def _uri(n):
    return "http://127.0.0.1:%d/" % n.port


def test_a_live_node_is_not_asked_again_and_its_death_is_told_once(tmp_path):
    node = StandIn(tmp_path)
    node.start()
    gone, back = [], []
    watch = NodeWatch(lambda: "/blackboard", lambda name: _uri(node), lambda n, r: gone.append((n, r)),
                      back.append, period=0.02).start()
    try:
        until(lambda: watch.node == "/blackboard")
        time.sleep(0.5)  # 25 periods: a kept connection is waited on, not polled
        assert node.questions() == 1
        node.kill()
        until(lambda: gone, timeout=20.0)
        time.sleep(0.2)
    finally:
        watch.stop()
    assert gone == [("/blackboard", "its process ended")] and back == []


def test_a_node_back_under_its_name_is_told(tmp_path):
    (tmp_path / "a").mkdir()
    first = StandIn(tmp_path / "a")
    first.start()
    now = {"n": first}
    gone, back = [], []
    watch = NodeWatch(lambda: "/blackboard", lambda name: _uri(now["n"]), lambda n, r: gone.append(n), back.append,
                      period=0.02).start()
    try:
        until(lambda: watch.node == "/blackboard")
        first.kill()
        until(lambda: gone, timeout=20.0)
        (tmp_path / "b").mkdir()
        second = StandIn(tmp_path / "b")
        second.start()
        now["n"] = second
        until(lambda: back, timeout=20.0)
        second.kill()
        until(lambda: len(gone) == 2, timeout=20.0)
    finally:
        watch.stop()
    assert back == ["/blackboard"] and gone == ["/blackboard", "/blackboard"]


def test_a_node_registered_but_dead_at_first_sight(tmp_path):
    """Killed outright, a node stays registered: gone at once with ``dead_is_gone`` (the run a watch
    shows), waited for silently without (a Blackboard already dead when the run starts: warned then)."""
    dead = "http://127.0.0.1:%d/" % free_port()
    told = {True: [], False: []}
    watches = [NodeWatch(lambda: "/bmtree_1", lambda name: dead, lambda n, r, k=k: told[k].append(r),
                         period=0.02, dead_is_gone=k).start() for k in (True, False)]
    try:
        until(lambda: told[True], timeout=20.0)
        time.sleep(0.3)
    finally:
        for w in watches:
            w.stop()
    assert told == {True: ["its process ended"], False: []}
