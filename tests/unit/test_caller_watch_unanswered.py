"""A module's watch over its callers with ``unreachable`` seconds: a caller that does not answer for that long
has its calls cancelled, saying why (against a stand-in node process stopped with SIGSTOP, which answers
nothing, as a machine cut off by a dropped link does); without it, or while the caller answers, nothing is.
The module node with real processes: ``tests/integration/test_unreachable_caller.py``."""
from __future__ import annotations

import argparse
import signal
import time

import pytest

from comm.liveness import ModuleLost, Watchdog
from modules.callers import unreachable_seconds
from tests.conftest import until
from tests.unit.xmlrpc_standin import StandIn


@pytest.fixture
def node(tmp_path):
    n = StandIn(tmp_path)
    n.start()
    yield n
    n.proc.send_signal(signal.SIGCONT)
    n.kill()


def _watching(node, unanswered):
    got = []
    uri = "http://127.0.0.1:%d/" % node.port
    dog = Watchdog(got.append, lambda key: key, lambda name: uri, period=0.1, ping_timeout=0.2,
                   unregistered_lost=False, unanswered=unanswered)
    dog.start()
    dog.call_sent("c1", "/bmtree_run")
    until(lambda: "/bmtree_run" in dog._known)
    return dog, got


def test_a_caller_that_stops_answering_is_lost_after_the_limit_saying_so(node):
    dog, got = _watching(node, 1.0)
    try:
        node.stop()
        stopped = time.monotonic()
        until(lambda: got, timeout=10.0)
        waited = time.monotonic() - stopped
    finally:
        dog.stop()
    lost, = got
    assert isinstance(lost, ModuleLost) and lost.call_ids == ["c1"] and lost.node == "/bmtree_run"
    assert lost.unanswered >= 1.0 and waited >= 1.0
    assert lost.reason.startswith("node /bmtree_run has not answered for ")
    assert lost.reason.endswith("(its machine cannot be reached, or its process is stopped)")


def test_a_caller_that_answers_over_its_kept_connection_is_asked_every_period_and_never_lost(node):
    dog, got = _watching(node, 1.0)
    try:
        asked = node.questions()
        until(lambda: node.questions() >= asked + 15)  # past the limit: asked, not taken as silent
        assert got == []
    finally:
        dog.stop()


def test_without_a_limit_a_silent_caller_is_not_lost(node):
    dog, got = _watching(node, 0.0)
    try:
        node.stop()
        time.sleep(1.5)   # what would be past a limit of 1 s
        assert got == []
    finally:
        dog.stop()


def test_a_caller_silent_for_a_while_then_answering_again_starts_the_count_again(node):
    dog, got = _watching(node, 1.5)
    try:
        for _ in range(3):   # silent for less than the limit, three times: never 1.5 s in a row
            node.stop()
            time.sleep(0.7)
            node.resume()
            resumed = time.monotonic()
            until(lambda t=resumed: dog._heard.get("/bmtree_run", 0.0) > t)  # an answer came back
        assert got == []
    finally:
        dog.stop()


@pytest.mark.parametrize("value, expected", [("0", 0.0), ("5", 5.0), (1, 1.0), ("2.5", 2.5)])
def test_unreachable_caller_values(value, expected):
    assert unreachable_seconds(value) == expected


@pytest.mark.parametrize("value, said", [("0.2", "expected 0 (never) or at least 1 seconds, got 0.2"),
                                         ("-1", "expected a finite number of seconds of 0 or more (0: never)"),
                                         ("soon", "expected a number of seconds, got 'soon'"),
                                         (True, "expected a number of seconds, got True")])
def test_bad_unreachable_caller_values_say_what_is_wrong(value, said):
    with pytest.raises(argparse.ArgumentTypeError) as err:
        unreachable_seconds(value)
    assert said in str(err.value)


def test_the_cancelled_answer_and_the_log_say_why():
    import logging

    from modules.callers import CallerWatch

    said = []
    handler = logging.Handler()
    handler.emit = lambda record: said.append(record.getMessage())
    logging.getLogger("bmtree.module").addHandler(handler)

    class Server:
        cancelled = {}

        def cancel(self, call_id, why=""):
            self.cancelled[call_id] = why
            return True

    server = Server()
    try:
        CallerWatch(server, "arm", 3.0).orphaned(ModuleLost(module="/bmtree_run", node="/bmtree_run", reason="…",
                                                            call_ids=["c1"], unanswered=3.4))
    finally:
        logging.getLogger("bmtree.module").removeHandler(handler)
    assert server.cancelled == {"c1": "its caller /bmtree_run has not answered for 3s (its machine cannot be reached, "
                                      "or its process is stopped), and module arm cancels a call when that lasts 3s "
                                      "(unreachable_caller)"}
    assert any("cancelled call c1 of module arm: its caller /bmtree_run has not answered for 3s" in text
               for text in said)
