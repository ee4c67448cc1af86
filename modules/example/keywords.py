"""The README's example of a ROS topic as module events and a ROS service as a module function
(SMACH's MonitorState and ServiceState): a tree's leaves talk only to modules, so a topic or a
service of another node is reached through a module like this one."""
from __future__ import annotations

from typing import Any, Dict

import rospy
from std_msgs.msg import String
from std_srvs.srv import SetBool

from modules import BasicModule, Failure
from modules.errortext import service_error


class Keywords(BasicModule):
    def setup(self, node: Any) -> None:                 # after rospy.init_node
        self._enable = rospy.get_param("~enable_service", "/speech_recognition/enable")
        rospy.Subscriber(rospy.get_param("~topic", "/speech_recognition/final_result"), String, self._on_text,
                         queue_size=10)

    def _on_text(self, msg: String) -> None:            # in rospy's thread: emit may be called from any
        self.emit("heard", text=msg.data.strip().lower())

    def listen(self, enabled: Any) -> Dict[str, Any]:  # enabled: std_msgs/Bool
        try:
            rospy.wait_for_service(self._enable, timeout=2.0)
            answer = rospy.ServiceProxy(self._enable, SetBool)(enabled.data)
        except (rospy.ROSException, rospy.ServiceException) as exc:
            raise Failure("%s: %s" % (self._enable, service_error(exc)))   # the server's words, not b'…'
        if not answer.success:
            raise Failure("%s refused: %s" % (self._enable, answer.message))
        return {"success": True}
