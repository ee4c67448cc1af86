"""A module left stuck by an earlier run: a non-concurrent function whose code ignored its cancel still
runs. The next run's preflight ping says so at start (a warning naming the call, how long ago it was
cancelled and that a restart frees the module), and its call is refused with the same words at once."""
from __future__ import annotations

import json
import os
import re
import subprocess

from tests.integration.conftest import bmtree_cmd, wait_announced

STUCK_PY = '''
import time

from modules import BasicModule


class Stuck(BasicModule):
    def grip(self):
        end = time.monotonic() + 60
        while time.monotonic() < end:   # never looks at its cancel
            time.sleep(0.05)
        return {}

    def status(self):
        return {}
'''


def _definition(path):
    fn = {"Exec-condition": "", "Description": "d", "Input-params": [], "Output-params": []}
    path.write_text(json.dumps({"Basic Module": "stuckarm", "Brief Description": "An arm whose grip ignores cancels.",
                                "Hardware Required": [], "Functions": [dict(fn, Name="grip"), dict(fn, Name="status")]}))


def _run(tmp_path, body):
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n" + body)
    return subprocess.run(bmtree_cmd("run", "-q", "--no-record", "--modules", str(tmp_path / "stuckarm.json"),
                                     str(tree)), capture_output=True, text=True, timeout=120, env=dict(os.environ),
                          stdin=subprocess.DEVNULL)


def test_the_next_run_is_told_at_start_that_an_earlier_runs_call_holds_the_module(ros_graph, tmp_path):
    _definition(tmp_path / "stuckarm.json")
    (tmp_path / "stuck.py").write_text(STUCK_PY)
    ros_graph.start_node(["-m", "modules.node", "--definition", str(tmp_path / "stuckarm.json"), "--class",
                          str(tmp_path / "stuck.py") + ":Stuck"], "/bm_stuckarm")
    wait_announced("stuckarm")
    first = _run(tmp_path, "  call: stuckarm.grip\n  timeout: 0.5\n")
    assert first.returncode == 1 and "no answer within 0.5s" in first.stdout, first.stdout + first.stderr
    # the run waited for the answer to its cancel: the module says the code goes on (not "cancelled")
    assert "may still be running: its module says its code has not returned after 1s: it goes on running" \
        in first.stdout, first.stdout
    assert "warning: module stuckarm" not in first.stderr, first.stderr
    second = _run(tmp_path, "  call: stuckarm.status\n")
    said = (r"busy with call \w+ \(grip\): it was cancelled (\d+\.\d) s ago and its code has not returned; stuckarm "
            r"refuses calls until it does, or until its node is restarted")
    warned = re.search(r"warning: module stuckarm: " + said, second.stderr)
    assert warned and float(warned.group(1)) >= 1.0, second.stdout + second.stderr  # the grace (1 s) is long over
    assert second.returncode == 1 and re.search(r"rejected\s+\S+\s+" + said, second.stdout), second.stdout
