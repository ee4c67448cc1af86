"""``python -m bench`` / ``make bench``: every measure against its baseline, in one run."""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from typing import List, Optional

from bench import measures, scale
from bench.stats import Row, table
from coordinator.graph import RosGraph


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m bench", description=__doc__)
    p.add_argument("--n", type=int, default=400, help="repetitions of each latency measure")
    p.add_argument("--seconds", type=float, default=10.0, help="Blackboard throughput window")
    p.add_argument("--scale", default="10,25,50", help="module counts of the scale section ('' skips it)")
    p.add_argument("--rounds", type=int, default=20, help="rounds of 100 parallel calls per scale size")
    p.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "results"))
    p.add_argument("--only", metavar="PART,…", help="run only these parts: %s" % ",".join(PARTS))
    return p


PARTS = ("calls", "cpp", "ticks", "record", "load", "bb-latency", "bb-throughput", "mocked", "memory", "scale")


def main(argv: Optional[List[str]] = None) -> int:
    args = make_parser().parse_args(argv)
    only = set(args.only.split(",")) if args.only else set(PARTS)
    unknown = only - set(PARTS)
    if unknown:
        print("unknown part %s (parts: %s)" % (", ".join(sorted(unknown)), ", ".join(PARTS)), file=sys.stderr)
        return 2
    started = time.time()
    tmp = tempfile.mkdtemp(prefix="bmtree-bench-")
    rows: List[Row] = []
    graph = RosGraph(os.path.join(tmp, "ros"))
    try:
        graph.start_master()
        graph.adopt(home=True)
        graph.start_node(["-m", "bench.nodes", "echo"], "/bench_echo")
        graph.start_node(["-m", "bench.nodes", "module"], "/bm_bench")
        if "calls" in only:  # the call leaf's peer baseline
            graph.start_node(["-m", "bench.nodes", "action-server"], "/bench_action_server")
        print("private rosmaster at %s; measuring..." % graph.uri, flush=True)
        if "calls" in only:
            rows += measures.call_latency(graph, tmp, args.n)
        if "cpp" in only:
            rows += measures.cpp_call_latency(graph, tmp, args.n)
        if "ticks" in only:
            rows += measures.tick_cost(tmp)
        if "record" in only:
            rows += measures.record_cost(tmp)
        if "load" in only:
            rows += measures.load_cost(tmp)
        if "bb-latency" in only:
            rows += measures.blackboard_latency(graph, tmp, args.n)
        if "bb-throughput" in only:
            rows += measures.blackboard_throughput(graph, tmp, args.seconds)
        if "mocked" in only:
            rows += measures.mocked_tree_tests()
        if "memory" in only:
            rows += measures.memory(graph, tmp)
        sizes = [int(x) for x in args.scale.split(",") if x.strip()]
        if "scale" in only and sizes:
            rows += scale.scale(graph, tmp, sizes, args.rounds)
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
