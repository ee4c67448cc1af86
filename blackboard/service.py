"""The Blackboard's logic: store results, answer requests, acknowledge what is durable.

ROS callbacks only enqueue; one worker thread decodes, writes in batches and
answers, in arrival order, so a request that follows a result sees it.
"""
from __future__ import annotations

import json
import logging
import queue
import threading
import time
from collections import OrderedDict
from typing import Any, Callable, List, Optional, Set, Tuple

from blackboard.attribution import Attribution
from blackboard.store import Store, name_problem, rows_of
from comm.errors import ProtocolError
from comm.messages import DEFAULT_MAX_BYTES, BlackboardAnswer, BlackboardRequest, FunctionResult, load_payload
from comm.saylimit import SayLimit

__all__ = ["BlackboardService", "MAX_NAMES", "MAX_HISTORY"]

log = logging.getLogger("bmtree.blackboard")

_RESULT, _REQUEST, _STOP = 0, 1, 2

# Per request, far above what a robot's tree asks (a few names, a short history): more names are
# refused at once, with the limit named, before any value is read; a longer history is what the store
# keeps of a name (it holds no more). The answer is also bounded by
# ``max_bytes``: one that would not fit is answered by an error naming both sizes.
MAX_NAMES = 256       # distinct names (duplicates are answered once)
MAX_HISTORY = 1000    # values per name a history gives, when the store keeps every value (else what it keeps)


