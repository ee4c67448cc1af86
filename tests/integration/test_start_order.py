"""The Blackboard, a module and ``bmtree run`` started in random orders: no first call is lost.

3 orders in `make test`, 20 in `make reliability`.
"""
from __future__ import annotations

import os
import random
import subprocess
import sys
import time

from tests.integration.faultkit import PROBE_CLASS, PROBE_JSON, scale

TREE = """format: 1
root:
  sequence:
    - call: probe.echo
      inputs: {tag: first}
      timeout: 15
    - recall: {said: tag}
    - check: 'said == "first"'
"""


def test_random_start_orders_lose_no_first_call(ros_graph, tmp_path):
    rng = random.Random(20)
    tree = tmp_path / "first.yaml"
    tree.write_text(TREE)
    orders, lost = [], []
    for i in range(scale(3, 20)):
        db = str(tmp_path / ("bb%d.sqlite" % i))
        starters = {
            "blackboard": lambda db=db: ros_graph.start_node(["-m", "blackboard.node", "--db", db,
                                                              "__name:=bb_order"], "/bb_order", wait=False),
            "module": lambda: ros_graph.start_node(["-m", "modules.node", "--definition", PROBE_JSON, "--class",
                                                    PROBE_CLASS, "__name:=bm_order"], "/bm_order", wait=False),
            "run": lambda: subprocess.Popen([sys.executable, "-m", "coordinator", "run", str(tree), "--modules",
                                             PROBE_JSON, "-q", "--wait", "60"], env=dict(os.environ),
                                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True),
        }
        order = list(starters)
        rng.shuffle(order)
        procs = {}
        for name in order:
            procs[name] = starters[name]()
            time.sleep(rng.choice([0.0, 0.05, 0.3, 1.0]))  # the gap between starts is the variable under test
        run = procs["run"]
        try:
            out, _ = run.communicate(timeout=120)
        finally:
            if run.poll() is None:
                run.kill()
                run.wait(10)
        orders.append(" -> ".join(order))
        if run.returncode != 0:
            lost.append((orders[-1], out))
        for name in ("module", "blackboard"):
            ros_graph.stop_node(procs[name])
    print("\nFIGURE start orders: %d random orders, %d lost first calls" % (len(orders), len(lost)))
    assert not lost, lost
