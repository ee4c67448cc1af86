"""Recording with real processes: the run stream on ROS topics, run logs of --sim runs, a log
cut by kill -9, and the loop field run -> log -> scenario -> bmtree test -> changed tree."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import time

import yaml

from coordinator.runlog import read_log
from tests.conftest import DATA
from tests.integration.conftest import bmtree_cmd, start_sim_module

GO = os.path.join(DATA, "record", "go_kitchen.yaml")
GO_RETRY = os.path.join(DATA, "record", "go_kitchen_retry.yaml")


def world(tmp_path, name, **changes):
    from modules.sim import DEFAULT_WORLD

    with open(DEFAULT_WORLD) as fh:
        data = yaml.safe_load(fh)
    data.update(changes)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return str(path)


def bmtree(*args, env, timeout=120):
    return subprocess.run(bmtree_cmd(*args), capture_output=True, text=True, timeout=timeout, env=env,
                          stdin=subprocess.DEVNULL)


def test_field_run_to_log_to_scenario_and_a_changed_tree(tmp_path):
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    faulty = world(tmp_path, "blocked.yaml", faults={"navigation.go_to": {"fail": "blocked", "times": 1}})
    tree = tmp_path / "go_kitchen.yaml"
    shutil.copy(GO, str(tree))

    out = bmtree("run", "--sim", "--world", faulty, str(tree), env=env)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "reason: go to the kitchen: navigation.go_to failed: blocked" in out.stdout
    # the simulated robot's store and module logs are kept, and the run says where
    sim_dir = next(line.split(": ", 1)[1] for line in out.stdout.splitlines()
                   if line.startswith("simulated robot's Blackboard store and module logs: "))
    assert os.path.isfile(os.path.join(sim_dir, "blackboard.sqlite"))
    assert os.path.isfile(os.path.join(sim_dir, "bm_navigation.out"))
    dump = bmtree("blackboard", "dump", "--db", os.path.join(sim_dir, "blackboard.sqlite"), env=env)
    assert dump.returncode == 0 and "success" in dump.stdout, dump.stdout + dump.stderr
    log_path = next(line.split(": ", 1)[1] for line in out.stdout.splitlines() if line.startswith("run log: "))
    assert log_path.startswith(str(tmp_path / "home" / "bmtree" / "runs"))

    runs = bmtree("runs", env=env)
    assert runs.returncode == 0
    assert "go_kitchen" in runs.stdout and "FAILURE" in runs.stdout and "navigation.go_to failed: blocked" in runs.stdout

    failure = bmtree("replay", "last", "--failure", env=env)
    assert failure.returncode == 0, failure.stderr
    assert "the failure that ended the run, at" in failure.stdout and "'go to the kitchen'" in failure.stdout
    assert "tree blackboard:" in failure.stdout and "calls in flight: none" in failure.stdout

    scenario = str(tmp_path / "regression.yaml")
    made = bmtree("replay", "1", "--scenario", scenario, env=env)
    assert made.returncode == 0, made.stderr
    passed = bmtree("test", scenario, env=env)
    assert passed.returncode == 0, passed.stdout + passed.stderr
    assert "PASS" in passed.stdout and "1 passed, 0 failed" in passed.stdout

    shutil.copy(GO_RETRY, str(tree))  # the change the field run suggested
    changed = bmtree("test", scenario, env=env)
    assert changed.returncode == 1, changed.stdout + changed.stderr
    assert "calls changed" in changed.stdout
    assert '+ navigation.go_to {"place": "kitchen"}' in changed.stdout
    assert '= speech.say {"text": "I am going to the kitchen."}' in changed.stdout


def test_run_stream_on_ros_topics_and_max_duration(ros_graph, ros_probe, tmp_path):
    slow = world(tmp_path, "crawl.yaml", speed=0.25)  # the kitchen is a minute away
    start_sim_module(ros_graph, "navigation", slow)
    start_sim_module(ros_graph, "speech")
    topics = ("tree", "status", "calls", "events", "blackboard", "end")
    got = {c: ros_probe.collect("/bmtree/run/" + c) for c in topics}
    log = tmp_path / "stream.jsonl"
    try:
        out = bmtree("run", GO, "-q", "--max-duration", "3", "--record", str(log), env=dict(os.environ))
        assert out.returncode == 1, out.stdout + out.stderr
        assert "reason: stopped after 3 s while 'go to the kitchen' was running" in out.stdout
        end = json.loads(got["end"].wait_for(lambda t: True, 20)[0])
        assert end["v"] == 1 and end["status"] == "FAILURE" and end["reason"] == "stopped after 3 s while 'go to the kitchen' was running"
        tree = json.loads(got["tree"].wait_for(lambda t: True, 20)[0])
        assert tree["name"] == "go_kitchen" and tree["run"] == end["run"]
        node = next(n for n in tree["nodes"] if n["name"] == "go to the kitchen")
        assert node["kind"] == "call" and node["line"] == 12 and node["file"].endswith("go_kitchen.yaml")
        calls = [json.loads(t) for t in got["calls"].wait_for(lambda t: '"call_end"' in t, 20, count=2)]
        assert calls[0]["target"] == "speech.say" and calls[0]["status"] == "succeeded"
        assert calls[1]["target"] == "navigation.go_to" and calls[1]["status"] == "halted"
        starts = [json.loads(t) for t in got["calls"].wait_for(lambda t: '"call_start"' in t, 20, count=2)]
        assert starts[1]["inputs"] == {"place": "kitchen"} and starts[1]["node"] == node["id"]
        ticks = [json.loads(t) for t in got["status"].items]
        running = [c for t in ticks for c in t["changes"] if c[0] == node["id"]]
        assert running[0][1] == "RUNNING"
        assert all(t["changes"] for t in ticks)
        # the log holds the same records as the topics
        logged = read_log(str(log)).records
        published = [json.loads(t) for c in topics for t in got[c].items]
        assert sorted(json.dumps(r, sort_keys=True) for r in logged) == sorted(
            json.dumps(r, sort_keys=True) for r in published)
    finally:
        for c in got.values():
            ros_probe.close_collector(c)


def _run_then_kill(tree, log, *signals):
    """``bmtree run TREE --record LOG``; for each ``(n, signal)``, once the log shows ``n`` call starts,
    the signal (the last one SIGKILL)."""
    proc = subprocess.Popen(bmtree_cmd("run", tree, "-q", "--record", str(log)), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=dict(os.environ), stdin=subprocess.DEVNULL)
    try:
        for n, sig in signals:
            end = time.monotonic() + 60
            while not (log.exists() and sum('"call_start"' in line for line in log.read_text().splitlines()) >= n):
                assert proc.poll() is None, "bmtree run ended early"
                assert time.monotonic() < end, "the log never showed %d call starts" % n
                time.sleep(0.05)
            proc.send_signal(sig)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)


def test_a_run_killed_with_kill_9_leaves_a_readable_log(ros_graph, tmp_path):
    slow = world(tmp_path, "crawl.yaml", speed=0.25)
    start_sim_module(ros_graph, "navigation", slow)
    start_sim_module(ros_graph, "speech")
    runs = tmp_path / "runs"
    runs.mkdir()
    log = runs / "20260101-000000-abcdef-go_kitchen.jsonl"
    _run_then_kill(GO, log, (2, signal.SIGKILL))   # once the drive started
    run = read_log(str(log))
    assert run.end is None
    assert [r["target"] for r in run.of_type("call_start")] == ["speech.say", "navigation.go_to"]
    # a record cut in the middle (the process died while writing) is dropped, the rest reads
    with open(str(log), "a") as fh:
        fh.write('{"v":1,"type":"tick","run":"x","t":9.5,"n":99,"chan')
    cut = read_log(str(log))
    assert cut.truncated and len(cut.records) == len(run.records)
    env = dict(os.environ)
    listed = bmtree("runs", "--dir", str(runs), env=env)
    assert "UNFINISHED" in listed.stdout and "killed?" in listed.stdout
    shown = bmtree("replay", str(log), env=env)
    assert shown.returncode == 0 and "go_kitchen: UNFINISHED: last seen alive at" in shown.stdout, \
        shown.stdout + shown.stderr
    assert "that record was cut), and the log has no end: the process was killed?" in shown.stdout, shown.stdout
    assert "RUNNING   go to the kitchen" in shown.stdout
    # the killed run as a test: the same calls until its last tick, the navigation still running
    scenario = str(tmp_path / "killed.yaml")
    made = bmtree("replay", str(log), "--scenario", scenario, env=env)
    assert made.returncode == 0, made.stdout + made.stderr
    assert "it was killed" in open(scenario).read()
    passed = bmtree("test", scenario, env=env)
    assert passed.returncode == 0 and "1 passed, 0 failed" in passed.stdout, passed.stdout + passed.stderr


CLEANUP_TREE = """format: 1
name: go_back
root:
  call: navigation.go_to
  name: go to the kitchen
  inputs: {place: kitchen}
  timeout: 60
