"""The Blackboard's store and service without ROS: queries, retention, malformed input, dump."""
from __future__ import annotations

import json
import os

import pytest
from std_msgs.msg import Bool, String

from blackboard.service import BlackboardService
from blackboard.store import Store
from comm import BlackboardAnswer, BlackboardRequest, FunctionResult, commBM
from coordinator.cli import main as bmtree


@pytest.fixture
def bb(tmp_path):
    answers, acks = [], []
    store = Store(str(tmp_path / "bb.sqlite"), keep=3)
    svc = BlackboardService(store, answers.append, acks.append, prune_every=1)
    yield svc, answers, acks
    svc.stop()
    store.close()


def ask(svc, answers, **kw):
    req = BlackboardRequest(**kw)
    svc.on_request(req.encode())
    assert svc.flush()
    ans = BlackboardAnswer.decode(answers[-1])
    assert ans.request_id == req.request_id
    return ans


def result(mod, fn, call_id, **values):
    names = list(values)
    return FunctionResult(names, [Bool(v) if isinstance(v, bool) else String(v) for v in values.values()],
                          call_id=call_id, basic_mod=mod, function=fn).encode()


def test_latest_qualified_history_call_and_missing(bb):
    svc, answers, acks = bb
    svc.on_result(result("arm", "grasp", "c1", success=True, note="a"))
    svc.on_result(result("base", "go", "c2", success=False))
    svc.on_result(commBM.writeMsgFromRos([String("legacy")], ["note"]))     # an original module's result
    ans = ask(svc, answers, var_names=["success", "arm/grasp/success", "note", "nothing", "a/b"])
    assert [(n, m.data) for n, m in zip(ans.names, ans.msgs)] == [
        ("success", False), ("arm/grasp/success", True), ("note", "legacy")]
    assert ans.missing == ["nothing", "a/b"] and "invalid name 'a/b'" in ans.error
    assert ans.sources[0]["call_id"] == "c2" and ans.sources[2]["basic_mod"] is None
    hist = ask(svc, answers, var_names=["note"], history=5)
    assert [m.data for m in hist.msgs] == ["legacy", "a"]
    by_call = ask(svc, answers, call_id="c1")
    assert sorted(by_call.names) == ["note", "success"]
    assert json.loads(acks[-1])["total"] == 4
    assert ask(svc, answers, call_id="zzz").missing == ["zzz"]


def test_legacy_var_request_answer_format(bb):
    svc, answers, _ = bb
    svc.on_result(result("arm", "grasp", "c1", success=True))
    svc.on_request(commBM.writeVarRequest(["success", "final_pos"]))
    assert svc.flush()
    raw = json.loads(answers[-1])
    assert raw["names"] == ["success"] and raw["rostypes"] == ["std_msgs/Bool"] and raw["msgs"] == ['{"data": true}']
    assert raw["missing"] == ["final_pos"] and raw["request_id"] is None
    assert commBM.readMsg2Ros(answers[-1]) == (["success"], [Bool(True)])   # readable by the original API


def test_retention_keeps_the_newest(bb):
    svc, answers, _ = bb
    for i in range(10):
        svc.on_result(result("m", "f", "c%d" % i, note=str(i)))
    svc.flush()
    svc.on_result(result("m", "f", "last", other="x"))   # triggers pruning of the touched names
    svc.flush()
    assert [m.data for m in ask(svc, answers, var_names=["note"], history=10).msgs] == ["9", "8", "7"]


def test_malformed_input_is_ignored_and_answered(bb):
    svc, answers, _ = bb
    for bad in ("", "{", "[]", '{"names": 1}', '{"names": ["a"], "rostypes": ["x/Y"], "msgs": ["{}"]}', b"\xff"):
        svc.on_result(bad)
        svc.on_request(bad)
    svc.on_request('{"var_names": "a", "request_id": "r1"}')
    svc.on_result(result("m", "f", "ok", good=True))
    svc.flush()
    errs = [BlackboardAnswer.decode(a) for a in answers]
    assert [(a.request_id, a.error[:11]) for a in errs] == [("r1", "bad request")]
    assert svc.rejected == 13
    assert ask(svc, answers, var_names=["good"]).msgs == [Bool(True)]


