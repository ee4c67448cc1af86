"""What a module author writes against: the :class:`BasicModule` base class, the call's
:class:`CallContext`, and the exceptions that answer ``failed`` or ``rejected``.

Kept apart from the server that runs calls (:mod:`modules.runtime`), so that an author's
view of a module reads on its own.
"""
from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Optional, Set, Union

from modules.definition import ModuleDefinition
from modules.outcome import Outcome

if TYPE_CHECKING:  # pragma: no cover
    from modules.runtime import ModuleServer

__all__ = ["BasicModule", "CallContext", "Cancelled", "Failure", "Rejected", "BindingError", "public_methods"]

log = logging.getLogger("bmtree.module")


class Failure(Exception):
    """Raise (or return) this from a function to answer ``failed`` with a reason.

    ``not_stopped``: raised by a cancelled call whose code gave up waiting for what it drives to stop
    (an action server that ignores its cancel), what may go on (``/move_base did not end the goal
    within 0.8s of its cancel``): the call answers ``cancelled`` saying so, and ``bmtree run`` lists it
    under "may still be running"."""

    def __init__(self, *args: Any, not_stopped: str = ""):
        super().__init__(*args)
        self.not_stopped = not_stopped


class Rejected(Exception):
    """Raise this to answer ``rejected``: the call cannot be taken now (its Exec-condition
    does not hold), as opposed to a call that was tried and failed."""


class BindingError(Exception):
    """The class and the definition do not match (named in the message)."""


class Cancelled(threading.Event):
    """A call's cancel flag: an Event (``wait``, ``is_set``) that is also true or false by itself, so
    ``if self.context.cancelled:`` and ``self.context.cancelled()`` (the C++ library's spelling) say
    whether the call was cancelled, as a reader expects (a plain Event is always true)."""

    def __bool__(self) -> bool:
        return self.is_set()

    def __call__(self) -> bool:
        return self.is_set()


class CallContext:
    """What a running function knows about its call: id, and whether it was cancelled."""

    def __init__(self, call_id: Optional[str], function: str):
        self.call_id = call_id
        self.function = function
        self.cancelled = Cancelled()
        self._callbacks: List[Callable[[], None]] = []
        self._lock = threading.Lock()

    def on_cancel(self, callback: Callable[[], None]) -> None:
        """Run ``callback`` (once, from the cancelling thread) when the call is cancelled."""
        with self._lock:
            if not self.cancelled.is_set():
                self._callbacks.append(callback)
                return
        callback()

    def cancel(self) -> bool:
        """Cancel the call; False if it was cancelled already (a second cancel changes nothing)."""
        with self._lock:
            if self.cancelled.is_set():
                return False
            self.cancelled.set()
            callbacks, self._callbacks = self._callbacks, []
        for cb in callbacks:
            try:
                cb()
            except BaseException:  # noqa: B036 - it runs in the thread that takes cancels: that goes on
                log.exception("cancel callback of %s failed", self.function)
        return True

    def sleep(self, seconds: float) -> bool:
        """Sleep unless cancelled first; True if the full time passed (an infinite time waits for the
        cancel, NaN does not wait). This blocks a worker thread in wall time: to wait on the
        module's clock (simulated in tests), return an Outcome with a ``delay`` instead."""
        if seconds != seconds or seconds <= 0:
            return not self.cancelled.is_set()
        if seconds > threading.TIMEOUT_MAX:
            self.cancelled.wait()
            return False
        return not self.cancelled.wait(seconds)


class BasicModule:
    """Base class for module authors: one method per function of the definition.

    A method receives its inputs as keyword arguments (ROS messages, by name) and
    returns a dict of outputs (ROS messages or YAML-like values such as ``True`` for
    ``std_msgs/Bool``), or an :class:`~modules.outcome.Outcome` (``succeed(delay=2.0, ...)``).
    Raise or return :class:`Failure` to answer ``failed``.
    Long functions should watch ``self.context.cancelled`` or use
    ``self.context.sleep``.

    Attributes:
        concurrent: True, or a set of function names that may run while others run.
            Non-concurrent functions exclude each other (they share the hardware).
    """

    concurrent: Union[bool, Set[str]] = False

    def __new__(cls, *args: Any, **kwargs: Any) -> BasicModule:
        # what the runtime needs is set here, so that a class whose __init__ does not call
        # super().__init__() still runs its calls (they failed, unanswered, with an AttributeError)
        self = super().__new__(cls)
        self._server = None
        self._local = threading.local()
        return self

    def __init__(self) -> None:
        self._server: Optional[ModuleServer] = None
        self._local = threading.local()

    @property
    def context(self) -> CallContext:
        ctx = getattr(self._local, "ctx", None)
        if ctx is None:
            raise RuntimeError("no call is running in this thread")
        return ctx

    @property
    def definition(self) -> ModuleDefinition:
        return self._bound("definition").definition

    def emit(self, event: str, **params: Any) -> None:
        """Publish an event of this module, checked against the definition's Events."""
        self._bound("emit(%r)" % (event,)).emit(event, params)

    def _bound(self, what: str) -> ModuleServer:
        server = self._server
        if server is None:  # an assert would be gone under python -O, and say less
            raise RuntimeError("%s of %s before its runtime is bound: use it in a function, in setup() or later, "
                               "not in __init__" % (what, type(self).__name__))
        return server

    def before_call(self, function: str, inputs: Dict[str, Any]) -> Optional[Outcome]:
        """Hook run in the call's turn before the function: return an Outcome to answer with it
        instead of running the method (fault injection), None to run the method."""
        return None

    def not_ready(self, caller: Optional[str] = None) -> str:
        """Hook asked at each ping (``bmtree run``'s start-up check, from node ``caller``): why the module
        cannot take a call now, '' when it can. A reason leaves the ping unanswered, so the run waits for
        the module as for one not started yet (the C++ bridge while its C++ node is not running)."""
        return ""

    def setup(self, node: Any) -> None:
        """Hook run once by the ROS node after it connected (extra topics, parameters)."""

    def shutdown(self) -> None:
        """Hook run once when the node stops."""


_RESERVED = set(dir(BasicModule))


def public_methods(obj: Any) -> Set[str]:
    """The names of ``obj``'s methods that must be functions of its definition (BasicModule's own excepted)."""
    return {n for n in dir(type(obj)) if not n.startswith("_") and n not in _RESERVED
            and callable(getattr(type(obj), n, None))}
