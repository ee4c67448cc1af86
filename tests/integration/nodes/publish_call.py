"""Test node: publish one FunctionCall on /master/output once a subscriber is connected."""
import sys
import time

import rospy
from geometry_msgs.msg import Point
from std_msgs.msg import Float64, String

from comm import FunctionCall

rospy.init_node("publish_call")
pub = rospy.Publisher("/master/output", String, queue_size=10)
end = time.monotonic() + 20
while pub.get_num_connections() < int(sys.argv[1]) and time.monotonic() < end:
    time.sleep(0.02)
call = FunctionCall("PYTHON_BM", "graspObject", [Point(0.4, -0.1, 0.8), Float64(0.05)],
                    names=["target_pos", "obj_radius"], call_id="from-a-process")
pub.publish(String(call.encode()))
time.sleep(1.0)
