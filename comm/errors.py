"""The one exception class of the wire protocol."""
from __future__ import annotations

__all__ = ["ProtocolError"]


class ProtocolError(ValueError):
    """A payload or value that does not follow the bmtree wire protocol.

    The message always names the problem (the key, the index, the ROS type), so
    that a log line is enough to find the sender's mistake.
    """
