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


CALL_ONLY = "format: 1\nroot:\n  call: probe.echo\n  inputs: {tag: first}\n"


def _run_first(tree, *args):
    """``bmtree run`` started before its module: (process, path of its stderr)."""
    err = str(tree) + ".err"
    with open(err, "w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "coordinator", "run", str(tree), "-q", *args],
                                env=dict(os.environ), stdout=subprocess.PIPE, stderr=fh, text=True)
    return proc, err


def _text(path):
    with open(path) as fh:
        return fh.read()


def test_a_run_started_before_its_modules_says_what_it_waits_for_and_runs(ros_graph, tmp_path):
    """A launch file starts the modules and the run together: the run waits (bounded by --wait) for
    a module it only knows from its announcement, and for one whose definition it was given, and
    says once what it waits for instead of waiting silently."""
    from tests.conftest import until

    tree = tmp_path / "first.yaml"
    tree.write_text(CALL_ONLY)
    for given in ([], ["--modules", PROBE_JSON]):
        run, err = _run_first(tree, "--wait", "60", *given)
        try:
            notice = ("module 'probe' not announced on %s yet, and no definition given with --modules; waiting up to"
                      % os.environ["ROS_MASTER_URI"]) if not given else "(--wait): module 'probe' is not running ("
            until(lambda n=notice, e=err, r=run: n in _text(e) or r.poll() is not None, 60)
            assert run.poll() is None, _text(err)
            module = ros_graph.start_node(["-m", "modules.node", "--definition", PROBE_JSON, "--class", PROBE_CLASS,
                                           "__name:=bm_late"], "/bm_late", wait=False)
            out, _ = run.communicate(timeout=120)
        finally:
            if run.poll() is None:
                run.kill()
                run.wait(10)
        assert run.returncode == 0, out + _text(err)
        assert _text(err).count(notice) == 1 and "probe.echo" in out and "succeeded" in out
        ros_graph.stop_node(module)


def test_a_module_that_never_comes_is_the_environment_and_a_close_name_is_a_typo(ros_graph, tmp_path):
    tree = tmp_path / "never.yaml"
    tree.write_text(CALL_ONLY)
    run, err = _run_first(tree, "--wait", "1")
    out, _ = run.communicate(timeout=60)
    assert run.returncode == 3, out + _text(err)
    assert "never.yaml:3:9: module 'probe' is not running: no bmtree module of that name announced itself on" \
        in _text(err) and "Traceback" not in _text(err)
    # a name close to one the run knows (given, or announced) is refused at once, as a typo
    typo = tmp_path / "typo.yaml"
    typo.write_text(CALL_ONLY.replace("probe.echo", "prob.echo"))
    run, err = _run_first(typo, "--wait", "60", "--modules", PROBE_JSON)
    out, _ = run.communicate(timeout=30)
    assert run.returncode == 2 and "typo.yaml:3:9: unknown module 'prob' (did you mean 'probe'?)" in _text(err), \
        out + _text(err)


def _registrations_of(pid):
    """Topics the master still lists for the node of process ``pid`` (rospy's anonymous names hold it)."""
    import rosgraph

    pubs, subs, _ = rosgraph.Master("/t").getSystemState()
    mark = "_%d_" % pid
    return sorted("%s %s" % (kind, topic) for kind, table in (("publishes", pubs), ("subscribes", subs))
                  for topic, nodes in table for n in nodes if mark in n)


def test_a_run_stopped_at_any_moment_of_its_start_up_leaves_nothing_on_the_master(ros_graph, tmp_path):
    """SIGTERM or SIGINT while ``bmtree run`` registers with the master (its module never comes, so
    it stays in its start-up): it ends with exit 3 and unregisters everything it had registered,
    whichever moment the signal hit."""
    import signal

    tree = tmp_path / "first.yaml"
    tree.write_text(TREE)
    leaks = []
    for i, delay in enumerate([0.0, 0.01, 0.02, 0.04, 0.08, 0.15, 0.3, 0.6] * scale(1, 5)):
        proc = subprocess.Popen([sys.executable, "-m", "coordinator", "run", str(tree), "--modules", PROBE_JSON, "-q",
                                 "--wait", "30"], env=dict(os.environ), stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
        try:
            end = time.monotonic() + 60
            while not _registrations_of(proc.pid):  # its node has registered something: start-up is under way
                assert proc.poll() is None and time.monotonic() < end, proc.communicate()[0]
                time.sleep(0.005)
            time.sleep(delay)
            proc.send_signal(signal.SIGTERM if i % 2 else signal.SIGINT)
            out, _ = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
        assert proc.returncode == 3, out
        assert "Traceback" not in out, out
        left = _registrations_of(proc.pid)
        if left:
            leaks.append((delay, left))
    assert leaks == [], leaks
