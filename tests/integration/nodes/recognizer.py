"""Stand-in speech recognizer for the README's keywords example: a std_srvs/SetBool service
/speech_recognition/enable, and once enabled, "  STOP  " on /speech_recognition/final_result every
0.1 s (so a wait_event that starts after the call still hears it)."""
from __future__ import annotations

import rospy
from std_msgs.msg import String
from std_srvs.srv import SetBool, SetBoolResponse


def main() -> None:
    rospy.init_node("recognizer")
    enabled = []
    pub = rospy.Publisher("/speech_recognition/final_result", String, queue_size=10)

    def enable(req):
        enabled.append(req.data)
        return SetBoolResponse(success=True, message="listening" if req.data else "deaf")

    rospy.Service("/speech_recognition/enable", SetBool, enable)
    rate = rospy.Rate(10)
    while not rospy.is_shutdown():
        if enabled and enabled[-1]:
            pub.publish(String("  STOP  "))
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break


if __name__ == "__main__":
    main()
