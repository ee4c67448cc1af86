"""``bmtree control`` when no run is on the master: refused at once, not kept for the next run.

It used to wait (``--wait``) for a run to connect and send the command then: a ``stop`` typed
when no run was going stopped the run started three seconds later, and a stray ``p`` in a watch
waiting for a run paused the next one."""
from __future__ import annotations

import subprocess
import sys

from tests.integration.conftest import bmtree_cmd


def test_a_command_with_no_run_on_the_master_is_refused_at_once(own_graph):
    out = subprocess.run(bmtree_cmd("control", "stop", "--wait", "60"), capture_output=True, text=True,
                         env=own_graph.env, timeout=50, stdin=subprocess.DEVNULL)
    assert out.returncode == 3, out.stdout + out.stderr
    assert out.stderr.strip().splitlines()[-1] == (
        "refused: no run takes commands on this master now (a command is for a run that is running, not kept for "
        "the next one)"), out.stderr


def test_two_runs_on_one_master_need_a_node(own_graph):
    """Two nodes take requests: a command without --node is refused naming both, and reaches neither."""
    taker = ("import rospy; from std_msgs.msg import String; rospy.init_node('%s'); "
             "rospy.Subscriber('/bmtree/run/control_request', String, lambda m: print('took', m.data, flush=True)); "
             "rospy.spin()")
    for name in ("run_a", "run_b"):
        own_graph.start_node([sys.executable, "-c", taker % name], "/" + name)
    out = subprocess.run(bmtree_cmd("control", "pause", "--wait", "5"), capture_output=True, text=True,
                         env=own_graph.env, timeout=50, stdin=subprocess.DEVNULL)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "refused: 2 runs take commands on this master (/run_a, /run_b): say which one with --node" in out.stderr
    for name in ("run_a", "run_b"):
        with open("%s/%s.out" % (own_graph.ros_home, name)) as fh:
            assert "took" not in fh.read()
