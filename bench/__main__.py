"""``python -m bench`` / ``make bench``: every measure against its baseline, in one run."""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from typing import List, Optional

from bench import measures
from bench.stats import Row, table
from coordinator.graph import RosGraph


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m bench", description=__doc__)
    p.add_argument("--n", type=int, default=400, help="repetitions of each latency measure")
    p.add_argument("--seconds", type=float, default=10.0, help="Blackboard throughput window")
    p.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "results"))
    return p


def main(argv: Optional[List[str]] = None) -> int:
    args = make_parser().parse_args(argv)
    started = time.time()
    tmp = tempfile.mkdtemp(prefix="bmtree-bench-")
    rows: List[Row] = []
    graph = RosGraph(os.path.join(tmp, "ros"))
    try:
        os.environ["ROS_MASTER_URI"] = graph.start_master()
        os.environ["ROS_HOME"] = graph.ros_home
        graph.start_node(["-m", "bench.nodes", "echo"], "/bench_echo")
        graph.start_node(["-m", "bench.nodes", "module"], "/bm_bench")
        print("private rosmaster at %s; measuring..." % graph.uri, flush=True)
        rows += measures.call_latency(graph, tmp, args.n)
        rows += measures.tick_cost(tmp)
        rows += measures.load_cost(tmp)
        rows += measures.blackboard_latency(graph, tmp, args.n)
        rows += measures.blackboard_throughput(graph, tmp, args.seconds)
        rows += measures.mocked_tree_tests()
        rows += measures.memory(graph, tmp)
    finally:
        graph.close()
    meta = dict(measures.versions(), started=started, seconds=round(time.time() - started, 1))
    print()
    print("bmtree benchmarks  (Python %(python)s, py_trees %(py_trees)s, rospy %(rospy)s; %(seconds)ss)" % meta)
    print(table(rows))
    path = os.path.join(args.out, time.strftime("bench-%Y%m%d-%H%M%S.json"))
    measures.dump(rows, meta, path)
    print("\nwritten to %s" % os.path.relpath(path))
    return 0


if __name__ == "__main__":
    sys.exit(main())
