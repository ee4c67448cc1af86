"""Fault handling without ROS: hostile input at every boundary, correlation checks, lost modules."""
from __future__ import annotations

import json
import sys
import threading

import pytest
from std_msgs.msg import String

from blackboard.service import BlackboardService
from blackboard.store import Store
from comm import BlackboardAnswer, BlackboardRequest, FunctionCall, FunctionResult, ProtocolError
from comm.limits import check_depth
from comm.liveness import BlackboardLost, ModuleLost
from comm.messages import load_payload
from comm.rostypes import resolve_type
from coordinator.cli import main as bmtree
from coordinator.clock import SimClock
from coordinator.context import RunContext
from coordinator.transport import Transport
from modules.definition import DefinitionError, load_definition, parse_definition
from modules.runtime import BasicModule, ModuleServer
from tests.conftest import log_records

DEF = {"Basic Module": "probe", "Brief Description": "", "Hardware Required": [], "Functions": [
    {"Name": "echo", "Exec-condition": "", "Description": "", "Concurrent": True,
     "Input-params": [{"Name": "tag", "Data-type": "std_msgs/String", "Description": ""}],
     "Output-params": [{"Name": "tag", "Data-type": "std_msgs/String", "Description": ""}]},
    {"Name": "other", "Exec-condition": "", "Description": "", "Input-params": [], "Output-params": []}]}


@pytest.fixture
def probe():
    return parse_definition(json.loads(json.dumps(DEF)), "probe.json")


# comm -------------------------------------------------------------------------------------
def test_depth_is_checked_before_parsing():
    check_depth("[" * 100 + "]" * 100)
    check_depth('["' + "[" * 5000 + '"]')  # brackets inside strings do not count
    with pytest.raises(ProtocolError, match="nested deeper than 100"):
        check_depth("[" * 10000 + "]" * 10000)
    with pytest.raises(ProtocolError, match="nested deeper"):
        load_payload('{"a": %s}' % ("[" * 10000 + "]" * 10000))


def test_lone_surrogates_are_refused_and_pairs_accepted():
    with pytest.raises(ProtocolError, match="lone surrogate"):
        load_payload('{"names": ["\\ud800"]}')
    assert load_payload('{"x": "\\ud83d\\ude00"}') == {"x": "\U0001F600"}


@pytest.mark.parametrize("name", ["this/Zen", "antigravity/X", "os/path", "json/decoder", "std_msgs/Nope",
                                  "../x/Y", "std_msgs/String\x00", "a" * 500 + "/B", "std_msgs/__init__"])
def test_type_names_never_import_anything(name):
    before = set(sys.modules)
    assert resolve_type(name) is None
    assert set(sys.modules) - before == set()


def test_values_that_break_the_converter_are_protocol_errors():
    for text in ['{"data": %s}' % ("9" * 400), '{"data": 1e999}', "[" * 5000 + "]" * 5000]:
        with pytest.raises(ProtocolError):
            FunctionCall.decode(json.dumps({"basic_mod": "m", "function": "f", "rostypes": ["std_msgs/Int32"],
                                            "msgs": [text]}))


# module runtime ----------------------------------------------------------------------------
class Probe(BasicModule):
    concurrent = True

    def echo(self, tag):
        return {"tag": tag}

    def other(self):
        return {}


def test_a_deep_call_gets_a_rejected_answer(probe):
    out = []
    server = ModuleServer(probe, Probe(), out.append, lambda t: None)
    server.handle_call('{"basic_mod": "probe", "function": "echo", "call_id": "c1", "msgs": %s}'
                       % ("[" * 10000 + "]" * 10000))
    server.handle_call(json.dumps({"basic_mod": "probe", "function": "echo", "call_id": "c2", "names": ["tag"],
                                   "rostypes": ["std_msgs/String"], "msgs": ["[" * 10000 + "]" * 10000]}))
    server.handle_call('{"basic_mod": "probe", "function": "echo", "call_id": "c3", "x": "%s"}' % ("y" * (2 << 20)))
    got = {r.call_id: r for r in map(FunctionResult.decode, out)}
    assert set(got) == {"c1", "c2", "c3"}
    assert all(r.status == "rejected" for r in got.values())
    assert "nested deeper" in got["c1"].error and got["c1"].error.startswith("malformed call: ")
    # not malformed: too large for this node, and what to raise says so
    assert got["c3"].error.startswith("call too large: payload of ") and got["c3"].error.endswith(
        "(raise it with --max-bytes N, or _max_bytes:=N, on the module's node)"), got["c3"].error


