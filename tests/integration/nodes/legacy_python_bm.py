"""The original PYTHON_BM template module, written only with the legacy commBM API.

No bmtree runtime: it reads calls with readFunCall and answers with writeMsgFromRos,
exactly as modules written against the original basicmodutil_pkg did (no call_id).
``obj_radius`` doubles as a delay in seconds, to exercise timeouts.
"""
import time

import rospy
from geometry_msgs.msg import Point
from std_msgs.msg import Bool, String

from basicmodutil_pkg import commBM

rospy.init_node("PYTHON_BM")
pub = rospy.Publisher("/function/output", String, queue_size=10)
pos = Point(0.0, 0.0, 0.5)


def on_call(msg):
    global pos
    call = commBM.readFunCall(msg.data)
    if call == [] or call[0] != "PYTHON_BM":
        return
    _, fun, msgs = call
    if fun == "graspObject":
        time.sleep(max(0.0, msgs[1].data))
        pos = Point(msgs[0].x, msgs[0].y, msgs[0].z)
        ok = True
    elif fun == "putObject":
        pos = Point(msgs[0].x, msgs[0].y, msgs[0].z)
        ok = True
    elif fun == "goSafePos":
        pos = Point(0.0, 0.0, 0.5)
        ok = True
    else:
        return
    pub.publish(String(commBM.writeMsgFromRos([Bool(ok), pos], ["success", "final_pos"])))


rospy.Subscriber("/master/output", String, on_call)
rospy.spin()
