"""A misbehaving module: ignores cancels and answers after ``seconds`` whatever happened.

It announces itself like a bmtree module (so ``bmtree run`` accepts it) but answers
with raw typed messages, to test that a late answer is never taken for another call.
"""
import os
import threading
import time

import rospy
from std_msgs.msg import String

from comm import FunctionCall
from modules.definition import load_definition
from modules.discovery import PARAM_ROOT, announcement

definition = load_definition(os.path.join(os.path.dirname(__file__), "late.json"))
fn = definition.function("echo")
rospy.init_node("bm_late")
pub = rospy.Publisher("/function/output", String, queue_size=10)


def answer(call):
    inputs = fn.inputs_of(call)
    time.sleep(inputs["seconds"].data)
    pub.publish(String(fn.build_result({"tag": inputs["tag"].data}, call.call_id).encode()))


def on_call(msg):
    call = FunctionCall.decode(msg.data)
    if call.basic_mod == "late":
        threading.Thread(target=answer, args=(call,), daemon=True).start()


rospy.Subscriber("/master/output", String, on_call)
rospy.set_param(PARAM_ROOT + "/late", announcement(rospy.get_name(), definition))
rospy.spin()
