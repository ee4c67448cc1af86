"""Addressed calls without ROS: cheap refusal, run-once, pings, announcements, routing."""
from __future__ import annotations

import copy
import json
import random
import threading

from std_msgs.msg import String

from bench.scale import definition as scale_definition
from bench.scale import echo_module
from comm import CancelRequest, FunctionCall, FunctionResult
from comm.addressing import (
    PING_FUNCTION,
    RecentIds,
    call_topic,
    cancel_on_call_topic,
    cancel_topic,
    surely_not_for,
    valid_topic,
)
from modules.definition import _VALIDATOR, _surely_valid, parse_definition
from modules.execution import Executor
from modules.node import CallInbox
from modules.runtime import ModuleServer


def _call(module="scale00", function="f00", text="hi", call_id="c1"):
    return FunctionCall(module, function, [String(text)], names=["text"], call_id=call_id)


def test_topics_of_a_module():
    assert call_topic("navigation") == "/bmtree/call/navigation"
    assert cancel_topic("navigation") == "/bmtree/cancel/navigation"
    assert valid_topic("/bmtree/call/navigation") and valid_topic("/robot1/bmtree/call/x_1")
    for bad in ("/master/output", "/function/output", "bmtree/call/x", "/a b", "/1x", "", None, 3, "/" + "a" * 300):
        assert not valid_topic(bad), bad


def test_a_call_for_another_module_is_refused_without_parsing():
    text = _call("vision", text='{"basic_mod": "navigation"}').encode()
    assert surely_not_for(text, "navigation")  # the name inside a value is escaped: not a key's value
    assert not surely_not_for(text, "vision")
    assert surely_not_for("{not json at all", "navigation")  # not ours, whatever it is
    # a name disguised with \u escapes, or anything that is not text, goes to the full decoder
    assert not surely_not_for('{"basic_mod": "n\\u0061vigation"}', "navigation")
    assert not surely_not_for(b'{"basic_mod": "vision"}', "navigation")
    assert not surely_not_for(text, "odd-name")


def test_recent_ids_are_bounded():
    ids = RecentIds(size=3)
    assert ids.first("a") and not ids.first("a")
    assert ids.first(None) and ids.first(None)
    for x in "bcd":
        assert ids.first(x)
    assert len(ids) == 3 and ids.first("a")  # forgotten: memory stays bounded


class _Inline(Executor):
    """Runs each call in the thread that took it, so a test knows when every run has ended."""

    def submit(self, fn, *args):
        fn(*args)


class _Inbox:
    def __init__(self, run_real=False):
        self.calls, self.cancels, self.results = [], [], []
        if run_real:
            d = parse_definition(scale_definition(0))
            self.server = ModuleServer(d, echo_module(list(d.functions)), self.results.append, lambda t: None,
                                       executor=_Inline())
            self.inbox = CallInbox("scale00", self.server.handle_call, self.server.handle_cancel, self.results.append)
        else:
            self.inbox = CallInbox("scale00", self.calls.append, self.cancels.append, self.results.append)


def test_inbox_hands_over_only_calls_for_its_module_once_each():
    t = _Inbox()
    mine, other = _call().encode(), _call("scale01").encode()
    for text in (mine, other, mine, other):
        t.inbox.handle_call(text)  # as if it came on /master/output and on /bmtree/call/scale00
    assert t.calls == [mine] and t.inbox.skipped == 2 and t.inbox.duplicates == 1
    legacy = json.dumps({"basic_mod": "scale00", "function": "f00", "msgs": [], "rostypes": []})
    t.inbox.handle_call(legacy)
    t.inbox.handle_call(legacy)  # no call_id: the original protocol, every one runs
    assert t.calls == [mine, legacy, legacy]
    t.inbox.handle_call("{broken")  # not ours for sure: skipped
    t.inbox.handle_call('{"basic_mod": "scale00", ')  # maybe ours: the runtime reports it
    assert t.calls[-1] == '{"basic_mod": "scale00", '
    cancel = CancelRequest("c1", "scale00", "f00").encode()
    t.inbox.handle_cancel(cancel)
    t.inbox.handle_cancel(CancelRequest("c1", "scale01", "f00").encode())
    on_call_topic = cancel_on_call_topic("c1", "scale00", "f00")
    t.inbox.handle_call(on_call_topic)  # a cancel that travelled behind its call
    t.inbox.handle_call(cancel_on_call_topic("c1", "scale01", "f00"))
    assert t.cancels == [cancel, on_call_topic] and t.results == []
    assert CancelRequest.decode(on_call_topic) == CancelRequest("c1", "scale00", "f00")


def test_inbox_answers_pings_itself():
    t = _Inbox()
    t.inbox.handle_call(FunctionCall("scale00", PING_FUNCTION, [], names=[], call_id="p1").encode())
    t.inbox.handle_call(FunctionCall("scale01", PING_FUNCTION, [], names=[], call_id="p2").encode())
    assert t.calls == []
    [answer] = [FunctionResult.decode(r) for r in t.results]
    assert (answer.call_id, answer.basic_mod, answer.function, answer.status) == ("p1", "scale00", PING_FUNCTION,
                                                                                  "succeeded")


