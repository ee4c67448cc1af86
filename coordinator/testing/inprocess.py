"""The in-process transport of tree tests: every mocked module served by the real module
runtime, and an in-memory Blackboard, in the coordinator's process on the run's clock."""
from __future__ import annotations

import threading
from typing import Any, Callable, Dict, List, Optional, Tuple

from blackboard.service import BlackboardService
from blackboard.store import Store
from comm.liveness import ModuleLost
from comm.messages import (
    BlackboardAnswer,
    BlackboardRequest,
    CancelRequest,
    FunctionCall,
    FunctionResult,
)
from coordinator.clock import Clock
from coordinator.testing.mocks import MockModule, Mocks, mock_module
from coordinator.transport import Screen, Transport
from modules.execution import ClockExecutor
from modules.runtime import ModuleServer

__all__ = ["InProcessTransport"]


class InProcessTransport(Transport):
    """The module runtime serving every mocked module, and an in-memory Blackboard, in the
    coordinator's process on the run's clock."""

    def __init__(self, mocks: Mocks, clock: Clock):
        self.mocks = mocks
        self.clock = clock
        self._deliver: Callable[[Any], None] = lambda item: None
        self._blackboard: Optional[BlackboardService] = None
        self._blackboard_lock = threading.Lock()   # results (timer thread) and requests (tick thread) may race
        self.sent: List[Any] = []
        self._made: Dict[str, int] = {}  # calls sent, per module.function (for the events tied to them)
        self.screen = Screen(mocks.definitions)  # what the modules send, checked as the ROS transport does
        executor = ClockExecutor(clock)
        self.servers: Dict[str, ModuleServer] = {
            name: ModuleServer(definition, mock_module(mocks, name), self._on_result, self._on_event,
                               executor=executor, scheduler=clock)
            for name, definition in mocks.definitions.items()}
        for name, server in self.servers.items():
            server.on_death = lambda ids, reason, name=name: self._died(name, ids, reason)
        if mocks.stored_values:
            self._seed(clock.now())

    def _seed(self, start: float) -> None:
        """Store the values of :meth:`Mocks.stored` as the results of earlier calls would be, through
        the real service: a second apart, the newest a second before ``start`` (the run's own
        results are newer, by order and by stamp)."""
        batches = self.mocks.stored_values
        for i, entries in enumerate(batches):
            by_function: Dict[Tuple[Optional[str], Optional[str]], List[Tuple[str, Any]]] = {}
            for mod, fn, name, msg in entries:
                by_function.setdefault((mod, fn), []).append((name, msg))
            for (mod, fn), values in by_function.items():
                result = FunctionResult(names=[n for n, _ in values], msgs=[m for _, m in values],
                                        basic_mod=mod, function=fn)
                self.blackboard.on_result(result.encode(), stamp=start - (len(batches) - i))

    @property
    def blackboard(self) -> BlackboardService:
        """The in-memory Blackboard, made at the first result or request (a sqlite database costs
        a fifth of a millisecond, and loading or checking a tree needs none)."""
        service = self._blackboard
        if service is None:
            with self._blackboard_lock:
                if self._blackboard is None:
                    self._blackboard = BlackboardService(Store(":memory:"), self._on_answer, threaded=False)
                service = self._blackboard
        return service

    def connect(self, deliver: Callable[[Any], None]) -> None:
        self._deliver = deliver
        for server in self.servers.values():
            impl = server.impl
            assert isinstance(impl, MockModule)
            impl._start_events()

    def _died(self, module: str, call_ids: List[str], reason: str) -> None:
        """A ``die`` outcome: the run learns it as from the ROS transport's watchdog (the mock is ready
        again for the calls that follow, as a respawned node would be)."""
        self.screen.ended(call_ids)
        self._deliver(ModuleLost(module, "/%s" % module, reason, list(call_ids)))

    def _on_event(self, text: str) -> None:
        for item in self.screen.event(text):   # as over ROS: one that breaks its definition is refused
            self._deliver(item)

    def _on_answer(self, text: str) -> None:
        self._deliver(BlackboardAnswer.decode(text))

    def _on_result(self, text: str) -> None:
        self.blackboard.on_result(text, stamp=self.clock.now())
        for item in self.screen.result(text):   # as over ROS: a malformed answer fails its call
            self._deliver(item)

    def send_call(self, call: FunctionCall) -> None:
        self.sent.append(call)
        self.screen.sent(call)
        server = self.servers.get(call.basic_mod)
        if server is not None:                               # else nobody listens, as on a robot
            server.handle_call(call.encode())
        if self.mocks.call_events:
            self._events_after(call)

    def _events_after(self, call: FunctionCall) -> None:
        """Schedule the events tied to this call (:meth:`Mocks.event_after`) on the run's clock, from
        now: an event at the call's answer time reaches the tree with the answer, before its next tick."""
        target = "%s.%s" % (call.basic_mod, call.function)
        n = self._made[target] = self._made.get(target, 0) + 1
        for after, nth, at, mod, name, params in self.mocks.call_events:
            server = self.servers.get(mod)
            if after == target and nth == n and server is not None:
                impl = server.impl
                assert isinstance(impl, MockModule)
                self.clock.call_later(at, lambda impl=impl, name=name, params=params: impl.emit(name, **params))

    def send_cancel(self, cancel: CancelRequest) -> None:
        self.sent.append(cancel)
        self.screen.ended([cancel.call_id])
        server = self.servers.get(cancel.basic_mod)
        if server is not None:
            server.handle_cancel(cancel.encode())

    def send_request(self, request: BlackboardRequest) -> None:
        self.sent.append(request)
        self.blackboard.on_request(request.encode())
