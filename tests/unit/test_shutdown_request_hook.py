"""Interrupts' hook for a shutdown of rospy begun in another thread (``rosnode kill``): the main thread
stops as on SIGINT, the hook holds rospy's shutdown until the process leaves (bounded); and what
``bmtree run`` says of it. The hook is called directly here: no rospy node in this process."""
from __future__ import annotations

import threading
import time

import pytest

from comm.nodelife import Interrupts
from coordinator.runcmd import interrupted_line, shutdown_notice

REASON = "external shutdown request from [/caller]: [rosnode kill]"


def _request(interrupts, start=True):
    """The hook, run as rospy's XML-RPC thread runs it; the thread and how long the hook took."""
    took = []

    def run():
        begun = time.monotonic()
        interrupts._on_shutdown_request(REASON)
        took.append(time.monotonic() - begun)
    thread = threading.Thread(target=run, daemon=True)
    if start:
        thread.start()
    return thread, took


def _wait_interrupted(seconds=5.0):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        time.sleep(0.01)


def test_a_request_stops_the_main_thread_and_is_held_until_the_process_leaves():
    interrupts = Interrupts()
    told = []
    try:
        interrupts._bound, interrupts._told = (lambda: 10.0), told.append
        thread, took = _request(interrupts, start=False)
        with pytest.raises(KeyboardInterrupt):
            thread.start()
            _wait_interrupted()
        assert told == [REASON] and interrupts.shutdown_request == REASON
        assert interrupts.last_signal is not None   # as a signal: a second one cuts the cleanup short
        time.sleep(0.2)
        assert thread.is_alive()                    # held: rospy's topics stay open
        interrupts.leaving()
        assert interrupts.request_answered(2.0) and took[0] < 2.0
    finally:
        interrupts.restore()


def test_a_request_is_bounded_and_does_not_stop_a_process_that_is_stopping_or_done():
    interrupts = Interrupts()
    try:
        interrupts._bound = lambda: 0.3
        interrupts.done()                # the run ended by itself: only the leave is waited for
        thread, took = _request(interrupts)
        thread.join(5)
        assert not thread.is_alive() and 0.25 < took[0] < 2.0
        assert interrupts.shutdown_request == REASON
        interrupts.leaving()             # the process's own shutdown, from its leave thread: not held
        thread, took = _request(interrupts)
        thread.join(5)
        assert took[0] < 0.2
    finally:
        interrupts.restore()


def test_a_request_from_the_main_thread_is_not_held():
    interrupts = Interrupts()
    try:
        interrupts._bound = lambda: 10.0
        start = time.monotonic()
        interrupts._on_shutdown_request(REASON)   # rospy shut down from the main thread: it would wait for itself
        assert time.monotonic() - start < 0.5
    finally:
        interrupts.restore()


def test_what_the_run_says_of_a_shutdown_request():
    assert shutdown_notice("/bmtree_1_2", REASON) == (
        "this run's node /bmtree_1_2 was asked to shut down (rosnode kill?): external shutdown request from "
        "[/caller]: [rosnode kill]; stopping the run as Ctrl-C does")
    kicked = "external shutdown request from [/master]: [[/bmtree_1_2] Reason: new node registered with same name]"
    assert shutdown_notice("/bmtree_1_2", kicked).startswith(
        "another node registered with this run's node name /bmtree_1_2, so the ROS master shut it down: ")
    assert interrupted_line(None, False, REASON) == (
        "interrupted during start-up by a shutdown request of its node (%s): nothing was called" % REASON)
    assert interrupted_line(None, False) == "interrupted during start-up: nothing was called"
