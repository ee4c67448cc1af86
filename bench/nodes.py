"""Processes the benchmarks start: a raw rospy echo, a bmtree echo module, a result publisher.

    python -m bench.nodes echo                 # raw std_msgs/String ping-pong partner
    python -m bench.nodes action-server        # actionlib SimpleActionServer that succeeds at once
    python -m bench.nodes module               # the 'bench' basic module (runtime, answers at once)
    python -m bench.nodes publish ID RATE SECONDS [COUNT]   # results on /function/output at RATE/s
    python -m bench.nodes rss-tree TREE        # RSS after imports, then with TREE loaded and ticked
"""
from __future__ import annotations

import os
import sys
import time
from typing import Any

from modules.runtime import BasicModule

DEFINITION = os.path.join(os.path.dirname(os.path.abspath(__file__)), "bench_module.json")


class Bench(BasicModule):
    def ping(self, text):
        return {"text": text}


def echo() -> int:
    import rospy
    from std_msgs.msg import String

    rospy.init_node("bench_echo")
    pub = rospy.Publisher("/bench/pong", String, queue_size=100, tcp_nodelay=True)
    rospy.Subscriber("/bench/ping", String, pub.publish, queue_size=100, tcp_nodelay=True)
    rospy.spin()
    return 0


ACTION = "/bench/action"


def action_server() -> int:
    """The peer of a call leaf in py_trees_ros and SMACH: a skill as an actionlib goal
    (move_base_msgs/MoveBase, the navigation goal) on a SimpleActionServer that succeeds at once."""
    import actionlib
    import rospy
    from move_base_msgs.msg import MoveBaseAction, MoveBaseResult

    rospy.init_node("bench_action_server")
    server: Any = None

    def execute(goal: Any) -> None:
        server.set_succeeded(MoveBaseResult())

    server = actionlib.SimpleActionServer(ACTION, MoveBaseAction, execute_cb=execute, auto_start=False)
    server.start()
    rospy.spin()
    return 0


def module() -> int:
    from modules.definition import load_definition
    from modules.node import run_module

    return run_module(load_definition(DEFINITION), Bench(), "bm_bench")


def publish(ident: str, rate: float, seconds: float, count: int = 0) -> int:
    """Publish results at ``rate`` per second for ``seconds`` (or until ``count`` were sent);
    print how many were sent."""
    import rospy
    from std_msgs.msg import Float64, String

    from comm import FunctionResult

    rospy.init_node("bench_pub_%s" % ident)
    pub = rospy.Publisher("/function/output", String, queue_size=100000, tcp_nodelay=True)
    while pub.get_num_connections() < 1:
        time.sleep(0.01)
    time.sleep(0.2)
    sent = 0
    start = time.monotonic()
    names = ["value_%s_%d" % (ident, i) for i in range(10)]
    while True:
        now = time.monotonic() - start
        if now >= seconds or (count and sent >= count):
            break
        due = int(now * rate) + 1
        if count:
            due = min(due, count)
        while sent < due:
            res = FunctionResult([names[sent % 10]], [Float64(sent)], call_id="%s-%d" % (ident, sent),
                                 basic_mod="bench", function="measure")
            pub.publish(String(res.encode()))
            sent += 1
        time.sleep(0.0005)
    time.sleep(0.5)  # let rospy's queue drain before exiting
    print(sent, flush=True)
    return 0


def rss_tree(path: str) -> int:
    """Print this process's RSS (KiB) after the imports, then after loading and ticking ``path``."""
    from bench.measures import _offline, _rss_kib

    before = _rss_kib()
    root = _offline(path)
    for _ in range(50):
        root.tick_once()
    print(before, _rss_kib(), flush=True)
    return 0


if __name__ == "__main__":
    verb = sys.argv[1]
    if verb == "echo":
        sys.exit(echo())
    if verb == "module":
        sys.exit(module())
    if verb == "action-server":
        sys.exit(action_server())
    if verb == "rss-tree":
        sys.exit(rss_tree(sys.argv[2]))
    if verb == "publish":
        sys.exit(publish(sys.argv[2], float(sys.argv[3]), float(sys.argv[4]),
                         int(sys.argv[5]) if len(sys.argv) > 5 else 0))
    sys.exit("unknown verb %r" % verb)
