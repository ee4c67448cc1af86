"""The README's example of a module that wraps an actionlib action: move_base.

    bmtree-module --definition modules/example/mobile_base.json --class modules/example/mobile_base.py:MobileBase
    (private parameters: _action:=move_base, the action's namespace; _frame:=map, the goal's frame)

``go_to`` is not Concurrent (one base): a cancel still reaches it while it waits, and cancels the goal.
"""
from __future__ import annotations

from typing import Any, Dict

from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal

from modules import BasicModule
from modules.actions import Action

__all__ = ["MobileBase"]


class MobileBase(BasicModule):
    def setup(self, node: Any) -> None:
        import rospy

        self._frame = rospy.get_param("~frame", "map")
        self._move_base = Action(self, rospy.get_param("~action", "move_base"), MoveBaseAction)
        self._move_base.connect()  # connects now, in the background: the first call does not wait for it

    def go_to(self, target: Any) -> Dict[str, Any]:
        goal = MoveBaseGoal()
        goal.target_pose.header.frame_id = self._frame
        goal.target_pose.pose = target
        seen = [target.position]  # move_base's feedback: where the robot is

        return self._move_base.run(
            goal,
            outputs=lambda result: {"success": True, "position": seen[-1]},  # MoveBaseResult is empty
            feedback=lambda fb: seen.append(fb.base_position.pose.position))
