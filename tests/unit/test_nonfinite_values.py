"""A NaN or an infinity in a run (a std_msgs/Float64 output, a tree's ``.nan``, an event's param)
leaves Python as JSON: the run stream's records and the run log (``jq``, roslibjs), the snapshots and
the web page's ``/state`` (the browser's ``JSON.parse`` refused Python's bare ``NaN``, and the page
stopped updating). Readers get the float back; old logs with a bare ``NaN`` still read."""
from __future__ import annotations

import json
import math
import urllib.request

import pytest

from coordinator.runlog import read_log
from coordinator.runrecords import parse_record
from coordinator.runstream import NONFINITE, to_json
from coordinator.watchsinks import SnapshotSink
from coordinator.watchstate import WatchState
from coordinator.watchtext import brief, values_text
from coordinator.webview import WebServer, replay_states
from tests.unit.test_recording import recorded

NAN, INF = float("nan"), float("inf")
TREE = {"v": 1, "type": "tree", "run": "r1", "t": 0.0, "started": 1.7e9, "name": "demo",
        "blackboard": {"limit": NAN}, "nodes": [{"id": 0, "name": "root", "parent": None, "kind": "sequence"}]}
NAN_TREE = """format: 1
name: nan_values
inputs:
  limit: {default: .nan}
root:
  sequence:
    name: read the battery
    children:
      - call: battery.level
        name: level
        outputs: {percentage: level}
      - set: {far: .inf, near: -.inf}
      - wait_event: battery.low
        name: low
        outputs: {percentage: low_at}
"""


def strict(text):
    """``text`` read as JSON is (a browser's JSON.parse, jq): no NaN, Infinity or -Infinity."""
    def refuse(word):
        raise ValueError("not JSON: %s" % word)

    return json.loads(text, parse_constant=refuse)