def test_garbage_cancels_never_raise(probe):
    server = ModuleServer(probe, Probe(), lambda t: None, lambda t: None)
    for text in ["", "[" * 10000, '{"call_id": ["x"]}', b"\xff", None, 5, '{"call_id": "\\ud800"}']:
        server.handle_cancel(text)
        server.handle_call(text)


# blackboard --------------------------------------------------------------------------------
@pytest.fixture
def bb(tmp_path):
    answers, acks = [], []
    store = Store(str(tmp_path / "bb.sqlite"))
    svc = BlackboardService(store, answers.append, acks.append, after_wait=0.5)
    yield svc, answers, acks
    svc.stop()
    store.close()


def _result(call_id, name="v", value="x"):
    return FunctionResult([name], [String(value)], call_id=call_id, basic_mod="m", function="f").encode()


def test_a_bad_row_does_not_cost_its_neighbours(bb, monkeypatch):
    svc, answers, acks = bb
    real_add = svc.store.add

    def add(rows):  # what SQLite does with a text it cannot encode
        if any(r[0] == "bad" for r in rows):
            raise UnicodeEncodeError("utf-8", "\ud800", 0, 1, "surrogates not allowed")
        return real_add(rows)

    monkeypatch.setattr(svc.store, "add", add)
    svc._handle([(0, _result("a"), 1.0), (0, _result("b", name="bad"), 1.0), (0, _result("c"), 1.0)])
    assert json.loads(acks[-1])["call_ids"] == ["a", "c"]
    assert svc.store.has_call("a") and svc.store.has_call("c") and not svc.store.has_call("b")


def test_deep_and_hostile_input_keeps_the_writer_alive(bb):
    svc, answers, acks = bb
    for text in ['{"names": %s}' % ("[" * 10000 + "]" * 10000), '{"names": ["\\ud800"], "rostypes": [], "msgs": []}',
                 json.dumps({"names": ["v"], "rostypes": ["this/Zen"], "msgs": ["{}"]})]:
        svc.on_result(text)
    for text in ["[" * 10000, '{"var_names": ["v"], "history": 1e400, "request_id": "h"}',
                 '{"var_names": ["v"], "history": %s, "request_id": "h2"}' % ("9" * 50)]:
        svc.on_request(text)
    svc.on_result(_result("good"))
    req = BlackboardRequest(var_names=["v"])
    svc.on_request(req.encode())
    assert svc.flush()
    last = BlackboardAnswer.decode(answers[-1])
    assert last.request_id == req.request_id and last.values["v"].data == "x"
    assert {json.loads(a)["request_id"] for a in answers[:-1]} == {"h", "h2"}  # bad requests answered too


def test_a_request_waits_for_the_results_it_names(bb):
    svc, answers, acks = bb
    req = BlackboardRequest(var_names=["v"], after=["late"])
    svc.on_request(req.encode())
    assert svc.flush() and answers == []  # held back: 'late' is not stored yet
    svc.on_result(_result("late", value="fresh"))
    assert svc.flush()
    done = threading.Event()
    for _ in range(100):
        if answers:
            break
        done.wait(0.01)
    ans = BlackboardAnswer.decode(answers[-1])
    assert ans.request_id == req.request_id and ans.values["v"].data == "fresh"
    # a result that never comes: answered with what is there after the bounded wait
    svc.on_request(BlackboardRequest(var_names=["v"], after=["never"], request_id="n").encode())
    for _ in range(500):
        if len(answers) == 2:
            break
        done.wait(0.01)
    assert json.loads(answers[-1])["request_id"] == "n"
    # ... and says which of the results it was to wait for it does not have (its value is older)
    assert BlackboardAnswer.decode(answers[-1]).unstored == ["never"]
    assert BlackboardAnswer.decode(answers[0]).unstored == [] and "unstored" not in answers[0]


