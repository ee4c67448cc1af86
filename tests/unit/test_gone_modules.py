"""A module known to be gone ends what waits on it (no ROS master): a ``wait_event`` whose module's
node is gone fails with the reason and a notice; the watchdog finds a module whose node stopped
cleanly (no announcement, not registered) at its last address; a call to an original module whose
node is not connected to ``/master/output`` ends at once instead of being dropped by ROS."""
from __future__ import annotations

import os
import socket

from std_msgs.msg import String

from comm.liveness import ModuleLost
from comm.messages import Event
from coordinator import rosliveness
from coordinator.builder import build_tree
from coordinator.clock import SimClock
from coordinator.context import MODULE_GONE, RunContext, gone_text
from coordinator.language import load_tree
from coordinator.ros_transport import WATCH_PREFIX, RosTransport
from modules.definition import load_definition
from tests.conftest import ROOT
from tests.unit.test_faults import _Sent

PROBE = load_definition(os.path.join(ROOT, "tests", "integration", "nodes", "probe.json"))


class _Watching(_Sent):
    """Records what is sent and which modules are watched, as the ROS transport would watch them."""

    def __init__(self):
        super().__init__()
        self.watched = {}  # key -> module, while watched
        self.unwatched = []

    def watch_module(self, module):
        key = "%s%d" % (WATCH_PREFIX, len(self.watched) + len(self.unwatched))
        self.watched[key] = module
        return key

    def unwatch_module(self, key):
        self.watched.pop(key)
        self.unwatched.append(key)


def _tree(tmp_path, text, transport=None):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n" + text)
    ctx = RunContext(transport if transport is not None else _Watching(), SimClock(), {"probe": PROBE})
    return ctx, build_tree(load_tree(str(path), {"probe": PROBE}), ctx, {})


def _done(tag="x"):
    return Event(basic_mod="probe", event="done", names=["tag"], msgs=[String(tag)])


def test_a_wait_event_whose_module_is_lost_fails_with_the_reason_and_a_notice(tmp_path):
    ctx, root = _tree(tmp_path, "  wait_event: probe.done\n")
    root.tick_once()
    assert root.status.value == "RUNNING" and list(ctx.transport.watched.values()) == ["probe"]
    key = next(iter(ctx.transport.watched))
    ctx.dispatch(ModuleLost(module="probe", node="/bm_probe", reason="node /bm_probe stopped (its process is gone)",
                            call_ids=[key]))
    root.tick_once()
    assert root.status.value == "FAILURE"
    assert root.feedback_message == ("probe's node is gone (node /bm_probe stopped (its process is gone)): no "
                                     "probe.done event can come")
    assert [n.what for n in ctx.notices] == [MODULE_GONE]
    assert ctx.notices[0].text.endswith("no probe.done event can come; the wait_event for it fails")
    assert ctx.transport.unwatched == [key] and not ctx.transport.watched


def test_an_event_that_came_before_the_loss_is_still_taken(tmp_path):
    ctx, root = _tree(tmp_path, "  wait_event: probe.done\n  outputs: {tag: said}\n")
    root.tick_once()
    key = next(iter(ctx.transport.watched))
    ctx.dispatch(_done("last words"))
    ctx.dispatch(ModuleLost(module="probe", node="/bm_probe", reason="gone", call_ids=[key]))
    root.tick_once()
    assert root.status.value == "SUCCESS" and ctx.blackboard["said"].data == "last words"
    assert not ctx.transport.watched


def test_a_halted_wait_stops_watching_and_a_later_loss_tells_nothing(tmp_path):
    ctx, root = _tree(tmp_path, "  parallel:\n    - wait_event: probe.done\n    - fail: enough\n")
    root.tick_once()
    assert root.status.value == "FAILURE" and not ctx.transport.watched and len(ctx.transport.unwatched) == 1
    ctx.dispatch(ModuleLost(module="probe", node="/bm_probe", reason="gone", call_ids=ctx.transport.unwatched))
    assert not ctx.notices


def test_a_wait_started_again_watches_again(tmp_path):
    ctx, root = _tree(tmp_path, "  repeat: 2\n  child: {wait_event: probe.done}\n")
    root.tick_once()
    ctx.dispatch(_done())
    root.tick_once()
    root.tick_once()
    assert len(ctx.transport.unwatched) == 1 and len(ctx.transport.watched) == 1  # the second wait's
    key = next(iter(ctx.transport.watched))
    ctx.dispatch(ModuleLost(module="probe", node="/bm_probe", reason="node /bm_probe is not registered with the "
                            "master", call_ids=[key]))
    root.tick_once()
    assert root.status.value == "FAILURE"