def test_a_call_on_both_topics_runs_once_in_the_real_runtime():
    t = _Inbox(run_real=True)
    text = _call(call_id="twice").encode()
    threads = [threading.Thread(target=t.inbox.handle_call, args=(text,)) for _ in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    answers = [FunctionResult.decode(r) for r in t.results]
    assert [(a.call_id, a.status, a.values["text"].data) for a in answers] == [("twice", "succeeded", "hi")]


def test_fast_definition_check_never_accepts_what_the_schema_refuses():
    base = scale_definition(0)
    base["Events"] = [{"Name": "e", "Description": "", "Event-params": [dict(base["Functions"][0]["Input-params"][0])]}]
    assert _surely_valid(base) and not list(_VALIDATOR.iter_errors(base))
    rnd = random.Random(18)
    values = [None, 1, 1.5, True, "x", "9bad", "ok\n", [], {}, ["a"], [{}], {"Name": "a"}]

    def paths(o, pre=()):
        yield pre
        items = o.items() if isinstance(o, dict) else enumerate(o) if isinstance(o, list) else ()
        for k, v in items:
            yield from paths(v, pre + (k,))

    for _ in range(1500):
        d = copy.deepcopy(base)
        where = rnd.choice(list(paths(d))[1:])
        parent = d
        for k in where[:-1]:
            parent = parent[k]
        op = rnd.random()
        if op < 0.6:
            parent[where[-1]] = copy.deepcopy(rnd.choice(values))
        elif isinstance(parent, dict):
            if op < 0.8:
                del parent[where[-1]]
            else:
                parent["Extra"] = "x"
        if _surely_valid(d):
            assert not list(_VALIDATOR.iter_errors(d)), where


def test_announcement_names_the_topics_and_bad_topics_are_ignored(monkeypatch):
    import rosgraph

    from modules import discovery

    d = parse_definition(scale_definition(0))
    good = discovery.announcement("/bm_a", d, "i1", topics={"call_topic": "/bmtree/call/scale00",
                                                            "cancel_topic": "/bmtree/cancel/scale00"},
                                  uri="http://127.0.0.1:1/")
    assert good["instance"] == "i1"
    hostile = dict(good, node="/bm_b", call_topic="/function/output", cancel_topic=7)
    older = {"node": "/bm_c", "definition": good["definition"]}

    class Master:
        def __init__(self, *a, master_uri=None, **k):
            self.master_uri = master_uri or "http://127.0.0.1:3/"

        def getParam(self, key):
            return {"scale00": good, "hostile": hostile, "older": older, "junk": {"node": 3}}

        def lookupNode(self, node):
            return "http://127.0.0.1:2/"

    monkeypatch.setattr(rosgraph, "Master", Master)
    found = discovery.announced_modules()
    assert sorted(found) == ["hostile", "older", "scale00"]
    assert (found["scale00"].call_topic, found["scale00"].uri) == ("/bmtree/call/scale00", "http://127.0.0.1:1/")
    assert found["hostile"].call_topic is None and found["hostile"].cancel_topic is None
    assert found["older"].call_topic is None and found["older"].uri == "http://127.0.0.1:2/"


class _Pub:
    def __init__(self, name):
        self.resolved_name = name
        self.sent = []

    def publish(self, msg, key=None):
        self.sent.append(msg.data)

    def discard(self, key):
        return False


def test_transport_sends_to_the_announced_topics_and_the_shared_ones_otherwise():
    from coordinator.ros_transport import RosTransport

    tr = RosTransport()
    tr._String = String
    own = _Pub("/bmtree/call/scale00")
    shared_call, shared_cancel = _Pub("/master/output"), _Pub("/master/cancel")
    tr._routes["scale00"] = own
    tr._pubs.update(call=shared_call, cancel=shared_cancel)
    tr.send_call(_call("scale00"))
    tr.send_call(_call("legacy"))
    tr.send_cancel(CancelRequest("c1", "scale00", "f00"))
    tr.send_cancel(CancelRequest("c2", "legacy", "f00"))
    assert [len(p.sent) for p in (own, shared_call, shared_cancel)] == [2, 1, 1]
    assert json.loads(own.sent[1]) == {"call_id": "c1", "basic_mod": "scale00", "function": "f00", "cancel": True}
    assert tr.topics_of("scale00") == ("/bmtree/call/scale00", "/bmtree/call/scale00")
    assert tr.topics_of("legacy") == ("/master/output", "/master/cancel")
    # a ping's answer is consumed by the transport, never delivered to the run
    tr._pings["p"] = "scale00"
    assert tr._take_ping(FunctionResult(call_id="p", basic_mod="scale00", function=PING_FUNCTION))
    assert tr._ponged == {"scale00"}
    assert not tr._take_ping(FunctionResult(call_id="p", basic_mod="scale00", function="f00"))
