"""The Blackboard node: ``bmtree-blackboard [--db PATH] [--keep N]``.

Subscribes to ``/function/output`` and ``/blackboard/input``, answers on
``/blackboard/output``, and after each commit publishes on ``/blackboard/stored``
(latched, std_msgs/String JSON ``{"total", "count", "call_ids"}``) which results
are now durable. Private parameters: ``~db``, ``~keep``, ``~max_bytes`` (payload limit).
"""
from __future__ import annotations

import argparse
import sys
from typing import List, Optional

from blackboard.service import BlackboardService
from blackboard.store import DEFAULT_KEEP, Store, default_db_path
from comm import TOPIC_BB_ANSWER, TOPIC_BB_REQUEST, TOPIC_RESULT, sync_publisher
from comm.messages import DEFAULT_MAX_BYTES

__all__ = ["TOPIC_STORED", "make_parser", "main"]

TOPIC_STORED = "/blackboard/stored"


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bmtree-blackboard", description="Run the Blackboard node.")
    p.add_argument("--db", help="SQLite file (default $ROS_HOME/bmtree/blackboard.sqlite; ':memory:' allowed)")
    p.add_argument("--keep", type=int, help="values kept per name (default %d)" % DEFAULT_KEEP)
    return p


def main(argv: Optional[List[str]] = None) -> int:
    import rospy
    from std_msgs.msg import String

    args = make_parser().parse_args(rospy.myargv(argv if argv is not None else sys.argv)[1:])
    rospy.init_node("blackboard")
    path = args.db or rospy.get_param("~db", "") or default_db_path()
    keep = args.keep or int(rospy.get_param("~keep", DEFAULT_KEEP))
    try:
        store = Store(path, keep=keep)
    except Exception as exc:
        sys.stderr.write("error: cannot open the store %s: %s\n" % (path, exc))
        return 3
    answer_pub = sync_publisher(TOPIC_BB_ANSWER, String)  # from the writer thread, in request order
    ack_pub = rospy.Publisher(TOPIC_STORED, String, queue_size=1000, latch=True)
    max_bytes = int(rospy.get_param("~max_bytes", DEFAULT_MAX_BYTES))
    service = BlackboardService(store, lambda t: answer_pub.publish(String(t)), lambda t: ack_pub.publish(String(t)),
                                max_bytes=max_bytes)
    rospy.Subscriber(TOPIC_RESULT, String, lambda m: service.on_result(m.data), queue_size=10000, tcp_nodelay=True)
    rospy.Subscriber(TOPIC_BB_REQUEST, String, lambda m: service.on_request(m.data), queue_size=1000,
                     tcp_nodelay=True)
    rospy.loginfo("blackboard storing in %s (%d values, keeping %d per name)", path, service.total, keep)
    rospy.spin()
    service.stop()
    store.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