cleanup:
  sequence:
    - call: speech.say
      inputs: {text: "{ended}: {ended_reason}"}
    - call: navigation.go_to
      name: back to the charger
      inputs: {place: living_room}
      timeout: 60
"""




def test_a_run_killed_with_kill_9_during_its_cleanup_replays_as_a_scenario_that_ends_there(ros_graph, tmp_path):
    """Ctrl-C stops root (the drive), the cleanup speaks and drives back, kill -9 during that drive: the
    scenario stops root when the run did, runs the cleanup until the log ends, and passes."""
    slow = world(tmp_path, "crawl.yaml", speed=0.25)
    start_sim_module(ros_graph, "navigation", slow)
    start_sim_module(ros_graph, "speech")
    tree = tmp_path / "go_back.yaml"
    tree.write_text(CLEANUP_TREE)
    log = tmp_path / "run.jsonl"
    # Ctrl-C once the drive started (root stops, the cleanup runs), kill -9 once the drive back started
    _run_then_kill(str(tree), log, (1, signal.SIGINT), (3, signal.SIGKILL))
    run = read_log(str(log))
    assert run.end is None
    assert [r["target"] for r in run.of_type("call_start")] == ["navigation.go_to", "speech.say", "navigation.go_to"]
    scenario = str(tmp_path / "killed.yaml")
    env = dict(os.environ)
    made = bmtree("replay", str(log), "--scenario", scenario, env=env)
    assert made.returncode == 0, made.stdout + made.stderr
    text = open(scenario).read()
    data = yaml.safe_load(text)["scenarios"][0]
    assert data["max_duration"] < data["killed_at"], text     # root stopped first, the cleanup cut later
    assert data["expect"]["status"] == "failure" and "cleanup" not in data["expect"], text
    said = data["expect"]["calls"][1]["speech.say"]["text"]
    assert said.startswith("stopped: stopped after %g s while 'go to the kitchen' was running" % data["max_duration"])
    assert "# It was killed at" in text and "while the cleanup ran" in text
    passed = bmtree("test", scenario, env=env)
    assert passed.returncode == 0 and "1 passed, 0 failed" in passed.stdout, passed.stdout + passed.stderr