# coordinator -------------------------------------------------------------------------------
class _Sent(Transport):
    def __init__(self):
        self.sent = []

    def connect(self, deliver):
        pass

    def send_call(self, call):
        self.sent.append(call)

    def send_cancel(self, cancel):
        self.sent.append(cancel)

    def send_request(self, request):
        self.sent.append(request)


def test_results_must_match_the_calls_module_and_function(probe):
    ctx = RunContext(_Sent(), SimClock(), {"probe": probe})
    fn = probe.function("echo")
    rec = ctx.start_call(fn, fn.build_call({"tag": "x"}, "id1"))
    wrong = FunctionResult(call_id="id1", basic_mod="probe", function="other")
    assert ctx.correlate(wrong) is None
    assert ctx.correlate(FunctionResult(call_id="id1", basic_mod="other", function="echo")) is None
    right = probe.function("echo").build_result({"tag": "x"}, "id1")
    assert ctx.correlate(right) is rec


def test_lost_modules_and_blackboards_end_what_waits_on_them(probe):
    transport = _Sent()
    ctx = RunContext(transport, SimClock(), {"probe": probe})
    fn = probe.function("echo")
    rec = ctx.start_call(fn, fn.build_call({"tag": "x"}, "id1"))
    ctx.dispatch(ModuleLost(module="probe", node="/bm_probe", reason="node /bm_probe stopped", call_ids=["id1"]))
    assert rec.status == "module_lost" and "stopped" in rec.error and not ctx.pending
    ctx.dispatch(FunctionResult(names=["tag"], msgs=[String("x")], call_id="id9", basic_mod="probe",
                                function="echo"))
    rid = ctx.request(["tag"])
    ctx.dispatch(BlackboardLost(node="/blackboard", reason="gone", request_ids=[rid]))
    assert "Blackboard node lost" in ctx.answers[rid].error


def test_a_recall_names_the_results_it_must_see(probe):
    transport = _Sent()
    ctx = RunContext(transport, SimClock(), {"probe": probe})
    fn = probe.function("echo")
    ctx.start_call(fn, fn.build_call({"tag": "x"}, "id1"))
    ctx.dispatch(fn.build_result({"tag": "x"}, "id1"))
    ctx.request(["tag"])
    ctx.request(["tag"])
    assert transport.sent[-2].after == ["id1"] and transport.sent[-1].after == []


def test_a_value_whose_result_the_blackboard_did_not_store_is_not_recalled(probe, tmp_path):
    """A Blackboard node restarted (or cut off) while a call ran answers with the value from
    before the call: the recall fails and says why instead of handing it to the tree."""
    from coordinator.builder import build_tree
    from coordinator.language import load_tree

    transport = _Sent()
    ctx = RunContext(transport, SimClock(), {"probe": probe})
    fn = probe.function("echo")
    for call_id in ("id1", "id2"):
        ctx.start_call(fn, fn.build_call({"tag": "x"}, call_id))
        ctx.dispatch(fn.build_result({"tag": call_id}, call_id))
    path = tmp_path / "recall.yaml"
    path.write_text("format: 1\nroot:\n  recall: {said: tag, full: probe/echo/tag}\n")
    tree = load_tree(str(path), {"probe": probe})
    root = build_tree(tree, ctx, {})
    root.tick_once()
    req = transport.sent[-1]
    assert req.after == ["id1", "id2"]
    old = [String("before")] * 2
    ctx.dispatch(BlackboardAnswer(names=["tag", "probe/echo/tag"], msgs=old, request_id=req.request_id, unstored=["id2"]))
    root.tick_once()
    assert root.status.value == "FAILURE"
    assert ("the Blackboard node did not store the result of probe.echo (call id2) that wrote tag, so its value is "
            "an older one") in root.feedback_message and "wrote probe/echo/tag" in root.feedback_message
    # a later result of that output, stored, makes the Blackboard's value the run's again
    ctx.start_call(fn, fn.build_call({"tag": "x"}, "id3"))
    ctx.dispatch(fn.build_result({"tag": "id3"}, "id3"))
    root.tick_once()
    req = transport.sent[-1]
    assert req.after == ["id3"]
    ctx.dispatch(BlackboardAnswer(names=["tag", "probe/echo/tag"], msgs=[String("id3")] * 2, request_id=req.request_id))
    root.tick_once()
    assert root.status.value == "SUCCESS" and ctx.blackboard["said"].data == "id3"
    # a request the Blackboard never answered asks about its results again
    ctx.dispatch(fn.build_result({"tag": "id4"}, ctx.start_call(fn, fn.build_call({"tag": "x"}, "id4")).call_id))
    rid = ctx.request(["tag"])
    ctx.dispatch(BlackboardLost(node="/blackboard", reason="gone", request_ids=[rid]))
    assert ctx.request(["tag"]) and transport.sent[-1].after == ["id4"]


