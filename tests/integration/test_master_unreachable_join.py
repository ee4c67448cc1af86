"""``bmtree watch`` and ``bmtree control`` whose master answers their "is the master up?" check and
then nothing: stopped, or its machine dropped off the network, before they registered with it.

rospy retries a registration for as long as it runs, asking the master with no timeout: both
sat in ``rospy.init_node`` without a word, Ctrl-C included. A front answers the first ``getPid``
(the check) itself and passes everything after it to the test's own master, SIGSTOPped. Every
bound is against a hang, not a measure of speed.
"""
from __future__ import annotations

import contextlib
import os
import signal
import types
import xmlrpc.client

from tests.integration.test_master_unreachable import _ends, _finish, _start, _stopped
from tests.integration.test_master_unreachable_more import _xmlrpc


@contextlib.contextmanager
def _silent_after_check(graph):
    """A front of ``graph``'s master, stopped inside the block, that answers one ``getPid`` itself."""
    checked = []

    def dispatch(method, params):
        if method == "getPid" and not checked:
            checked.append(method)
            return [1, "", os.getpid()]
        return getattr(xmlrpc.client.ServerProxy(graph.uri), method)(*params)  # held while stopped

    with _xmlrpc(dispatch) as uri, _stopped(graph):
        yield types.SimpleNamespace(env=dict(graph.env, ROS_MASTER_URI=uri), uri=uri)


def test_watch_and_control_give_up_on_a_master_that_stops_answering_before_they_registered(own_graph):
    for tool, args in (("watch", ("--plain",)), ("control", ("pause",))):
        with _silent_after_check(own_graph) as front:
            proc, out = _start(front, tool, *args, "--wait", "3")
            try:
                code = _ends(proc, out, 3 + 15)
            finally:
                _finish(proc)
        text = out.all_text()
        assert code == 3, text
        assert ("the ROS master at %s stopped answering during start-up; waiting up to 3 s (--wait) for it to answer "
                "again ..." % front.uri) in text, text
        assert ("error: the ROS master at %s stopped answering while bmtree %s registered with it and did not answer "
                "again within 3 s (--wait)" % (front.uri, tool)) in text, text
        assert "Traceback" not in text, text


def test_ctrl_c_ends_a_watch_held_by_a_master_that_stopped_answering_before_it_registered(own_graph):
    with _silent_after_check(own_graph) as front:
        proc, out = _start(front, "watch", "--plain", "--wait", "60")
        try:
            out.wait_for("stopped answering during start-up; waiting up to 60 s (--wait)", 15)
            proc.send_signal(signal.SIGINT)
            code = _ends(proc, out, 10)
        finally:
            _finish(proc)
    text = out.all_text()
    assert code == 0, text  # as a watch that Ctrl-C ends later
    assert "Traceback" not in text, text
