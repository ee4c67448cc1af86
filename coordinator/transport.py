"""How the coordinator reaches modules: an interface, so the engine runs with or without ROS.

A transport sends calls, cancels and Blackboard requests, and hands every decoded
incoming message (FunctionResult, Event, BlackboardAnswer) to ``deliver``, from any
thread; the runner queues them and handles them in its ticking thread.
"""
from __future__ import annotations

import abc
import contextlib
from typing import Any, Callable, ContextManager, Iterable, Optional

from comm.messages import BlackboardRequest, CancelRequest, FunctionCall

__all__ = ["Transport", "NullTransport"]


class Transport(abc.ABC):
    @abc.abstractmethod
    def connect(self, deliver: Callable[[Any], None]) -> None:
        """Start receiving; ``deliver`` gets decoded messages."""

    @abc.abstractmethod
    def send_call(self, call: FunctionCall) -> None:
        """Publish a call."""

    @abc.abstractmethod
    def send_cancel(self, cancel: CancelRequest) -> None:
        """Publish a cancel."""

    @abc.abstractmethod
    def send_request(self, request: BlackboardRequest) -> None:
        """Ask the Blackboard node."""

    def hold(self) -> ContextManager[Any]:
        """Sends made inside may wait and leave together at its end (the runner holds each
        tick: the calls a tick makes to one module then cost it one write and one wake-up)."""
        return contextlib.nullcontext()

    def wait_ready(self, modules: Iterable[str], timeout: float) -> None:  # noqa: B027 - optional, no-op default
        """Block until the named modules can be called (raise EnvironmentProblem if not)."""

    def watch_module(self, module: str) -> Optional[str]:
        """Watch ``module``'s node as a call in flight's is watched (a ``wait_event`` waits for one of its
        events): a key, which a ``ModuleLost`` delivered for the module carries as a call id once the node
        is gone; None when this transport has no nodes to lose (in process: mocks do not die)."""
        return None

    def unwatch_module(self, key: str) -> None:  # noqa: B027 - optional, no-op default
        """The wait that :meth:`watch_module` gave ``key`` for has ended."""

    def close(self) -> None:  # noqa: B027 - optional, no-op default
        """Stop receiving and release resources."""


class NullTransport(Transport):
    """For trees built only to be checked or rendered: sending anything is a bug."""

    def connect(self, deliver: Callable[[Any], None]) -> None:
        raise RuntimeError("this tree was built offline (check/render) and cannot run")

    def send_call(self, call: FunctionCall) -> None:
        raise RuntimeError("this tree was built offline (check/render) and cannot run")

    def send_cancel(self, cancel: CancelRequest) -> None:
        raise RuntimeError("this tree was built offline (check/render) and cannot run")

    def send_request(self, request: BlackboardRequest) -> None:
        raise RuntimeError("this tree was built offline (check/render) and cannot run")