# loaders and arguments ---------------------------------------------------------------------
def test_loaders_refuse_deep_tagged_and_recursive_documents(tmp_path, capsys):
    cases = {
        "deep.yaml": "[" * 50000 + "]" * 50000,
        "dash.yaml": "- " * 50000 + "x",
        "tagged.yaml": 'format: 1\nroot: !!python/object/apply:os.system ["true"]\n',
        "tagged_map.yaml": "format: 1\nroot: !!python/object:os.system {a: 1}\n",
        "rec.yaml": "a: &a [*a]\nroot: *a\n",
        "stamp.yaml": "format: 1\nroot: !!timestamp nonsense\n",
        "latin1.yaml": b"format: 1\nroot: \xe9\n",
    }
    for name, text in cases.items():
        path = tmp_path / name
        (path.write_bytes if isinstance(text, bytes) else path.write_text)(text)
        assert bmtree(["check", str(path)]) == 2, name
        err = capsys.readouterr().err
        assert "%s:1:" % name in err or "%s:2:" % name in err, err
        assert "Traceback" not in err
    (tmp_path / "deep.json").write_text('{"a":' * 50000 + "1" + "}" * 50000)
    with pytest.raises(DefinitionError, match="nested deeper"):
        load_definition(str(tmp_path / "deep.json"))


def test_unsafe_set_values_are_usage_errors(capsys):
    assert bmtree(["run", "trees/find_apple.yaml", "--set", 'x=!!python/object/apply:os.system ["true"]']) == 2
    assert "not a plain YAML value" in capsys.readouterr().err


class _AskEveryTime:
    """A watchdog line that keeps no connection (as a node closing each one): asked at every check."""

    kept = False

    def __init__(self, uri, pid):
        self.uri, self._pid = uri, pid

    def ask(self):
        return self._pid(self.uri)

    def fileno(self):
        return -1

    def close(self):
        pass


def test_watchdog_reports_a_restart_mid_call_but_not_a_respawn_between_calls():
    from comm import liveness

    state = {"uri": "http://h:1/", "pid": 10}

    def pid(uri):
        if uri != state["uri"]:
            raise OSError("refused")
        return state["pid"]

    got = []
    dog = liveness.Watchdog(got.append, lambda m: "/bm_probe", lambda n: state["uri"], period=0,
                            line=lambda uri, timeout, caller: _AskEveryTime(uri, pid))
    dog.call_sent("a", "probe")
    dog.check()                       # the watch begins: pid 10
    dog.call_done("a")
    dog.check()                       # nothing owed: forgotten
    state.update(uri="http://h:2/", pid=11)  # respawned between calls
    dog.call_sent("b", "probe")
    dog.check()
    dog.check()
    assert got == []
    state.update(uri="http://h:3/", pid=12)  # restarted while 'b' runs
    dog.check()
    assert len(got) == 1 and got[0].call_ids == ["b"] and "restarted" in got[0].reason


def test_a_call_answered_by_two_nodes_is_reported(probe):
    from coordinator.ros_transport import RosTransport

    class Msg:
        def __init__(self, data, node):
            self.data = data
            self._connection_header = {"callerid": node}

    with log_records("bmtree.coordinator") as records:
        transport = RosTransport(liveness=0)
        delivered = []
        transport._deliver = delivered.append
        text = probe.function("echo").build_result({"tag": "x"}, "id1").encode()
        on_result = transport._on(FunctionResult)
        on_result(Msg(text, "/bm_a"))
        on_result(Msg(text, "/bm_a"))
        assert records == []
        on_result(Msg(text, "/bm_b"))
    assert len(delivered) == 3
    assert len(records) == 1 and "answered by two nodes, /bm_a and /bm_b" in records[0].getMessage()