def test_store_survives_reopen_and_dump(tmp_path, capsys):
    path = str(tmp_path / "bb.sqlite")
    svc = BlackboardService(Store(path), lambda t: None)
    svc.on_result(result("vision", "find_object", "c1", success=True, room="kitchen"))
    svc.stop()
    assert Store(path).count() == 2
    assert bmtree(["blackboard", "dump", "--db", path]) == 0
    out = capsys.readouterr().out
    assert "room" in out and '{"data": "kitchen"}' in out
    assert bmtree(["blackboard", "dump", "--db", path, "--name", "vision/find_object/room"]) == 0
    assert "vision.find_object" in capsys.readouterr().out
    assert bmtree(["blackboard", "dump", "--db", str(tmp_path / "none.sqlite")]) == 3


def test_dump_reads_a_store_being_written_and_leaves_a_closed_store_as_it_was(tmp_path, capsys):
    path = str(tmp_path / "bb.sqlite")
    writer = Store(path)
    writer.add([("room", "std_msgs/String", '{"data": "hall"}', "vision", "find_object", "c1", 1.0)])
    assert os.path.exists(path + "-wal")              # the value is still in the writer's WAL
    assert bmtree(["blackboard", "dump", "--db", path]) == 0
    assert '{"data": "hall"}' in capsys.readouterr().out
    writer.close()
    assert sorted(os.listdir(str(tmp_path))) == ["bb.sqlite"]
    assert bmtree(["blackboard", "dump", "--db", path]) == 0
    assert '{"data": "hall"}' in capsys.readouterr().out
    assert sorted(os.listdir(str(tmp_path))) == ["bb.sqlite"]    # no -wal/-shm left by a reader


def test_original_modules_results_are_stored_under_the_module_whose_node_published_them(tmp_path):
    from geometry_msgs.msg import Point

    from blackboard.attribution import Attribution
    from comm import FunctionCall

    arm = {"Functions": [{"Name": "grasp", "Output-params": [{"Name": "success"}, {"Name": "final_pos"}]},
                         {"Name": "home", "Output-params": [{"Name": "final_pos"}]}]}
    announced = {"arm": {"node": "/arm_driver", "definition": json.dumps(arm), "legacy": True}}
    answers = []
    store = Store(str(tmp_path / "bb.sqlite"))
    svc = BlackboardService(store, answers.append, attribution=Attribution(lambda: announced))
    try:
        for module, function, call_id in (("arm", "home", "k1"), ("arm", "grasp", "k2"), ("speech", "say", "k3")):
            svc.on_call(FunctionCall(module, function, call_id=call_id).encode())
        svc.on_result(commBM.writeMsgFromRos([Bool(True), Point(x=1.0)], ["success", "final_pos"]),
                      publisher="/arm_driver")                  # answers k2 (arm.grasp), not k1 (arm.home)
        svc.on_result(commBM.writeMsgFromRos([Bool(False)], ["success"]), publisher="/stranger")
        svc.on_cancel(json.dumps({"call_id": "k1", "basic_mod": "arm", "function": "home"}))
        svc.on_result(commBM.writeMsgFromRos([Point(x=2.0)], ["final_pos"]), publisher="/arm_driver")
        ans = ask(svc, answers, var_names=["arm/grasp/success", "arm/grasp/final_pos", "arm/home/final_pos"])
        assert [n for n in ans.names] == ["arm/grasp/success", "arm/grasp/final_pos", "arm/home/final_pos"]
        assert ans.sources[0]["call_id"] == "k2" and ans.msgs[1].x == 1.0
        assert ans.sources[2]["call_id"] is None and ans.msgs[2].x == 2.0   # k1 was cancelled: no call of its own
        ans = ask(svc, answers, var_names=["success"])
        assert ans.msgs[0].data is False and ans.sources[0]["basic_mod"] is None   # a node of no module
    finally:
        svc.stop()
        store.close()
