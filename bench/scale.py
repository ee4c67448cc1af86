"""``make bench``'s scale section: many module processes, a ``parallel`` of 100 calls.

For each size (10, 25, 50 modules; each a ``bmtree-module`` process with 20 functions, all
``Concurrent``, whose definitions are generated here), measured in the same run:

- a round: a ``parallel`` of 100 ``call`` leaves spread over every module, repeated; its
  median against 100 x the median of one call leaf (real concurrency: the round must take at
  most half of the calls made one after another);
- every call answered ``succeeded`` by the module and function it was sent to, with the
  output equal to the call's own unique input (0 lost, 0 mis-correlated);
- the modules' total CPU per round (it must grow with the calls, not with calls x modules:
  with 100 calls a round it stays flat from 10 to 50 modules);
- the coordinator's CPU per round and RSS;
- ``bmtree run``'s preflight (announcements, every module pinged) in a fresh process.

Also ``python -m bench.scale module DEF.json`` (one echo module) and
``python -m bench.scale preflight N`` (prints the preflight's seconds).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from typing import Any, Dict, List, Sequence, Tuple

from bench.measures import _calls_in_running_tree_records, _rss_kib, _tree_file
from bench.stats import Row, summary
from coordinator.graph import RosGraph
from modules.runtime import BasicModule

__all__ = ["FUNCTIONS", "CALLS", "definition", "echo_module", "round_tree", "check_round", "scale"]

FUNCTIONS = 20
CALLS = 100


def module_name(i: int) -> str:
    return "scale%02d" % i


def definition(i: int) -> Dict[str, Any]:
    """Module ``scale<i>``: functions f00..f19, each echoing its ``text``, all Concurrent."""
    param = [{"Name": "text", "Data-type": "std_msgs/String", "Description": "Echoed."}]
    return {"Basic Module": module_name(i), "Brief Description": "Scale benchmark echo module.",
            "Hardware Required": [],
            "Functions": [{"Name": "f%02d" % k, "Exec-condition": "", "Description": "Returns its input.",
                           "Input-params": param, "Output-params": param, "Concurrent": True}
                          for k in range(FUNCTIONS)]}


def write_definitions(where: str, n: int) -> List[str]:
    os.makedirs(where, exist_ok=True)
    paths = []
    for i in range(n):
        path = os.path.join(where, "%s.json" % module_name(i))
        with open(path, "w") as fh:
            json.dump(definition(i), fh)
        paths.append(path)
    return paths


def echo_module(functions: Sequence[str]) -> BasicModule:
    """A module object whose every function returns its input."""
    def echo(self: BasicModule, text: Any) -> Dict[str, Any]:
        return {"text": text}
    return type("ScaleEcho", (BasicModule,), {f: echo for f in functions})()


def round_tree(n_modules: int, rounds: int, calls: int = CALLS) -> str:
    """A ``repeat`` of a ``parallel`` of ``calls`` call leaves, round-robin over the modules and
    their functions; every input is unique within the round."""
    leaves = []
    for c in range(calls):
        m, f = c % n_modules, (c // n_modules) % FUNCTIONS
        leaves.append("        - call: %s.f%02d\n          inputs: {text: 'c%03d-%s-f%02d'}\n" % (
            module_name(m), f, c, module_name(m), f))
    return "root:\n  repeat: %d\n  child:\n    parallel:\n      policy: all\n      children:\n%s" % (
        rounds, "".join(leaves))


def check_round(records: Sequence[Any]) -> Tuple[int, int]:
    """(lost, mis-correlated) among call records: not succeeded; answered by another call's
    id, module, function or with another call's input."""
    lost = wrong = 0
    for rec in records:
        res = rec.result
        if rec.status != "succeeded" or res is None:
            lost += 1
            continue
        fn = rec.function
        sent = rec.messages.get("text")
        got = res.values.get("text")
        if (res.call_id != rec.call_id or res.basic_mod != fn.module or res.function != fn.name
                or sent is None or got is None or got.data != sent.data):
            wrong += 1
    return lost, wrong


def _cpu_seconds(pid: int) -> float:
    """CPU time of a process's live threads, in nanoseconds summed from ``/proc/PID/task/*/schedstat``
    (``/proc/PID/stat`` counts clock ticks: 10 ms a process, so 50 processes over a few rounds
    would be off by more than the figure; a module's threads live as long as it does)."""
    total = 0
    task_dir = "/proc/%d/task" % pid
    for tid in os.listdir(task_dir):
        try:
            with open("%s/%s/schedstat" % (task_dir, tid)) as fh:
                total += int(fh.read().split()[0])
        except (OSError, ValueError, IndexError):  # the thread ended meanwhile
            continue
    return total / 1e9


def _preflight_seconds(graph: RosGraph, n: int, repeats: int) -> List[float]:
    out = []
    for _ in range(repeats):
        p = subprocess.run([sys.executable, "-m", "bench.scale", "preflight", str(n)], env=graph.env,
                           capture_output=True, text=True, timeout=120)
        if p.returncode != 0:
            raise RuntimeError("preflight of %d modules failed: %s" % (n, p.stderr.strip()))
        out.append(float(p.stdout.split()[-1]))
    return out


