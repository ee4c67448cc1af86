"""Blackboard bounds: per-request limits, answers over --max-bytes, and malformed announcements
that must never cost the other results of a batch."""
from __future__ import annotations

import json

import pytest
from std_msgs.msg import Bool, String

from blackboard.attribution import Attribution
from blackboard.service import _RESULT, MAX_HISTORY, MAX_NAMES, BlackboardService
from blackboard.store import Store
from comm import BlackboardAnswer, FunctionResult, commBM


@pytest.fixture
def store(tmp_path):
    s = Store(str(tmp_path / "bb.sqlite"))
    yield s
    s.close()


def result(call_id, **values):
    return FunctionResult(list(values), [Bool(v) if isinstance(v, bool) else String(v) for v in values.values()],
                          call_id=call_id, basic_mod="m", function="f").encode()


def ask(svc, answers, **req):
    before = len(answers)
    svc.on_request(json.dumps(dict(req, request_id="r")))
    assert len(answers) == before + 1          # answered at once, never left to a timeout
    ans = BlackboardAnswer.decode(answers[-1])
    assert ans.request_id == "r"
    return ans


def test_duplicates_answered_once_a_history_bounded_by_the_store_and_too_many_names_refused(store):
    answers = []
    svc = BlackboardService(store, answers.append, threaded=False)
    svc.on_result(result("c1", room="kitchen"))
    ans = ask(svc, answers, var_names=["room"] * 2000)
    assert ans.names == ["room"] and ans.msgs == [String("kitchen")] and not ans.error
    ans = ask(svc, answers, var_names=["room"] * 2000, history=1000000)   # the audit's request: 1.86 GB before
    assert ans.names == ["room"] and ans.msgs == [String("kitchen")] and not ans.error
    ans = ask(svc, answers, var_names=["n%d" % i for i in range(MAX_NAMES + 1)])
    assert not ans.names and "%d distinct names" % (MAX_NAMES + 1) in ans.error and str(MAX_NAMES) in ans.error
    assert len(ask(svc, answers, var_names=["n%d" % i for i in range(MAX_NAMES)]).missing) == MAX_NAMES
    assert ask(svc, answers, var_names=["room"], history=MAX_HISTORY).msgs == [String("kitchen")]
    assert all(len(a) < 20000 for a in answers)


@pytest.mark.parametrize("values", [3, 30])   # exact size over the limit / stopped while reading
def test_an_answer_over_max_bytes_is_an_error_naming_sizes(store, values):
    answers = []
    svc = BlackboardService(store, answers.append, threaded=False, max_bytes=2048, prune_every=10 ** 6)
    for i in range(values):
        svc.on_result(result("c%d" % i, blob="x" * 600))
    ans = ask(svc, answers, var_names=["blob"], history=values)
    assert not ans.names and not ans.missing
    assert "answer too large" in ans.error and "2048 bytes" in ans.error
    assert all(len(a.encode()) <= 2048 for a in answers)
    assert ask(svc, answers, var_names=["blob"]).msgs == [String("x" * 600)]   # one value fits


def deep_announcements():
    good = {"Functions": [{"Name": "grasp", "Output-params": [{"Name": "success"}]}]}
    deep = '{"Functions": ' + "[" * 50000 + "]" * 50000 + "}"
    return {"bad": {"node": "/bad_node", "definition": deep},
            "arm": {"node": "/arm_driver", "definition": json.dumps(good)}}


def test_a_deeply_nested_announcement_is_skipped_alone():
    att = Attribution(deep_announcements)
    assert att.attribute("/arm_driver", ["success"]) == ("arm", "grasp", None)
    assert att.attribute("/bad_node", ["success"])[0] == "bad"


class _Exploding(Attribution):
    def attribute(self, *args, **kw):
        raise RecursionError("maximum recursion depth exceeded")


@pytest.mark.parametrize("attribution", [lambda: Attribution(deep_announcements), lambda: _Exploding(dict)])
def test_one_bad_item_never_loses_its_batch(store, attribution):
    answers, acks = [], []
    svc = BlackboardService(store, answers.append, acks.append, threaded=False, attribution=attribution())
    items = [(_RESULT, (result("g%d" % i, ok=True), "/m"), 1.0) for i in range(2)]
    items.append((_RESULT, (commBM.writeMsgFromRos([Bool(True)], ["success"]), "/bad_node"), 1.0))
    items += [(_RESULT, (result("g%d" % i, ok=True), "/m"), 1.0) for i in range(2, 4)]
    svc._handle(items)
    assert json.loads(acks[-1])["call_ids"] == ["g0", "g1", "g2", "g3"]
    assert store.count() == 5 and svc.total == 5
