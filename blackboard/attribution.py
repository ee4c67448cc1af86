"""Which module and call a result without ``call_id`` (an original module's) came from.

The Blackboard applies the coordinator's rule (README "Correlation"): the result belongs
to the module whose node published it; within that module it answers the oldest pending
call whose function's output names equal the result's names. It learns

- the pending calls by listening to ``/master/output`` and ``/master/cancel`` (every
  coordinator's calls, with module, function and call id);
- node -> module, and each function's output names, from the announcements on the
  parameter server (``/bmtree/modules/<module>``: bmtree modules announce themselves,
  and ``bmtree run`` announces the original modules it found or was told about with
  ``--legacy``), and, failing that, from the original convention: a node named
  ``/<module>`` is that module.

Thread-safe: calls arrive in rospy's threads, results in the writer thread.
"""
from __future__ import annotations

import json
import logging
import threading
import time
from collections import deque
from typing import Any, Callable, Deque, Dict, List, Mapping, Optional, Sequence, Tuple

__all__ = ["Attribution"]

log = logging.getLogger("bmtree.blackboard")

_MAX_PENDING = 200        # per module: calls nobody answered are forgotten oldest first
_REFRESH_EVERY = 1.0      # seconds between two reads of the announcements
_CALL_GRACE = 0.2         # a result may overtake its call (another connection): wait this long for it


class Attribution:
    """Args:
        announcements: returns ``{module: {"node": ..., "definition": JSON text}}`` (the
            parameter server's ``/bmtree/modules``), or raises OSError.
    """

    def __init__(self, announcements: Callable[[], Mapping[str, Any]]):
        self._announcements = announcements
        self._lock = threading.Lock()
        self._new_call = threading.Condition(self._lock)
        self._pending: Dict[str, Deque[Tuple[str, str]]] = {}   # module -> (call_id, function), oldest first
        self._nodes: Dict[str, str] = {}                        # node -> module
        self._outputs: Dict[str, Dict[str, List[str]]] = {}      # module -> function -> output names
        self._refreshed = 0.0

    # calls -------------------------------------------------------------------------
    def on_call(self, payload: Mapping[str, Any]) -> None:
        module, function, call_id = payload.get("basic_mod"), payload.get("function"), payload.get("call_id")
        if not (isinstance(module, str) and isinstance(function, str) and isinstance(call_id, str)):
            return
        with self._lock:
            self._pending.setdefault(module, deque(maxlen=_MAX_PENDING)).append((call_id, function))
            self._new_call.notify_all()

    def done(self, call_id: str) -> None:
        """The call was answered (with its id) or cancelled: no legacy result answers it."""
        with self._lock:
            for calls in self._pending.values():
                for item in calls:
                    if item[0] == call_id:
                        calls.remove(item)
                        return

    # results -----------------------------------------------------------------------
    def attribute(self, publisher: Optional[str], names: Sequence[str],
                  module: Optional[str] = None) -> Tuple[Optional[str], Optional[str], Optional[str]]:
        """(module, function, call_id) of a result without call_id; None where unknown."""
        if module is None and publisher:
            module = self._module_of(publisher)
        if module is None:
            return None, None, None
        self._refresh_if_unknown(module)
        end = time.monotonic() + _CALL_GRACE
        with self._lock:
            outputs = self._outputs.get(module, {})
            while True:
                for item in self._pending.get(module, ()):
                    if sorted(outputs.get(item[1], [None])) == sorted(names):
                        self._pending[module].remove(item)
                        return module, item[1], item[0]
                left = end - time.monotonic()
                if left <= 0 or not outputs:
                    break
                self._new_call.wait(left)  # the call may still be on its way (results overtake calls)
            matching = [f for f, outs in outputs.items() if sorted(outs) == sorted(names)]
        return module, matching[0] if len(matching) == 1 else None, None

    def _module_of(self, node: str) -> Optional[str]:
        with self._lock:
            module = self._nodes.get(node)
        if module is None:
            self._refresh()
            with self._lock:
                module = self._nodes.get(node)
                if module is None and node.rsplit("/", 1)[-1] in self._pending:
                    module = node.rsplit("/", 1)[-1]      # the original convention: node /<module>
        return module

    def _refresh_if_unknown(self, module: str) -> None:
        with self._lock:
            known = module in self._outputs
        if not known:
            self._refresh()

    def _refresh(self) -> None:
        now = time.monotonic()
        with self._lock:
            if now - self._refreshed < _REFRESH_EVERY:
                return
            self._refreshed = now
        try:
            entries = self._announcements() or {}
        except Exception as exc:  # OSError, ValueError, or anything an odd master answer raises
            log.warning("cannot read the module announcements (%s: %.200s)", type(exc).__name__, exc)
            return
        nodes: Dict[str, str] = {}
        outputs: Dict[str, Dict[str, List[str]]] = {}
        try:
            items = list(entries.items()) if isinstance(entries, Mapping) else []
        except Exception as exc:  # whatever the parameter server holds, results go on being stored
            log.warning("ignored the malformed module announcements (%s: %s)", type(exc).__name__, exc)
            items = []
        for module, entry in items:
            # one malformed announcement (even one nested too deep to decode: RecursionError) is
            # skipped alone: it must never cost the others, nor the results being attributed
            try:
                if not isinstance(entry, Mapping) or not isinstance(entry.get("node"), str):
                    continue
                nodes[entry["node"]] = module
                functions = json.loads(entry.get("definition", ""))["Functions"]
                outputs[module] = {f["Name"]: [p["Name"] for p in f["Output-params"]] for f in functions}
            except Exception as exc:
                log.warning("ignored the malformed announcement of module %.80r (%s: %.200s)", module,
                            type(exc).__name__, exc)
        with self._lock:
            self._nodes.update(nodes)
            self._outputs.update(outputs)
