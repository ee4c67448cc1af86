"""Addressed calls: each bmtree module's own call and cancel topics, and what readers need.

The original protocol broadcasts every call on ``/master/output``, so every module
receives (and used to decode) every call. A bmtree module also listens on
``/bmtree/call/<module>`` and ``/bmtree/cancel/<module>`` and names them in its
announcement; a coordinator that reads the announcement sends there, and on the
shared topics otherwise. Nothing here talks to ROS.

A preflight *ping* is a call of the reserved function :data:`PING_FUNCTION` (no
inputs) on a module's call topic: a bmtree module answers it on
``/function/output`` with ``status: succeeded`` and the ping's ``call_id``; a bmtree
module too old to know pings answers ``rejected`` (unknown function), which proves
the round trip just as well. The name cannot clash with a definition's functions
(their names are identifiers).

A module also takes a cancel on its call topic, marked ``"cancel": true``
(:func:`cancel_on_call_topic`): bmtree's coordinator cancels there, so that a cancel sent
right after its call travels on the same connection and can never overtake it, and so
that a preflight registers one publisher per module, not two.
"""
from __future__ import annotations

import json
import re
import threading
from collections import OrderedDict
from typing import Any, Optional

__all__ = ["CALL_PREFIX", "CANCEL_PREFIX", "PING_FUNCTION", "call_topic", "cancel_topic", "valid_topic",
           "surely_not_for", "cancel_on_call_topic", "RecentIds"]

CALL_PREFIX = "/bmtree/call/"
CANCEL_PREFIX = "/bmtree/cancel/"
PING_FUNCTION = "bmtree/ping"

_PLAIN = re.compile(r"^[A-Za-z0-9_]+$")
_TOPIC = re.compile(r"^(/[A-Za-z][A-Za-z0-9_]*)+$")
_SHARED = {"/master/output", "/master/cancel", "/function/output", "/event/output", "/blackboard/input",
           "/blackboard/output", "/blackboard/stored"}


def call_topic(module: str) -> str:
    """The topic on which ``module`` takes calls addressed to it alone."""
    return CALL_PREFIX + module


def cancel_topic(module: str) -> str:
    """The topic on which ``module`` takes cancels addressed to it alone."""
    return CANCEL_PREFIX + module


def valid_topic(name: Any) -> bool:
    """True for a global ROS topic name that is none of the protocol's shared topics.

    A coordinator sends to an announced topic only if this holds, so that a wrong or
    hostile announcement cannot turn calls into results or Blackboard requests.
    """
    return isinstance(name, str) and len(name) <= 256 and bool(_TOPIC.match(name)) and name not in _SHARED


def surely_not_for(text: Any, module: str) -> bool:
    """True when payload ``text`` cannot be addressed to ``module``, found without parsing it.

    A module name is an identifier, so in JSON it can only be disguised by ``\\u``
    escapes: a payload with no ``"<module>"`` and no ``\\u`` anywhere cannot have
    ``basic_mod == module``. Anything else (including what is not text) is left to the
    full decoder, which reports malformed payloads.
    """
    if not isinstance(text, str) or not _PLAIN.match(module):
        return False
    return ('"%s"' % module) not in text and "\\u" not in text


def cancel_on_call_topic(call_id: str, basic_mod: str, function: str) -> str:
    """A cancel as sent on a module's call topic: ``/master/cancel``'s payload plus ``"cancel": true``."""
    return json.dumps({"call_id": call_id, "basic_mod": basic_mod, "function": function, "cancel": True},
                      separators=(",", ":"))


class RecentIds:
    """The last ``size`` ids seen, so that a call received on two topics runs once.

    Memory is bounded: the oldest id is forgotten when a new one comes.
    """

    def __init__(self, size: int = 4096):
        self.size = size
        self._ids: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    def first(self, ident: Optional[str]) -> bool:
        """Record ``ident``; True unless it was seen among the last ``size`` (None is always new)."""
        if ident is None:
            return True
        with self._lock:
            if ident in self._ids:
                return False
            self._ids[ident] = None
            if len(self._ids) > self.size:
                self._ids.popitem(last=False)
            return True

    def __len__(self) -> int:
        with self._lock:
            return len(self._ids)
