"""The Blackboard node: ``bmtree-blackboard [--db PATH] [--keep N] [--max-bytes N]``.

Subscribes to ``/function/output`` and ``/blackboard/input``, answers on
``/blackboard/output``, and after each commit publishes on ``/blackboard/stored``
(latched, std_msgs/String JSON ``{"total", "count", "call_ids"}``) which results
are now durable. It also listens to ``/master/output`` and ``/master/cancel`` and reads
the module announcements, to store an original module's result (no call id) under its
module, function and call (:mod:`blackboard.attribution`). Private parameters: ``~db``, ``~keep``, ``~max_bytes`` (payload limit).
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import Any, List, Optional

from blackboard.attribution import Attribution
from blackboard.service import BlackboardService
from blackboard.store import DEFAULT_KEEP, Store, default_db_path
from comm import TOPIC_BB_ANSWER, TOPIC_BB_REQUEST, TOPIC_CALL, TOPIC_CANCEL, TOPIC_RESULT, sync_publisher
from comm.masterwatch import watch_master
from comm.messages import DEFAULT_MAX_BYTES, MIN_MAX_BYTES
from comm.nodelife import StopSignals
from comm.nodeopts import parse_node_args
from comm.replies import ReplyPublisher, caller_of
from comm.roslog import log_to_rosout
from comm.rpc import MASTER_TIMEOUT, master_answers, master_api
from comm.startup import patiently

__all__ = ["TOPIC_STORED", "make_parser", "main"]

TOPIC_STORED = "/blackboard/stored"
ANNOUNCEMENTS = "/bmtree/modules"  # modules.discovery.PARAM_ROOT (the Blackboard does not import modules)


def _announcements() -> Any:
    """The module announcements (``/bmtree/modules``), for attributing original modules' results.
    Asked from the writer thread, so bounded: a master that does not answer raises OSError (the
    result is stored without its module) and never holds the results behind it, nor the answers."""
    import rosgraph

    try:
        return master_api("/blackboard", MASTER_TIMEOUT).getParam(ANNOUNCEMENTS)
    except rosgraph.masterapi.Error:
        return {}


def _running_blackboard() -> str:
    """The Blackboard node already running on the master, if any (asked before this node registers:
    a node of the same name would stop it, one of another name would store everything twice)."""
    import rosgraph

    from blackboard.client import blackboard_listeners

    try:
        if not master_answers(1.0):  # bounded: rosgraph.is_master_online() waits for a stopped master for ever
            return ""  # init_node waits for it (and says so); nothing can be registered there yet
        found = blackboard_listeners("/blackboard_start")
    except (OSError, rosgraph.masterapi.Error):
        return ""
    return ", ".join(found)


def _kicked_out(reason: str) -> None:
    import rospy

    if "new node registered with same name" in reason:
        sys.stderr.write("error: another node registered with this node's name %s, so the master stopped this "
                         "Blackboard node (give each node its own name: __name:=)\n" % rospy.get_name())


def make_parser() -> argparse.ArgumentParser:
    from coordinator.cliutil import count  # the type= of every command's options

    p = argparse.ArgumentParser(prog="bmtree-blackboard", description="Run the Blackboard node.")
    p.add_argument("--db", help="SQLite file (default $ROS_HOME/bmtree/blackboard.sqlite; ':memory:' allowed)")
    p.add_argument("--keep", type=count(), help="values kept per name (default %d)" % DEFAULT_KEEP)
    p.add_argument("--max-bytes", type=count(MIN_MAX_BYTES, what="an answer must fit"),
                   help="largest payload accepted (bytes; default %d)" % DEFAULT_MAX_BYTES)
    return p


def main(argv: Optional[List[str]] = None) -> int:
    import rospy
    from std_msgs.msg import String

    parser = make_parser()
    args = parse_node_args(parser, (argv if argv is not None else sys.argv)[1:], "blackboard")
    if args.db is not None:  # given (or ~db): no empty name, no NUL (checked here: a ~db list says "expected a text")
        from coordinator.cliutil import path_arg

        try:
            path_arg("an SQLite file")(args.db)
        except argparse.ArgumentTypeError as exc:
            parser.error("argument --db: %s" % exc)
    stop = StopSignals()  # a stop during start-up ends it cleanly too
    other = _running_blackboard()
    if other:
        sys.stderr.write("error: a Blackboard node already runs on this master (%s): two would each store every "
                         "result and both answer every request; stop it first, or start this one with another "
                         "master\n" % other)
        return 3
    if not stop.init_node("blackboard"):
        stop.leave()
        return 0
    rospy.core.add_preshutdown_hook(_kicked_out)
    log_to_rosout()
    db = args.db or patiently(lambda: rospy.get_param("~db", ""))
    if not isinstance(db, str):  # set on the master after this node read its parameters
        db = ""
    path = os.path.expanduser(db or default_db_path())  # ~/ from a launch file
    keep = args.keep if args.keep is not None else DEFAULT_KEEP
    max_bytes = args.max_bytes if args.max_bytes is not None else DEFAULT_MAX_BYTES
    try:
        store = Store(path, keep=keep)
    except Exception as exc:
        sys.stderr.write("error: cannot open the store %s: %s\n" % (path, exc))
        stop.leave()
        return 3
    # from the writer thread, in request order; an answer waits for its asker's connection (a Blackboard
    # restarted mid-run gets requests before the coordinator has connected to its answers)
    answer_pub = ReplyPublisher(sync_publisher(TOPIC_BB_ANSWER, String))
    ack_pub = rospy.Publisher(TOPIC_STORED, String, queue_size=1000, latch=True)
    service = BlackboardService(store, lambda t: answer_pub.publish(String(t)), lambda t: ack_pub.publish(String(t)),
                                max_bytes=max_bytes, attribution=Attribution(_announcements))
    rospy.Subscriber(TOPIC_RESULT, String, lambda m: service.on_result(m.data, None, caller_of(m)), queue_size=10000,
                     tcp_nodelay=True)
    rospy.Subscriber(TOPIC_CALL, String, lambda m: service.on_call(m.data), queue_size=1000, tcp_nodelay=True)
    rospy.Subscriber(TOPIC_CANCEL, String, lambda m: service.on_cancel(m.data), queue_size=1000, tcp_nodelay=True)
    def on_request(msg: Any) -> None:
        answer_pub.heard(caller_of(msg))
        service.on_request(msg.data)

    rospy.Subscriber(TOPIC_BB_REQUEST, String, on_request, queue_size=1000, tcp_nodelay=True)
    watch_master()
    rospy.loginfo("blackboard storing in %s (%d values, keeping %d per name)", path, service.total, keep)
    stop.spin()  # then leaves the graph, bounded: a master that does not answer is left as it is
    service.stop()
    store.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
