"""A module author's mistakes on a real module node: a function that calls ``sys.exit`` answers
``failed`` and the node keeps serving; a ``setup`` that raises is one line, exit 2."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

from modules.definition import parse_definition
from tests.unit.test_module_mistakes import DEFINITION as PROBE

DEFINITION = dict(PROBE, **{"Basic Module": "mistakes"})  # no other test's module of that name

CLASS = '''import os, sys
from modules import BasicModule

class Probe(BasicModule):
    def setup(self, node):
        if os.environ.get("PROBE_SETUP") == "broken":
            raise RuntimeError("no driver")

    def f(self, mode):
        if mode.data == "exit":
            sys.exit(3)
        return {"x": 1.0, "s": "ok"}

    def wait(self):
        return {}
'''


def _files(tmp_path):
    (tmp_path / "mistakes.json").write_text(json.dumps(DEFINITION))
    (tmp_path / "probe_class.py").write_text(CLASS)
    return ["-m", "modules.node", "--definition", str(tmp_path / "mistakes.json"), "--class",
            str(tmp_path / "probe_class.py") + ":Probe"]


def test_a_function_that_exits_fails_its_call_and_a_setup_that_raises_is_exit_2(ros_graph, caller_factory,
                                                                                 ros_master, tmp_path):
    args = _files(tmp_path)
    out = subprocess.run([sys.executable, *args, "__name:=bm_mistakes_setup"], capture_output=True, text=True, timeout=60,
                         stdin=subprocess.DEVNULL, env=dict(os.environ, ROS_MASTER_URI=ros_master, PROBE_SETUP="broken"))
    assert out.returncode == 2, out.stdout + out.stderr
    assert out.stderr.strip().splitlines()[-1] == \
        "error: Probe.setup raised RuntimeError: no driver (probe_class.py:7 in setup)", out.stderr
    assert "Traceback" not in out.stderr

    node = ros_graph.start_node(args, "/bm_mistakes")
    caller = caller_factory(nodes=["/bm_mistakes"], answering=["mistakes"])
    defs = {"mistakes": parse_definition(DEFINITION, "mistakes.json")}
    r = caller.call(defs, "mistakes.f", mode="exit")
    assert (r.status, r.error) == ("failed", "SystemExit: 3 (probe_class.py:11 in f)")
    assert caller.call(defs, "mistakes.f", mode="again").status == "succeeded"  # not left busy
    assert node.poll() is None
    node.send_signal(signal.SIGINT)
    assert node.wait(15) == 0

