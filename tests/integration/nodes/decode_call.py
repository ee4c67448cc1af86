"""Test node: print the first FunctionCall seen on /master/output as JSON, then exit."""
import json
import sys
import threading

import rospy
from std_msgs.msg import String

from comm import FunctionCall, from_message

done = threading.Event()


def on_call(msg):
    call = FunctionCall.decode(msg.data)
    print(json.dumps({"basic_mod": call.basic_mod, "function": call.function, "names": call.names,
                      "call_id": call.call_id, "values": [from_message(m) for m in call.msgs]}), flush=True)
    done.set()


rospy.init_node("decode_call")
rospy.Subscriber("/master/output", String, on_call)
sys.exit(0 if done.wait(20) else 1)