def same(a, b):
    """Equal, a NaN equal to a NaN."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


def test_a_nonfinite_float_is_written_as_json_and_read_back_as_the_float():
    rec = {"v": 1, "type": "call_end", "run": "r1", "t": 0.5, "call_id": "c1", "target": "battery.level",
           "status": "succeeded", "outputs": {"percentage": NAN, "range": [1.5, INF, -INF], "pair": (NAN, 2)},
           "duration": 0.1}
    text = to_json(rec)
    data = strict(text)  # what a browser, jq, roslibjs read
    assert data["outputs"]["percentage"] == {NONFINITE: "NaN"}
    assert data["outputs"]["range"] == [1.5, {NONFINITE: "Infinity"}, {NONFINITE: "-Infinity"}]
    got, why = parse_record(text)  # what bmtree's readers (runs, replay, watch, scenarios) get
    assert why == ""
    assert same(got, dict(rec, outputs=dict(rec["outputs"], pair=[NAN, 2])))


def test_a_ros_message_and_a_key_with_nan_are_json_too():
    from geometry_msgs.msg import Point

    text = to_json({"v": 1, "type": "write", "run": "r1", "t": 0.0, "key": "goal", "value": Point(x=NAN, y=1.0, z=-INF),
                    "odd": {NAN: 1}})
    data = strict(text)
    assert data["value"] == {"x": {NONFINITE: "NaN"}, "y": 1.0, "z": {NONFINITE: "-Infinity"}}
    assert data["odd"] == {"NaN": 1}
    assert same(parse_record(text)[0]["value"], {"x": NAN, "y": 1.0, "z": -INF})


def test_a_record_without_nan_is_written_as_before_and_lookalikes_stay():
    rec = {"v": 1, "type": "write", "run": "r1", "t": 0.25, "key": "k", "value": {"a": [1, 2.5, "NaN", None]}}
    assert to_json(rec) == json.dumps(rec, separators=(",", ":"), ensure_ascii=False)
    # the text "NaN" and objects that only look like the marker are left as they are
    for value in ("NaN", {NONFINITE: "nan"}, {NONFINITE: "NaN", "other": 1}, {NONFINITE: 5}):
        text = to_json(dict(rec, value=value))
        assert parse_record(text)[0]["value"] == value


def test_an_old_log_with_a_bare_nan_still_reads(tmp_path):
    lines = [json.dumps(TREE), json.dumps({"v": 1, "type": "write", "run": "r1", "t": 0.1, "key": "level", "value": NAN}),
             json.dumps({"v": 1, "type": "end", "run": "r1", "t": 0.2, "status": "SUCCESS", "ticks": 1, "duration": 0.2})]
    assert "NaN" in lines[1]
    path = tmp_path / "old.jsonl"
    path.write_text("".join(line + "\n" for line in lines))
    log = read_log(str(path))
    assert math.isnan(log.of_type("write")[0]["value"]) and math.isnan(log.tree["blackboard"]["limit"])
    state = WatchState()
    for line in lines:
        state.apply_text(line)
    assert math.isnan(state.blackboard["level"])


def _get(url):
    with urllib.request.urlopen(url, timeout=10) as answer:
        return strict(answer.read().decode("utf-8"))


def test_the_page_gets_json_live_and_in_a_replay():
    records = [TREE, {"v": 1, "type": "write", "run": "r1", "t": 0.1, "key": "far", "value": -INF},
               {"v": 1, "type": "event", "run": "r1", "t": 0.2, "module": "battery", "event": "low",
                "params": {"percentage": NAN}}]
    state = WatchState()
    for rec in records:
        state.apply(parse_record(to_json(rec))[0])  # as the watch gets them from the run stream
    live = WebServer(state)
    replay = WebServer(None, at=replay_states(records), duration=0.2)
    try:
        for data in (_get(live.url + "state?since=-1"), _get(replay.url + "state?at=end")):
            assert data["blackboard"] == {"limit": {NONFINITE: "NaN"}, "far": {NONFINITE: "-Infinity"}}
            assert data["events"][-1]["params"] == {"percentage": {NONFINITE: "NaN"}}
    finally:
        live.close()
        replay.close()


def test_a_snapshot_of_a_run_with_nan_is_json_and_a_late_watch_loads_it():
    sent = []
    sink = SnapshotSink(sent.append, interval=0.0)
    sink.write("tree", to_json(TREE))
    sink.write("blackboard", to_json({"v": 1, "type": "write", "run": "r1", "t": 0.1, "key": "far", "value": INF}))
    sink.close()
    assert strict(sent[-1])["blackboard"]["far"] == {NONFINITE: "Infinity"}
    late = WatchState()
    late.apply(TREE)
    late.apply_text(sent[-1])
    assert late.blackboard["far"] == INF and math.isnan(late.blackboard["limit"])


def test_the_terminal_says_nan_and_infinity():
    assert brief(NAN) == "NaN" and brief(INF) == "Infinity" and brief(-INF) == "-Infinity" and brief(1.5) == "1.5"
    assert values_text({"percentage": NAN, "charging": False}) == "percentage NaN, charging false"


def nan_run_log(sim_defs, tmp_path):
    """The log of a run on mocks whose battery answers NaN, whose tree sets infinities and whose event says
    -inf (the web page's test replays it too)."""
    tree = tmp_path / "nan_tree.yaml"
    tree.write_text(NAN_TREE)

    def script(m):
        m["battery.level"].succeed(percentage=NAN, charging=False)
        m.event_after("battery.level", 0.1, "battery.low", {"percentage": -INF})

    log, result = recorded(str(tree), sim_defs, tmp_path, script)
    assert result.status.value == "SUCCESS", result.reason
    return log


@pytest.fixture
def nan_log(sim_defs, tmp_path):
    return nan_run_log(sim_defs, tmp_path)


def test_a_run_with_nan_logs_json_lines_and_its_scenario_replays_it(nan_log, tmp_path):
    import io

    import yaml

    from coordinator.scenariogen import write_scenario
    from coordinator.testing.scenario import run_scenario_file

    lines = open(nan_log).read().splitlines()
    for line in lines:
        strict(line)  # jq reads every line
    log = read_log(nan_log)
    assert math.isnan(log.tree["blackboard"]["limit"])
    assert math.isnan(log.of_type("call_end")[0]["outputs"]["percentage"])
    assert {r["key"]: r["value"] for r in log.of_type("write")} == {"level": pytest.approx(NAN, nan_ok=True),
                                                                    "far": INF, "near": -INF, "low_at": -INF}
    out = tmp_path / "replayed.yaml"
    write_scenario(log, str(out))
    scenario = yaml.safe_load(out.read_text())["scenarios"][0]
    assert math.isnan(scenario["mocks"]["battery.level"][0]["succeed"]["percentage"])
    assert scenario["events"][0]["params"] == {"percentage": -INF}
    said = io.StringIO()
    assert run_scenario_file(str(out), out=said) == [True], said.getvalue()
