"""More commands against a master that does not answer (see test_master_unreachable.py):
``bmtree modules --live`` and ``bmtree control``, and what a run says of a Blackboard node that is
registered but does not answer from here.

A master stopped before a command starts is caught by the command's bounded "is the master up?"
check (``coordinator.cliutil.master_up``), old code included. What hung was a master that answered
that check and then nothing: stopped, or its machine dropped off the network, between two questions.
Here a front answers the check (``getPid``) itself and passes every other question to the test's
own master, SIGSTOPped meanwhile; ``bmtree control`` gets its master stopped once it has registered.
Every bound is against a hang, not a measure of speed.
"""
from __future__ import annotations

import contextlib
import os
import threading
import time
import types
import xmlrpc.client
from socketserver import ThreadingMixIn
from xmlrpc.server import SimpleXMLRPCServer

from comm.address import REFUSED
from comm.rpc import master_api
from tests.integration.test_master_unreachable import _ends, _finish, _start, _stopped


class _Server(ThreadingMixIn, SimpleXMLRPCServer):
    daemon_threads = True
    block_on_close = False  # a question held by the stopped master is not waited for


@contextlib.contextmanager
def _xmlrpc(dispatch):
    """An XML-RPC server on 127.0.0.1 answering with ``dispatch(method, params)``; its URI."""
    server = _Server(("127.0.0.1", 0), logRequests=False, allow_none=True)
    server.register_instance(types.SimpleNamespace(_dispatch=dispatch))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield "http://127.0.0.1:%d/" % server.server_address[1]
    finally:
        server.shutdown()
        server.server_close()


@contextlib.contextmanager
def _checked_then_silent(graph):
    """A front of ``graph``'s master that answers ``getPid`` itself and passes on the rest, with
    that master stopped inside the block: a master that answers the check and nothing after. The
    environment to give a command."""

    def dispatch(method, params):
        if method == "getPid":
            return [1, "", os.getpid()]
        return getattr(xmlrpc.client.ServerProxy(graph.uri), method)(*params)  # held while stopped

    with _xmlrpc(dispatch) as uri, _stopped(graph):  # continued (SIGCONT) before the front closes
        yield types.SimpleNamespace(env=dict(graph.env, ROS_MASTER_URI=uri), uri=uri)


def _registered(graph, prefix, topic, timeout):
    """Wait until a node whose name starts with ``prefix`` publishes ``topic`` on the master."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        pubs, _, _ = master_api("/test_more", 1.0, graph.uri).getSystemState()
        if any(n.startswith(prefix) for t, nodes in pubs if t == topic for n in nodes):
            return
        time.sleep(0.02)
    raise AssertionError("no node %s* publishes %s after %g s" % (prefix, topic, timeout))


def test_modules_live_ends_when_the_master_answers_its_check_and_then_nothing(own_graph):
    with _checked_then_silent(own_graph) as front:
        proc, out = _start(front, "modules", "--live", "--wait", "2")
        try:
            code = _ends(proc, out, 2 + 20)
        finally:
            _finish(proc)
    text = out.all_text()
    assert code == 3, text
    assert ("error: the ROS master at %s did not answer within 3 s (is its process stopped, or its machine off "
            "the network?)" % front.uri) in text, text
    assert "Traceback" not in text, text


SILENT_RUN = ("import rospy; from std_msgs.msg import String; rospy.init_node('silent_run'); "
              "rospy.Subscriber('/bmtree/run/control_request', String, lambda m: None); rospy.spin()")


def test_control_leaves_without_unregistering_when_the_master_stops_meanwhile(own_graph):
    """A run that never answers ``pause`` (a node that takes requests and says nothing); the master
    stops while control waits for its answer: control's exit does not wait for the master to take its
    unregistering."""
    import sys

    from coordinator.control import REQUEST

    own_graph.start_node([sys.executable, "-c", SILENT_RUN], "/silent_run")
    ctl, out = _start(own_graph, "control", "pause", "--wait", "2")
    try:
        _registered(own_graph, "/bmtree_control", REQUEST, 20)  # it waits for a run's answer now
        with _stopped(own_graph):
            code = _ends(ctl, out, 2 + 20)
    finally:
        _finish(ctl)
    text = out.all_text()
    assert code == 3 and "refused: no run answered" in text, text
    assert ("the ROS master at %s does not answer: leaving without unregistering" % own_graph.uri) in text, text
    assert "Traceback" not in text, text


def test_a_registered_blackboard_node_that_does_not_answer_is_named_not_missing(monkeypatch):
    """No ROS: a fake master registers a Blackboard node at a URI where nothing listens (refused:
    its process is gone) or that does not answer (timed out: its address); none at all says nothing.
    (The run's preflight puts this text in place of "the Blackboard node is not running or not
    connected" when no Blackboard node answers; that step needs a run and is not tested here.)"""
    from blackboard.client import blackboard_listeners, blackboard_nodes, silent_blackboards
    from comm import TOPIC_BB_REQUEST, TOPIC_CALL

    with _xmlrpc(lambda method, params: [1, "", os.getpid()]) as nothing_there:
        pass  # closed: its port refuses now
    registered = {"/blackboard": nothing_there}

    def master(method, params):
        if method == "getSystemState":
            subs = [[TOPIC_BB_REQUEST, sorted(registered)], [TOPIC_CALL, sorted(registered) + ["/other"]]]
            return [1, "", [[], subs, []]]
        if method == "lookupNode":
            return [1, "", registered[params[1]]]
        return [-1, "unexpected %s" % method, 0]

    with _xmlrpc(master) as uri:
        monkeypatch.setenv("ROS_MASTER_URI", uri)
        live, silent = blackboard_nodes()
        assert blackboard_listeners() == []
    assert live == [] and silent == {"/blackboard": (nothing_there, REFUSED)}
    assert silent_blackboards(silent, uri) == (
        "the Blackboard node /blackboard is registered but does not answer from here: nothing listens at %s, so its "
        "process is gone (killed outright, its registration left behind): start it again (bmtree-blackboard, or "
        "roslaunch bmtree blackboard.launch)" % nothing_there)
    far = "http://192.0.2.7:40000/"  # TEST-NET: not this machine's
    assert silent_blackboards({"/blackboard": (far, "timed out")}, "http://192.0.2.1:11311/") == (
        "the Blackboard node /blackboard is registered but cannot be reached: node /blackboard registered "
        "%s, which does not answer from here (timed out): a wrong ROS_IP on the machine that runs it (or is that "
        "machine off the network)?" % far)
    assert silent_blackboards({}) == ""
