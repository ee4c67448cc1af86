"""Helpers of the fault tests: the probe module, scale (``BMTREE_RELIABILITY=1`` for the full
counts of ``make reliability``), and the figures each test prints."""
from __future__ import annotations

import os
import queue
import signal
import statistics
import subprocess
import sys
import time
from typing import Any, Callable, List, Optional, Sequence

from modules.definition import load_definition
from tests.integration.conftest import NODES, wait_announced

__all__ = ["FULL", "scale", "PROBE_JSON", "PROBE_CLASS", "probe_def", "start_probe", "figure", "wait_item", "Publishers",
           "log_problems", "slow_run", "stop_run"]

FULL = os.environ.get("BMTREE_RELIABILITY") == "1"
PROBE_JSON = os.path.join(NODES, "probe.json")
PROBE_CLASS = os.path.join(NODES, "probe_module.py") + ":Probe"


def scale(reduced: int, full: int) -> int:
    return full if FULL else reduced


def probe_def() -> Any:
    return load_definition(PROBE_JSON)


def start_probe(ros_graph: Any, node: str = "bm_probe", wait: bool = True) -> Any:
    proc = ros_graph.start_node(["-m", "modules.node", "--definition", PROBE_JSON, "--class", PROBE_CLASS,
                                 "__name:=" + node], "/" + node)
    if wait:
        wait_announced("probe")
    return proc


def slow_run(tmp_path: Any, seconds: float = 100.0) -> subprocess.Popen[str]:
    """``bmtree run`` of one ``probe.work`` call of ``seconds`` as a process, once that call runs."""
    tree = tmp_path / "slow.yaml"
    tree.write_text("format: 1\nroot:\n  call: probe.work\n  inputs: {seconds: %s, tag: x}\n  timeout: 100\n"
                    % float(seconds))
    run = subprocess.Popen([sys.executable, "-m", "coordinator", "run", str(tree), "--modules", PROBE_JSON],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ))
    for line in run.stdout or ():
        if "RUNNING" in line and "probe.work" in line:
            break
    return run


def stop_run(run: subprocess.Popen[str]) -> None:
    """Ctrl-C to a run still going, and wait for it."""
    if run.poll() is None:
        run.send_signal(signal.SIGINT)
        run.wait(30)


def figure(name: str, values: List[float], unit: str = "s") -> str:
    """Print (and return) one measured figure: count, median, max."""
    if values:
        text = "FIGURE %s: n=%d median=%.3f%s max=%.3f%s" % (name, len(values), statistics.median(values), unit,
                                                            max(values), unit)
    else:
        text = "FIGURE %s: n=0" % name
    print("\n" + text)
    return text


def wait_item(q: queue.Queue[Any], predicate: Callable[[Any], bool], timeout: float) -> Optional[Any]:
    """The first queued item matching ``predicate`` (others are dropped), or None after ``timeout``."""
    end = time.monotonic() + timeout
    while True:
        left = end - time.monotonic()
        if left <= 0:
            return None
        try:
            item = q.get(timeout=left)
        except queue.Empty:
            return None
        if predicate(item):
            return item


def log_problems(path: str) -> List[str]:
    """Tracebacks and fatal lines in a node's log."""
    try:
        with open(path, errors="replace") as fh:
            text = fh.read()
    except OSError:
        return []
    return [line for line in text.splitlines() if "Traceback" in line or "Segmentation" in line]


class Publishers:
    """Publishers of this test only, unregistered at :meth:`close` (the session's probe keeps its own
    forever, and a publisher left in the test process would count as a peer in later tests)."""

    def __init__(self) -> None:
        self._pubs: dict = {}

    def get(self, topic: str, subscribers: int = 1, timeout: float = 20.0, nodes: Sequence[str] = ()) -> Any:
        """A publisher with ``subscribers`` connected, ``nodes`` among them by name."""
        import rospy
        from std_msgs.msg import String

        from coordinator.testing.ros import wait_subscribed

        pub = self._pubs.get(topic)
        if pub is None:
            pub = self._pubs[topic] = rospy.Publisher(topic, String, queue_size=10000)
        end = time.monotonic() + timeout
        while pub.get_num_connections() < subscribers:
            assert time.monotonic() < end, "only %d of %d subscribers on %s" % (
                pub.get_num_connections(), subscribers, topic)
            time.sleep(0.02)
        wait_subscribed(pub, nodes, max(0.0, end - time.monotonic()))
        return pub

    def close(self) -> None:
        for pub in self._pubs.values():
            pub.unregister()
        self._pubs.clear()