class BlackboardService:
    """Args:
        store: where values go.
        publish_answer: sends an encoded BlackboardAnswer.
        publish_ack: sends ``{"total": N, "call_ids": [...], "count": k}`` after each commit:
            the results named there are durable.
        prune_every: apply retention after this many stored values.
        attribution: tells the module, function and call of a result without call_id
            (an original module's) from the node that published it; without it such
            results are stored with the module and function they name, if any.
        after_wait: longest time a request naming calls in ``after`` waits for their results
            to be committed before it is answered with what is there.
    """

    def __init__(self, store: Store, publish_answer: Callable[[str], None],
                 publish_ack: Optional[Callable[[str], None]] = None, max_bytes: int = DEFAULT_MAX_BYTES,
                 prune_every: int = 2000, batch: int = 500, threaded: bool = True, after_wait: float = 2.0,
                 attribution: Optional[Attribution] = None):
        self.store = store
        self._publish_answer = publish_answer
        self._publish_ack = publish_ack
        self.max_bytes = max_bytes
        self.prune_every = prune_every
        self.batch = batch
        self.total = store.count()
        self.rejected = 0
        self._queue: queue.Queue = queue.Queue()
        self._since_prune = 0
        self._touched: Set[str] = set()
        self.threaded = threaded
        self.attribution = attribution
        self.after_wait = after_wait
        self._deferred: List[Tuple[float, BlackboardRequest]] = []
        self._bad_names = SayLimit()  # values refused for their names
        self._recent: OrderedDict = OrderedDict()  # call ids committed lately
        # Items received but not yet handled, and the store's lock: a request arriving when
        # nothing is pending is answered at once in the caller's thread (one hand-off less),
        # which keeps "a request that follows a result sees it".
        self._pending = 0
        self._pending_lock = threading.Lock()
        self._store_lock = threading.Lock()
        self._thread: Optional[threading.Thread] = None
        if threaded:
            self._thread = threading.Thread(target=self._work, name="blackboard-writer", daemon=True)
            self._thread.start()

    # called from any thread (threaded), or inline (threaded=False, for in-process runs)
    def on_result(self, text: Any, stamp: Optional[float] = None, publisher: Optional[str] = None) -> None:
        """A ``/function/output`` payload; ``publisher`` is the node that sent it (callerid)."""
        stamp = time.time() if stamp is None else stamp
        if not self.threaded:
            rows: List[tuple] = []
            ids: List[str] = []
            self._decode_result((text, publisher), stamp, rows, ids)
            self._commit(rows, ids)
            return
        self._enqueue((_RESULT, (text, publisher), stamp))

    def on_call(self, text: Any) -> None:
        """A ``/master/output`` payload: a call that a legacy result may answer."""
        if self.attribution is None:
            return
        try:
            self.attribution.on_call(load_payload(text, self.max_bytes))
        except ProtocolError as exc:
            log.debug("ignored a malformed call: %s", exc)

    def on_cancel(self, text: Any) -> None:
        """A ``/master/cancel`` payload: that call is answered by nobody any more."""
        if self.attribution is None:
            return
        try:
            call_id = load_payload(text, self.max_bytes).get("call_id")
        except ProtocolError as exc:
            log.debug("ignored a malformed cancel: %s", exc)
            return
        if isinstance(call_id, str):
            self.attribution.done(call_id)

    def on_request(self, text: Any) -> None:
        if not self.threaded:
            self._answer(text)
            return
        with self._store_lock:
            with self._pending_lock:
                idle = self._pending == 0
            if idle:
                self._answer(text)
                return
        self._enqueue((_REQUEST, text, time.time()))

    def _enqueue(self, item: tuple) -> None:
        with self._pending_lock:
            self._pending += 1
        self._queue.put(item)

    def stop(self, timeout: float = 5.0) -> None:
        if self._thread is not None:
            self._enqueue((_STOP, None, 0.0))
            self._thread.join(timeout)

    def flush(self, timeout: float = 5.0) -> bool:
        """Wait until everything queued so far is processed (tests, shutdown)."""
        if not self.threaded:
            return True
        done = threading.Event()
        self._enqueue((_REQUEST, done, 0.0))
        return done.wait(timeout)

    # worker
    def _work(self) -> None:
        while True:
            try:
                items = [self._queue.get(timeout=self._next_deadline())]
            except queue.Empty:
                with self._store_lock:
                    self._serve_deferred()
                continue
            while len(items) < self.batch:
                try:
                    items.append(self._queue.get_nowait())
                except queue.Empty:
                    break
            with self._store_lock:
                try:
                    stop = self._handle(items)
                except Exception as exc:  # last line of defence: the writer thread must live on
                    log.error("could not handle %d items (%s: %s)", len(items), type(exc).__name__, exc)
                    stop = any(kind == _STOP for kind, _, _ in items)
                with self._pending_lock:
                    self._pending -= len(items)
            if stop:
                return

    def _handle(self, items: List[tuple]) -> bool:
        """Store and answer one batch in arrival order; True at the stop marker."""
        rows: List[tuple] = []
        ids: List[str] = []
        for kind, payload, stamp in items:
            if kind == _RESULT:
                try:
                    self._decode_result(payload, stamp, rows, ids)
                except Exception as exc:  # one bad result must never cost the others of its batch
                    self.rejected += 1
                    log.warning("ignored a result that could not be handled (%s: %.200s): %.200r",
                                type(exc).__name__, exc, payload)
                continue
            self._commit(rows, ids)
            rows, ids = [], []
            if kind == _STOP:
                return True
            if isinstance(payload, threading.Event):
                payload.set()
            else:
                self._answer(payload)
        self._commit(rows, ids)
        if self._since_prune >= self.prune_every:
            self._prune()
        return False

    def _decode_result(self, item: Any, stamp: float, rows: List[tuple], ids: List[str]) -> None:
        """Decode one result (``text`` or ``(text, publisher)``) into rows to store."""
        text, publisher = item if isinstance(item, tuple) else (item, None)
        try:
            raw = load_payload(text, self.max_bytes)
            result = FunctionResult.from_obj(raw)
        except ProtocolError as exc:
            self.rejected += 1
            log.warning("ignored a malformed result: %s", exc)
            return
        except Exception as exc:  # nothing a sender writes may stop the writer thread
            self.rejected += 1
            log.warning("ignored a malformed result (%s: %s)", type(exc).__name__, exc)
            return
        module, function, call_id = result.basic_mod, result.function, result.call_id
        if self.attribution is not None:
            try:
                if call_id is not None:
                    self.attribution.done(call_id)
                elif module is None or function is None:
                    module, found, call_id = self.attribution.attribute(publisher, result.names, module)
                    function = function or found
            except Exception as exc:  # the result is stored all the same, with what it says itself
                log.warning("could not attribute a result of %s (%s: %.200s); storing it as it came", publisher,
                            type(exc).__name__, exc)
        if call_id is not None:
            ids.append(call_id)
        names, rostypes, texts = result.names, raw["rostypes"], raw["msgs"]
        bad = [i for i, name in enumerate(names) if name_problem(name)]
        if bad:  # refused alone: the result's other values, and the batch, are stored
            self.rejected += len(bad)
            more = self._bad_names.due("name")
            if more is not None:
                log.warning("refused %d value(s) of a result of %s.%s (call %s): %s, %.60r%s", len(bad), module,
                            function, call_id, name_problem(names[bad[0]]), names[bad[0]], more)
            keep = [i for i in range(len(names)) if i not in set(bad)]
            names, rostypes, texts = ([seq[i] for i in keep] for seq in (names, rostypes, texts))
        rows.extend(rows_of(names, rostypes, texts, module, function, call_id, stamp))

    def _commit(self, rows: List[tuple], ids: List[str]) -> None:
        if not rows and not ids:
            return
        try:
            n = self.store.add(rows)
        except Exception as exc:
            # One bad row must not cost its neighbours: store the batch row by row.
            log.warning("batch of %d values failed (%s: %s); storing them one by one", len(rows),
                        type(exc).__name__, exc)
            n, bad = self.store.add_each(rows)
            for row, err in bad:
                self.rejected += 1
                log.warning("could not store value %r of call %s: %s", row[0], row[5], err)
            bad_ids = {row[5] for row, _ in bad}
            ids = [i for i in ids if i not in bad_ids]
        self.total += n
        self._since_prune += n
        self._touched.update(r[0] for r in rows)
        for call_id in ids:
            self._recent[call_id] = None
        while len(self._recent) > 10000:
            self._recent.popitem(last=False)
        if self._deferred:
            self._serve_deferred()
        if self._publish_ack is not None:
            try:
                self._publish_ack(json.dumps({"total": self.total, "count": n, "call_ids": ids}))
            except Exception:
                log.exception("could not publish the storage acknowledgement")

    def _prune(self) -> None:
        try:
            removed = self.store.prune(self._touched)
        except Exception:
            log.exception("retention failed")
            return
        self.total -= removed
        self._touched.clear()
        self._since_prune = 0

    def _answer(self, text: Any) -> None:
        try:
            self._answer_one(text)
        except Exception as exc:  # a request must never stop the Blackboard
            self.rejected += 1
            log.warning("could not answer a request (%s: %s)", type(exc).__name__, exc)

    def _answer_one(self, text: Any) -> None:
        try:
            req = BlackboardRequest.decode(text, self.max_bytes)
        except ProtocolError as exc:
            self.rejected += 1
            log.warning("malformed request: %s", exc)
            request_id = None
            try:
                rid = load_payload(text, self.max_bytes).get("request_id")
                request_id = rid if isinstance(rid, str) else None
            except ProtocolError:
                pass
            if request_id is not None:
                self._publish_answer(BlackboardAnswer.encode_raw([], [], [], request_id, [], "bad request: %s" % exc))
            return
        refused = self._bound(req)
        if refused:
            self.rejected += 1
            log.warning("refused a request: %s", refused)
            self._refuse(req, "bad request: %s" % refused)
            return
        if req.after and self.threaded and not self._all_stored(req.after):
            # The results this request must see are still on their way (they travel on
            # another connection than the request): answer once they are committed.
            self._deferred.append((time.monotonic() + self.after_wait, req))
            self._enqueue((_REQUEST, threading.Event(), 0.0))  # wakes the worker to set its timer
            return
        self._reply(req)

    def _bound(self, req: BlackboardRequest) -> str:
        """Dedupe ``req.var_names`` (keeping order); why ``req`` is refused, or ``''``."""
        req.var_names = list(OrderedDict.fromkeys(req.var_names))
        if len(req.var_names) > MAX_NAMES:
            return "%d distinct names asked (at most %d per request)" % (len(req.var_names), MAX_NAMES)
        keep = getattr(self.store, "keep", 0) or 0
        most = keep if keep > 0 else MAX_HISTORY
        if req.history > most:   # the store never holds more of a name: "all you have", answered as such
            req.history = most
        return ""

    def _refuse(self, req: BlackboardRequest, error: str) -> None:
        """Answer ``req`` by ``error`` alone (no names, nothing missing: it was not answered)."""
        self._publish_answer(BlackboardAnswer.encode_raw([], [], [], req.request_id, [], error))

    def _too_large(self, req: BlackboardRequest, size: int, exact: bool) -> None:
        self.rejected += 1
        error = ("answer too large: %s%d bytes, over the limit of %d bytes (--max-bytes); ask for fewer names "
                 "or a shorter history" % ("" if exact else "at least ", size, self.max_bytes))
        log.warning("did not send the answer to request %s: %s", req.request_id, error)
        self._refuse(req, error)

    def _all_stored(self, call_ids: List[str]) -> bool:
        return all(c in self._recent or self.store.has_call(c) for c in call_ids)

    def _next_deadline(self) -> Optional[float]:
        if not self._deferred:
            return None
        return max(0.0, min(d for d, _ in self._deferred) - time.monotonic())

    def _serve_deferred(self) -> None:
        """Answer the waiting requests whose results are committed, or whose wait is over."""
        now = time.monotonic()
        waiting = []
        for deadline, req in self._deferred:
            if now >= deadline or self._all_stored(req.after):
                try:
                    self._reply(req)
                except Exception as exc:
                    log.warning("could not answer a request (%s: %s)", type(exc).__name__, exc)
            else:
                waiting.append((deadline, req))
        self._deferred = waiting

    def _reply(self, req: BlackboardRequest) -> None:
        names: List[str] = []
        types: List[str] = []
        texts: List[str] = []
        sources: List[dict] = []
        missing: List[str] = []
        errors: List[str] = []
        found = []
        size = 0  # a lower bound of the answer's encoded size: stop reading as soon as it cannot fit
        if req.call_id is not None:
            found.extend(self.store.by_call(req.call_id))
            size += sum(len(v.msg) + len(v.name) + len(v.rostype) for v in found)
            if not found and not req.var_names:
                missing.append(req.call_id)
        for name in req.var_names:
            if size > self.max_bytes:
                self._too_large(req, size, False)
                return
            try:
                values = self.store.latest(name, req.history)
            except ValueError as exc:
                errors.append(str(exc))
                missing.append(name)
                continue
            if not values:
                missing.append(name)
            for v in values:
                v.name = name
                size += len(v.msg) + len(name) + len(v.rostype)
            found.extend(values)
        if size > self.max_bytes:
            self._too_large(req, size, False)
            return
        for v in found:
            names.append(v.name)
            types.append(v.rostype)
            texts.append(v.msg)
            sources.append(v.source)
        unstored = [c for c in req.after if not self._all_stored([c])]
        text = BlackboardAnswer.encode_raw(names, types, texts, req.request_id, missing, "; ".join(errors), sources,
                                           unstored)
        encoded = len(text.encode("utf-8"))
        if encoded > self.max_bytes:
            self._too_large(req, encoded, True)
            return
        self._publish_answer(text)
