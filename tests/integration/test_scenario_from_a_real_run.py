"""A scenario from a real run (a module of one's own as a process, `bmtree run --sim --module`)
reproduces the run on the unchanged tree: an event keeps its place among the calls, and a time
input is written as {secs, nsecs} and matches."""
from __future__ import annotations

import json
import os
import subprocess

import yaml

from tests.integration.conftest import bmtree_cmd

DEFINITION = {
    "Basic Module": "my", "Brief Description": "emits an event, then answers", "Hardware Required": [],
    "Functions": [
        {"Name": "fire", "Exec-condition": "", "Description": "emit done, then answer",
         "Input-params": [{"Name": "deadline", "Data-type": "std_msgs/Time", "Description": ""}],
         "Output-params": []},
        {"Name": "noop", "Exec-condition": "", "Description": "nothing", "Input-params": [], "Output-params": []}],
    "Events": [{"Name": "done", "Description": "fired", "Event-params": []}],
}

MODULE = '''from modules import BasicModule


class My(BasicModule):
    def fire(self, deadline):
        self.emit("done")
        self.context.sleep(0.2)  # ROS orders per topic only: the event surely arrives before the answer
        return {}

    def noop(self):
        return {}
'''


def bmtree(*args, env, timeout=120):
    return subprocess.run(bmtree_cmd(*args), capture_output=True, text=True, timeout=timeout, env=env,
                          stdin=subprocess.DEVNULL)


def test_an_event_emitted_before_an_answer_stays_before_the_wait_after_twenty_calls(tmp_path):
    env = dict(os.environ, ROS_HOME=str(tmp_path / "home"))
    (tmp_path / "my.json").write_text(json.dumps(DEFINITION))
    (tmp_path / "my.py").write_text(MODULE)
    tree = ["format: 1", "name: drift", "root:", "  sequence:"] + ["    - call: my.noop"] * 20 + [
        "    - call: my.fire", "      inputs: {deadline: {secs: 100, nsecs: 0}}",
        "    - timeout: 1", "      child:", "        wait_event: my.done"]
    (tmp_path / "tree.yaml").write_text("\n".join(tree) + "\n")
    log = str(tmp_path / "run.jsonl")

    ran = bmtree("run", "--sim", "--module", "%s=%s:My" % (tmp_path / "my.json", tmp_path / "my.py"),
                 "--record", log, str(tmp_path / "tree.yaml"), env=env)
    # the event came before fire's answer, so the wait_event after it never saw it
    assert ran.returncode == 1, ran.stdout + ran.stderr
    assert "timed out after 1s while 'my.done' was running" in ran.stdout, ran.stdout

    scenario = str(tmp_path / "regression.yaml")
    made = bmtree("replay", log, "--scenario", scenario, env=env)
    assert made.returncode == 0, made.stdout + made.stderr
    tested = bmtree("test", "--modules", str(tmp_path / "my.json"), scenario, env=env)
    assert tested.returncode == 0, tested.stdout + tested.stderr
    assert "PASS" in tested.stdout and "1 passed, 0 failed" in tested.stdout

    written = yaml.safe_load(open(scenario))["scenarios"][0]
    assert [{k: v for k, v in ev.items() if k != "at"} for ev in written["events"]] == [
        {"event": "my.done", "after": "my.fire"}]
    assert written["expect"]["calls"][20] == {"my.fire": {"deadline": {"secs": 100, "nsecs": 0}}}
