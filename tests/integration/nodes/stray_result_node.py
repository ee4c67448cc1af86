"""An original-style node that answers every call it sees with ``success: false`` at once
(no call id, no module: it does not even check which module is called). bmtree must never
take its results for another module's call. It answers once ``~subscribers`` nodes listen
to its results, so none of its answers is lost."""
from __future__ import annotations

import time

import rospy
from geometry_msgs.msg import Point
from std_msgs.msg import Bool, String

from comm import commBM

rospy.init_node("stray")
need = int(rospy.get_param("~subscribers", 2))
pub = rospy.Publisher("/function/output", String, queue_size=10)


def on_call(msg):
    end = time.monotonic() + 20
    while pub.get_num_connections() < need and time.monotonic() < end:
        time.sleep(0.01)
    pub.publish(String(commBM.writeMsgFromRos([Bool(False), Point(9.0, 9.0, 9.0)], ["success", "final_pos"])))


rospy.Subscriber("/master/output", String, on_call)
rospy.spin()