def _measure(graph: RosGraph, tmp: str, n: int, pids: List[int], defs: Dict[str, Any], rounds: int,
             blocks: int) -> Dict[str, Any]:
    from coordinator.language import load_tree
    from coordinator.ros_transport import RosTransport

    transport = RosTransport("bench_scale_%d" % n)
    transport.wait_ready([module_name(i) for i in range(n)], 60, defs)
    per_block = max(1, rounds // blocks)
    many = load_tree(_tree_file(tmp, "scale%d.yaml" % n, round_tree(n, per_block)), defs)
    one = load_tree(_tree_file(tmp, "scale%d_one.yaml" % n, "root:\n  repeat: %d\n  child:\n"
                               "    call: %s.f00\n    inputs: {text: one}\n" % (CALLS, module_name(0))), defs)
    _calls_in_running_tree_records(many, transport, defs)  # warm-up: connections, caches
    _calls_in_running_tree_records(one, transport, defs)
    spans: List[float] = []
    singles: List[float] = []
    lost = wrong = total = 0
    modules_cpu = coordinator_cpu = 0.0
    for _ in range(blocks):  # interleaved, so that machine noise hits both alike
        singles += [r.ended - r.started for r in _calls_in_running_tree_records(one, transport, defs)]
        cpu0 = sum(_cpu_seconds(p) for p in pids)
        own0 = time.process_time()
        records = _calls_in_running_tree_records(many, transport, defs)
        coordinator_cpu += time.process_time() - own0
        modules_cpu += sum(_cpu_seconds(p) for p in pids) - cpu0
        for r in range(per_block):
            chunk = records[r * CALLS:(r + 1) * CALLS]
            spans.append(max(c.ended for c in chunk) - min(c.started for c in chunk))
            lo, wr = check_round(chunk)
            lost, wrong, total = lost + lo, wrong + wr, total + len(chunk)
    transport.close()
    done = blocks * per_block
    return {"round": summary(spans), "single": summary(singles), "lost": lost, "wrong": wrong, "calls": total,
            "modules_cpu_ms": modules_cpu / done * 1000, "coordinator_cpu_ms": coordinator_cpu / done * 1000,
            "coordinator_rss_mib": _rss_kib() / 1024.0}


def scale(graph: RosGraph, tmp: str, sizes: Sequence[int] = (10, 25, 50), rounds: int = 20,
          preflights: int = 5) -> List[Row]:
    """The rows of the scale section (modules are added to the graph size by size)."""
    from modules.definition import load_definition

    paths = write_definitions(os.path.join(tmp, "scale_defs"), max(sizes))
    pids: List[int] = []
    defs: Dict[str, Any] = {}
    rows: List[Row] = []
    cpu_at: Dict[int, float] = {}
    ms = 1000.0
    for n in sorted(sizes):
        for i in range(len(pids), n):
            proc = graph.start_node(["-m", "bench.scale", "module", paths[i]], "/bm_%s" % module_name(i),
                                    wait=False)
            pids.append(proc.pid)
            defs[module_name(i)] = load_definition(paths[i])
        for i in range(n):
            graph.wait_node("/bm_%s" % module_name(i), 120)
        print("scale: %d module processes up; measuring..." % n, flush=True)
        m = _measure(graph, tmp, n, pids, defs, rounds, blocks=4)
        pre = summary(_preflight_seconds(graph, n, preflights))
        cpu_at[n] = m["modules_cpu_ms"]
        r, s = m["round"]["median"], m["single"]["median"]
        rows += [
            Row("scale %d modules: round of %d parallel calls, median" % (n, CALLS), r * ms, "ms", CALLS * s * ms,
                "<= 0.5x", r <= 0.5 * CALLS * s, {"round": m["round"], "single": m["single"]}),
            Row("scale %d modules: calls lost / mis-correlated of %d" % (n, m["calls"]), m["lost"] + m["wrong"],
                "calls", None, "0", m["lost"] == 0 and m["wrong"] == 0, {"lost": m["lost"], "wrong": m["wrong"]}),
            Row("scale %d modules: modules' total CPU per round" % n, m["modules_cpu_ms"], "ms",
                cpu_at[min(cpu_at)], "flat in modules (<= 2x the smallest size)",
                m["modules_cpu_ms"] <= 2 * cpu_at[min(cpu_at)]),
            Row("scale %d modules: coordinator CPU per round" % n, m["coordinator_cpu_ms"], "ms", None, "report",
                None),
            Row("scale %d modules: coordinator RSS" % n, m["coordinator_rss_mib"], "MiB", None, "report", None),
            Row("scale %d modules: bmtree run preflight, median" % n, pre["median"] * ms, "ms", None,
                "< 500 ms at 50", pre["median"] < 0.5 if n >= 50 else None, {"preflight": pre}),
        ]
    return rows


def _preflight_main(n: int) -> int:
    """What ``bmtree run`` does before its first tick, timed in a fresh process."""
    from coordinator.ros_transport import RosTransport
    from modules.discovery import announced_modules

    t0 = time.perf_counter()
    live = announced_modules()
    defs = {name: m.definition for name, m in live.items()}
    transport = RosTransport()
    transport.wait_ready([module_name(i) for i in range(n)], 60, defs)
    elapsed = time.perf_counter() - t0
    transport.close()
    print("%.4f" % elapsed, flush=True)
    return 0


def _module_main(path: str) -> int:
    from modules.definition import load_definition
    from modules.node import run_module

    d = load_definition(path)
    return run_module(d, echo_module(list(d.functions)), "bm_%s" % d.name)


if __name__ == "__main__":
    if sys.argv[1:2] == ["module"]:
        sys.exit(_module_main(sys.argv[2]))
    if sys.argv[1:2] == ["preflight"]:
        sys.exit(_preflight_main(int(sys.argv[2])))
    sys.exit("usage: python -m bench.scale module DEF.json | preflight N")
