"""modules.errortext.service_error: what a ROS service raised, in the server's words (rospy formats the
bytes it read with %s, so a call answered `... responded with an error: b'error processing request: ...'`)."""
from __future__ import annotations

import rospy

from modules.errortext import service_error


def _as_rospy_says(raw: bytes) -> rospy.ServiceException:
    # rospy/impl/tcpros_service.py: ServiceException("service [%s] responded with an error: %s" % (name, str))
    return rospy.ServiceException("service [%s] responded with an error: %s" % ("/detect_object", raw))


def test_the_servers_words_replace_the_bytes_repr():
    exc = _as_rospy_says(b"error processing request: camera driver not responding")
    assert "b'" in str(exc)
    assert service_error(exc) == ("service [/detect_object] responded with an error: error processing request: "
                                  "camera driver not responding")


def test_non_ascii_and_quotes_come_back_as_written():
    exc = _as_rospy_says("error processing request: la cámara no responde ('USB')".encode())
    assert service_error(exc).endswith("error processing request: la cámara no responde ('USB')")


def test_other_errors_are_left_as_they_are():
    assert service_error(rospy.ROSException("timeout exceeded while waiting for service /x")) == \
        "timeout exceeded while waiting for service /x"
    assert service_error(rospy.ServiceException("service [/x] unavailable")) == "service [/x] unavailable"