def test_watchdog_asks_only_about_calls_in_flight_for_a_period(monkeypatch):
    from comm import liveness

    clock = {"now": 100.0}

    class _Time:
        @staticmethod
        def monotonic():
            return clock["now"]

    asked = []

    def pid(uri):
        asked.append(uri)
        raise OSError("refused")  # its process is gone

    monkeypatch.setattr(liveness, "time", _Time)
    got = []
    dog = liveness.Watchdog(got.append, lambda m: "/bm_%s" % m, lambda n: "http://h%s/" % n, period=0.25,
                            line=lambda uri, timeout, caller: _AskEveryTime(uri, pid))
    dog.call_sent("quick", "a")
    dog.check()
    dog.call_done("quick")            # answered within its first period: its node was never asked
    dog.call_sent("slow", "b")
    clock["now"] += 0.1
    dog.check()
    assert asked == [] and got == []
    clock["now"] += 0.2               # 'slow' has been in flight for a period: its node is asked
    dog.check()
    assert asked == ["http://h/bm_b/"]
    assert len(got) == 1 and got[0].module == "b" and got[0].call_ids == ["slow"]


def test_a_call_sent_after_its_node_was_found_gone_waits_for_the_node_to_be_started_again(monkeypatch):
    """kill -9 leaves the node registered at its dead URI until the new process registers: a retry sent
    at once was lost on the dead process a period later (a respawn taking a second under load made a
    ``retry: 3`` fail three times in 0.5 s). It waits ``restart_grace`` for a new process, then is lost."""
    from comm import liveness

    clock = {"now": 100.0}
    monkeypatch.setattr(liveness, "time", type("T", (), {"monotonic": staticmethod(lambda: clock["now"])}))
    state = {"uri": "http://h:1/", "alive": {"http://h:1/": 10}}

    def pid(uri):
        if uri not in state["alive"]:
            raise OSError("refused")
        return state["alive"][uri]

    got = []
    dog = liveness.Watchdog(got.append, lambda m: "/bm_probe", lambda n: state["uri"], period=0.25,
                            line=lambda uri, timeout, caller: _AskEveryTime(uri, pid), restart_grace=10.0)
    dog.call_sent("a", "probe")
    clock["now"] += 0.3
    dog.check()                       # the watch begins: pid 10
    state["alive"].clear()            # kill -9: still registered at h:1
    clock["now"] += 0.3
    dog.check()
    assert [(g.call_ids, g.reason) for g in got] == [(["a"], "node /bm_probe stopped (its process is gone)")]
    dog.call_sent("retry", "probe")   # sent at once
    for _ in range(30):               # 9 s: not started again yet
        clock["now"] += 0.3
        dog.check()
    assert len(got) == 1
    state.update(uri="http://h:2/", alive={"http://h:2/": 11})   # the new process registers
    clock["now"] += 0.3
    dog.check()
    assert len(got) == 1 and dog.owes("retry")
    state["alive"].clear()            # and dies too, and is never started again
    clock["now"] += 0.3
    dog.check()
    assert got[-1].call_ids == ["retry"] and got[-1].reason == "node /bm_probe stopped (its process is gone)"
    dog.call_sent("last", "probe")
    for _ in range(40):
        clock["now"] += 0.3
        dog.check()
    assert got[-1].call_ids == ["last"] and got[-1].reason == (
        "node /bm_probe stopped (its process is gone) and was not started again within 10s")


def test_a_call_to_a_node_stopped_cleanly_is_lost_at_once_not_held_for_a_restart():
    """A node stopped on purpose unregistered its topics: no respawn is coming, and a call held for one
    ran when the node was started again much later (a follower moving 40 s after it was asked)."""
    from comm import liveness

    got = []
    dog = liveness.Watchdog(got.append, lambda m: "/bm_probe", lambda n: "http://h:1/", period=0,
                            line=lambda uri, timeout, caller: _AskEveryTime(uri, _refused), restart_grace=10.0,
                            registered=lambda node: False)
    for call_id in ("a", "b"):
        dog.call_sent(call_id, "probe")
        dog.check()
        assert got[-1].call_ids == [call_id] and got[-1].reason == "node /bm_probe stopped (its process is gone)"


def _refused(uri):
    raise OSError("refused")
