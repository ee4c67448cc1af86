"""A module node of events only (``"Functions": []``), the bmtree form of SMACH's MonitorState: it turns
a ROS topic into events, says at start-up that it serves no functions and which events (it said
``serving `` with an empty list), and a tree's ``wait_event`` takes its event in ``bmtree run``."""
from __future__ import annotations

import json
import os
import subprocess
import time

from std_msgs.msg import String

from tests.conftest import until
from tests.integration.conftest import bmtree_cmd, wait_announced
from tests.unit.test_monitor_module import MONITOR

TOPIC = "/test_monitor/door"
DEFINITION = MONITOR
CLASS = '''import rospy
from std_msgs.msg import String

from modules import BasicModule


class DoorMonitor(BasicModule):
    def setup(self, node):
        self._sub = rospy.Subscriber(%r, String, self._on_door)

    def _on_door(self, msg):
        self.emit("heard", text=msg.data)
''' % TOPIC


def test_an_events_only_module_node_says_what_it_serves_and_a_tree_waits_for_its_event(tmp_path, ros_graph,
                                                                                         ros_probe):
    definition = tmp_path / "door_monitor.json"
    definition.write_text(json.dumps(DEFINITION))
    (tmp_path / "door_monitor.py").write_text(CLASS)
    ros_graph.start_node(["-m", "modules.node", "--definition", str(definition), "--class",
                          str(tmp_path / "door_monitor.py") + ":DoorMonitor"], "/bm_door_monitor")
    wait_announced("door_monitor")
    out_path = os.path.join(ros_graph.ros_home, "bm_door_monitor.out")

    def said() -> str:
        with open(out_path, encoding="utf-8") as fh:
            return fh.read()

    until(lambda: "basic module 'door_monitor' serving no functions; events: heard" in said(), 10, said)
    tree = tmp_path / "door.yaml"
    tree.write_text("format: 1\nroot:\n  wait_event: door_monitor.heard\n  where: 'text == \"open\"'\n"
                    "  outputs: {text: door}\n  timeout: 60\n")
    run = subprocess.Popen(bmtree_cmd("run", "-q", "--modules", str(definition), str(tree)), text=True,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                           env=dict(os.environ))
    try:
        door = ros_probe.publisher(TOPIC, 1)
        end = time.monotonic() + 60
        while run.poll() is None and time.monotonic() < end:   # the event counts once the leaf waits
            door.publish(String("open"))
            time.sleep(0.2)
        text = run.communicate(timeout=30)[0]
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == 0, text
    assert "Traceback" not in said() and "Traceback" not in text, said() + text
