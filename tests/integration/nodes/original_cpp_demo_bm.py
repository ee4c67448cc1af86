"""The original example C++ module DEMO_BM, as it behaves on the wire (manual §4.3).

For the bridge's compatibility tests: written from the protocol as measured on the wire
(definition: tests/data/reference/DEMO_BM.json), with its limits kept on purpose. Node
``/DEMO_BM``; it publishes and subscribes every data topic (so it also hears its own
messages), keeps the **last** message of each topic, reads the inputs from those when
``BM_input`` arrives, ignores unknown functions, publishes the outputs, waits
``_delay`` seconds in its only callback thread (the original waits 1 s) and then
``BM_output``.
"""
from __future__ import annotations

import json
import threading
import time

import rospy
from std_msgs.msg import Bool, String

BM = "DEMO_BM"


def main() -> None:
    rospy.init_node(BM)
    delay = float(rospy.get_param("~delay", 0.05))
    lock = threading.Lock()  # roscpp's single spinner thread
    last = {"/%s/string" % BM: String(), "/%s/bool" % BM: Bool()}
    pubs = {"/%s/string" % BM: rospy.Publisher("/%s/string" % BM, String, queue_size=1),
            "/%s/bool" % BM: rospy.Publisher("/%s/bool" % BM, Bool, queue_size=1)}
    out_pub = rospy.Publisher("/%s/BM_output" % BM, String, queue_size=1)

    def keep(topic):
        def cb(msg):
            with lock:
                last[topic] = msg
        return cb

    def on_input(msg):
        with lock:
            req = json.loads(msg.data)
            values = [last[t] for t in req["inparam_topics"]]
            if req["function"] == "functionA":       # (Aviso: String, Bandera: Bool) -> status: String
                aviso, bandera = values
                outputs = [("status", "/%s/string" % BM, String("%s:%s" % (aviso.data, "si" if bandera.data else "no")))]
            elif req["function"] == "functionB":     # (LSB: Bool, Contexto: String) -> flag: Bool
                lsb, contexto = values
                outputs = [("flag", "/%s/bool" % BM, Bool(lsb.data != (contexto.data == "invert")))]
            else:
                return                                # the original answers nothing
            for _, topic, value in outputs:
                pubs[topic].publish(value)
            time.sleep(delay)
            out_pub.publish(String(json.dumps({"outparam_names": [o[0] for o in outputs],
                                               "outparam_topics": [o[1] for o in outputs]},
                                              separators=(",", ":"))))

    rospy.Subscriber("/%s/string" % BM, String, keep("/%s/string" % BM), queue_size=1)
    rospy.Subscriber("/%s/bool" % BM, Bool, keep("/%s/bool" % BM), queue_size=1)
    rospy.Subscriber("/%s/BM_input" % BM, String, on_input, queue_size=1)
    rospy.spin()


if __name__ == "__main__":
    main()
