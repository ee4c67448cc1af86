"""Many module nodes on one master and a tree that keeps 100 calls in flight: every call is
answered and correlated to the right call (speed is ``make bench``'s, not this test's)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

from tests.integration.conftest import NODES, wait_announced

MODULES, FUNCTIONS, IN_FLIGHT, ROUNDS = 50, 20, 100, 3


def _definition(i):
    fns = [{"Name": "f%d" % k, "Exec-condition": "", "Description": "echo", "Concurrent": True,
            "Input-params": [{"Name": "tag", "Data-type": "std_msgs/String", "Description": ""}],
            "Output-params": [{"Name": "tag", "Data-type": "std_msgs/String", "Description": ""}]}
           for k in range(FUNCTIONS)]
    return {"Basic Module": "m%d" % i, "Brief Description": "load test", "Hardware Required": [], "Functions": fns}


def test_100_calls_in_flight_over_50_modules_are_all_answered_right(ros_graph, tmp_path):
    defs = tmp_path / "defs"
    defs.mkdir()
    for i in range(MODULES):
        (defs / ("many_%d.json" % i)).write_text(json.dumps(_definition(i)))
    for i in range(MODULES):
        ros_graph.start_node([sys.executable, os.path.join(NODES, "many_module.py"), str(defs / ("many_%d.json" % i))],
                             "/bm_m%d" % i, timeout=120, wait=False)
    wait_announced(*["m%d" % i for i in range(MODULES)], timeout=600)
    lines = ["format: 1", "root:", "  repeat: %d" % ROUNDS, "  child:", "    sequence:", "      - parallel:",
             "          children:"]
    for n in range(IN_FLIGHT):
        lines += ["            - call: m%d.f%d" % (n % MODULES, (n * 7) % FUNCTIONS),
                  "              inputs: {tag: c%d}" % n, "              outputs: {tag: k%d}" % n]
    lines += ["      - check: 'k%d == \"c%d\"'" % (n, n) for n in range(IN_FLIGHT)]
    tree = tmp_path / "load.yaml"
    tree.write_text("\n".join(lines) + "\n")
    started = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "coordinator", "run", str(tree), "--modules", str(defs), "-q",
                          "--wait", "120"], env=dict(os.environ), capture_output=True, text=True, timeout=600)
    took = time.monotonic() - started
    done = [line for line in out.stdout.splitlines() if line.startswith("  +")]
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert len(done) == IN_FLIGHT * ROUNDS and all(" succeeded " in line for line in done)
    print("\nFIGURE load: %d module nodes x %d functions, %d calls in flight x %d rounds: %d answered and "
          "correlated right, 0 lost (run %.1f s)" % (MODULES, FUNCTIONS, IN_FLIGHT, ROUNDS, len(done), took))
