"""Route bmtree's Python loggers (``bmtree.*``) to ``/rosout`` and to the node's terminal.

rospy sends only its own ``rosout`` logger to ``/rosout`` and the screen; a plain Python
logger reaches just the node's log file under ``$ROS_HOME/log``. A module method's
traceback would then be invisible where the module's author looks (its terminal, roslaunch
``output="screen"``, ``rqt_console``). Call :func:`log_to_rosout` once after ``rospy.init_node``.
"""
from __future__ import annotations

import logging

__all__ = ["log_to_rosout"]

_MARK = "_bmtree_rosout"


def log_to_rosout(name: str = "bmtree", level: int = logging.INFO) -> None:
    """Add a ``/rosout`` handler and a terminal handler (warnings and errors with tracebacks
    on stderr, as rospy prints its own) to the ``name`` logger; idempotent."""
    from rosgraph.roslogging import RosStreamHandler
    from rospy.impl.rosout import RosOutHandler

    logger = logging.getLogger(name)
    if getattr(logger, _MARK, False):
        return
    logger.addHandler(RosOutHandler())
    logger.addHandler(RosStreamHandler(colorize=True))
    logger.setLevel(level)
    setattr(logger, _MARK, True)
