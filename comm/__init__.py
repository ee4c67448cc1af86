"""The bmtree wire protocol: typed messages, ROS value conversion, legacy commBM."""
from __future__ import annotations

import time

from comm.errors import ProtocolError
from comm.messages import (
    DEFAULT_MAX_BYTES,
    STATUSES,
    BlackboardAnswer,
    BlackboardRequest,
    CallStatus,
    CancelRequest,
    Event,
    FunctionCall,
    FunctionResult,
    new_id,
)
from comm.rostypes import from_message, resolve_type, suggest_type, to_message
from comm.typewords import ValueMisfit, said_of

__all__ = [
    "DEFAULT_MAX_BYTES",
    "STATUSES",
    "BlackboardAnswer",
    "BlackboardRequest",
    "CallStatus",
    "CancelRequest",
    "Event",
    "FunctionCall",
    "FunctionResult",
    "ProtocolError",
    "ValueMisfit",
    "from_message",
    "new_id",
    "resolve_type",
    "said_of",
    "settle_new_connection",
    "suggest_type",
    "to_message",
]

# The topic names of DESIGN §2, in one place.
TOPIC_CALL = "/master/output"
TOPIC_RESULT = "/function/output"
TOPIC_CANCEL = "/master/cancel"
TOPIC_EVENT = "/event/output"
TOPIC_BB_REQUEST = "/blackboard/input"
TOPIC_BB_ANSWER = "/blackboard/output"


def sync_publisher(topic: str, data_class: type, **kwargs: object) -> object:
    """A rospy publisher that writes in the publishing thread (``queue_size=None``).

    rospy's queued publish hands each message to a writer thread and yields the GIL,
    which costs more than the whole protocol for the small, infrequent messages of
    calls, results and answers. Only for publishers whose callers may block briefly.
    """
    import warnings

    import rospy

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rospy.Publisher(topic, data_class, queue_size=None, **kwargs)


def settle_new_connection() -> None:
    """Wait the moment a publisher needs after a subscriber first counts their connection.

    rospy's publisher adds a connection to its topic only after writing its header, which is
    when the subscriber's side counts it: a message published in between goes to nobody.
    """
    time.sleep(0.05)