def test_without_a_watching_transport_the_wait_goes_on(tmp_path):
    class _Plain(_Watching):
        def watch_module(self, module):  # the in-process transport's (Transport's default): mocks do not die
            return None

    ctx, root = _tree(tmp_path, "  wait_event: probe.done\n", _Plain())
    root.tick_once()
    ctx.dispatch(ModuleLost(module="probe", node="/bm_probe", reason="gone", call_ids=["id"]))
    root.tick_once()
    assert root.status.value == "RUNNING" and not ctx.notices


def test_a_restarted_node_is_said_so():
    text = gone_text("hotword", "node /hotword was restarted (pid 9, was 8)", ["hotword.heard"])
    assert text == "hotword's node was restarted (node /hotword was restarted (pid 9, was 8)): a hotword.heard " \
                   "event may have been lost meanwhile"


def test_a_module_whose_node_left_no_trace_is_found_where_it_was_seen(monkeypatch):
    """A node stopped cleanly removes its announcement and unregisters: the master knows nothing of it."""
    monkeypatch.setattr(rosliveness, "node_of", lambda module: None)
    monkeypatch.setattr(rosliveness, "uri_of", lambda node: None)
    places = rosliveness.Whereabouts(lambda module: "/legacy_node" if module == "legacy" else None)
    places.seen("probe", "/bm_probe", "http://127.0.0.1:4711/")
    assert places.node_of("probe") == "/bm_probe" and places.uri_of("/bm_probe") == "http://127.0.0.1:4711/"
    assert places.node_of("legacy") == "/legacy_node" and places.uri_of("/legacy_node") is None
    assert places.node_of("never") is None and places.known("probe") == "/bm_probe"
    assert places.node_of(rosliveness.BLACKBOARD) is None
    monkeypatch.setattr(rosliveness, "node_of", lambda module: "/bm_probe2")  # announced by its next node
    monkeypatch.setattr(rosliveness, "uri_of", lambda node: "http://127.0.0.1:4712/")
    assert places.node_of("probe") == "/bm_probe2" and places.uri_of("/bm_probe2") == "http://127.0.0.1:4712/"


class _Conn:
    def __init__(self, node, sock):
        self.endpoint_id, self.socket, self.done = node, sock, False


class _Shared:
    resolved_name = "/master/output"

    def __init__(self, conns):
        self.impl = type("Impl", (), {"connections": conns})()
        self.published = []

    def publish(self, msg):
        self.published.append(msg)


def test_a_call_to_an_original_module_whose_node_is_not_connected_ends_at_once():
    """ROS drops a message for a subscriber that is not connected (or whose process died: its connection
    stays until a write fails): the call would wait for nothing, with ``timeout: none`` for ever."""
    transport = RosTransport(liveness=0)
    got = []
    transport._deliver = got.append
    transport._String = String
    ours, theirs = socket.socketpair()
    shared = transport._pubs["call"] = _Shared([_Conn("/PYTHON_BM", ours), _Conn("/other", None)])
    transport.node_modules = {"/PYTHON_BM": "PYTHON_BM"}
    call = PROBE.function("echo").build_call({"tag": "x"})
    call.basic_mod = "PYTHON_BM"
    transport.send_call(call)
    assert len(shared.published) == 1 and not got and transport.watchdog.owes(call.call_id)
    theirs.close()  # its process died
    again = PROBE.function("echo").build_call({"tag": "y"})
    again.basic_mod = "PYTHON_BM"
    transport.send_call(again)
    assert len(shared.published) == 1 and not transport.watchdog.owes(again.call_id)
    assert len(got) == 1 and isinstance(got[0], ModuleLost) and got[0].call_ids == [again.call_id]
    assert got[0].reason == "node /PYTHON_BM is not connected to /master/output (gone, or restarting): the call " \
                            "was not sent"
    ctx = RunContext(transport, SimClock(), {"probe": PROBE})
    rec = ctx.start_call(PROBE.function("echo"), again)
    ctx.dispatch(got[0])
    assert rec.status == "module_lost" and rec.error.startswith("module PYTHON_BM lost: node /PYTHON_BM is not")
    ours.close()
    unknown = PROBE.function("echo").build_call({"tag": "z"})  # a module the run knows no node of: sent
    transport.send_call(unknown)
    assert len(shared.published) == 2


def test_a_watched_module_is_owed_until_unwatched():
    transport = RosTransport(liveness=0)
    key = transport.watch_module("hotword")
    assert key.startswith(WATCH_PREFIX) and transport.watchdog.owes(key)
    transport.unwatch_module(key)
    assert not transport.watchdog.owes(key)
