"""A module node (re)started while calls wait for it answers them: the answer waits for the caller.

ROS connects the two directions between a caller and a new module node independently: the call
reaches the node when it subscribes to the call topic, the node's answer reaches the caller once
the caller has connected to the node's result topic. A node that answered at once answered into
nothing, and the call waited out its whole timeout (seen with roslaunch ``respawn``).
"""
from __future__ import annotations

import json

import rospy
from std_msgs.msg import String

from comm.addressing import call_topic
from tests.integration.faultkit import probe_def, start_probe


def test_a_call_waiting_for_a_starting_module_is_answered(ros_graph, ros_probe):
    echo = probe_def().function("echo")
    results = ros_probe.collect("/function/output")
    # latched: delivered the moment the module's node subscribes, before it can know this node reads its answers
    waiting = rospy.Publisher(call_topic("probe"), String, queue_size=10, latch=True)
    try:
        for i in range(5):
            call = echo.build_call({"tag": "waited %d" % i})
            waiting.publish(String(call.encode()))
            proc = start_probe(ros_graph)
            answers = results.wait_for(lambda t, c=call.call_id: json.loads(t).get("call_id") == c, 10)
            assert json.loads(answers[0])["status"] == "succeeded", answers
            ros_graph.stop_node(proc)
    finally:
        waiting.unregister()
        ros_probe.close_collector(results)
