"""A stand-in move_base: an actionlib SimpleActionServer of move_base_msgs/MoveBase in its own process.

    move_base_server.py MODE LOG      MODE: succeed | abort | slow | stubborn | instant

``succeed`` sends one feedback (the robot at the goal) and succeeds after 0.2 s; ``abort`` aborts with a
status text; ``slow`` runs up to 60 s unless preempted; ``stubborn`` ignores a cancel and succeeds after
4 s (a server that does not honour preemption); ``instant`` succeeds in the goal callback itself,
so the result can reach the client before its ``send_goal`` has returned. Every goal and how it ended
is written to LOG, a line each (``goal``, ``succeeded``, ``aborted``, ``preempted``).
"""
import sys
import time

import actionlib
import rospy
from move_base_msgs.msg import MoveBaseAction, MoveBaseFeedback, MoveBaseResult

mode, path = sys.argv[1], sys.argv[2]
out = open(path, "a", buffering=1)
rospy.init_node("move_base")
server = None


def execute(goal):
    out.write("goal %.1f %.1f\n" % (goal.target_pose.pose.position.x, goal.target_pose.pose.position.y))
    if mode == "abort":
        server.set_aborted(MoveBaseResult(), "no valid plan to the goal")
        out.write("aborted\n")
        return
    if mode == "succeed":
        fb = MoveBaseFeedback()
        fb.base_position = goal.target_pose
        fb.base_position.pose.position.z = 0.5  # tells the feedback's position from the target's
        server.publish_feedback(fb)
        time.sleep(0.2)
        server.set_succeeded(MoveBaseResult())
        out.write("succeeded\n")
        return
    end = time.monotonic() + (4 if mode == "stubborn" else 60)
    while time.monotonic() < end:
        if server.is_preempt_requested() and mode != "stubborn":
            server.set_preempted(MoveBaseResult(), "cancelled by the client")
            out.write("preempted\n")
            return
        time.sleep(0.02)
    server.set_succeeded(MoveBaseResult())
    out.write("succeeded\n")


def instant():
    goal = server.accept_new_goal()
    out.write("goal %.1f %.1f\n" % (goal.target_pose.pose.position.x, goal.target_pose.pose.position.y))
    server.set_succeeded(MoveBaseResult())
    out.write("succeeded\n")


if mode == "instant":
    server = actionlib.SimpleActionServer("move_base", MoveBaseAction, auto_start=False)
    server.register_goal_callback(instant)
else:
    server = actionlib.SimpleActionServer("move_base", MoveBaseAction, execute_cb=execute, auto_start=False)
server.start()
out.write("ready\n")
rospy.spin()
