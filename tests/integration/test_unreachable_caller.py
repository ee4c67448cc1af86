"""A module told ``--unreachable-caller S`` cancels the call of a coordinator that has not answered for S seconds,
with real processes: ``bmtree run`` is stopped with SIGSTOP mid-call (as a hung laptop, or one whose link dropped,
looks from the robot: its node answers nothing).

Before, a module went on with such a call for ever: only a caller whose process was found gone had its calls
cancelled, and a dropped link is no process gone. Now the function's ``context.sleep`` returns False, its code
after it ("stop the motors") runs, the module's log says why, and the run, once it runs again, gets the
``cancelled`` answer saying why. Without the option nothing changes (the call goes on; a unit test covers it).
"""
from __future__ import annotations

import json
import re
import signal

from tests.conftest import until
from tests.integration.test_module_stop_midcall import _Run, _setup


def test_the_call_of_a_coordinator_that_stopped_answering_is_cancelled_and_said_why(tmp_path, ros_graph):
    _proc, definition, marker = _setup(tmp_path, ros_graph, "--unreachable-caller", "2")
    run = _Run(tmp_path, definition, "stopper.work\n  inputs: {seconds: 30}")
    log = ros_graph.log_path("/bm_stopper")
    try:
        assert run.wait_line("RUNNING", "stopper.work"), "".join(run.lines)
        run.proc.send_signal(signal.SIGSTOP)
        try:
            until(lambda: marker.exists() and "motors stopped" in marker.read_text(), timeout=20.0)
        finally:
            run.proc.send_signal(signal.SIGCONT)
        text = run.end()
    finally:
        if run.proc.poll() is None:
            run.proc.send_signal(signal.SIGCONT)
    assert marker.read_text() == "work: sleep returned False, cancelled True; motors stopped\n"
    said = open(log).read()
    assert "; cancels the calls of a caller that has not answered for 2 s (unreachable_caller)" in said, said
    assert re.search(r"cancelled call \w+ of module stopper: its caller /bmtree_\w+ has not answered for [2-9]s "
                     r"\(its machine cannot be reached, or its process is stopped\)", said), said
    assert run.proc.returncode == 1, text
    assert re.search(r"stopper.work cancelled: its caller /bmtree_\w+ has not answered for [2-9]s \(its machine "
                     r"cannot be reached, or its process is stopped\), and module stopper cancels a call when that lasts 2s "
                     r"\(unreachable_caller\)", text), text


def test_a_bad_unreachable_caller_is_refused_at_start(tmp_path):
    import subprocess
    import sys

    definition = tmp_path / "m.json"
    definition.write_text(json.dumps({"Basic Module": "m", "Brief Description": "", "Hardware Required": [],
                                      "Functions": []}))
    got = subprocess.run([sys.executable, "-m", "modules.node", "--definition", str(definition), "--class",
                          "x.py:X", "--unreachable-caller", "0.2"], capture_output=True, text=True, timeout=60)
    assert got.returncode == 2, got.stderr
    assert "expected 0 (never) or at least 1 seconds, got 0.2" in got.stderr and "Traceback" not in got.stderr


def test_the_simulated_modules_take_the_option_too(tmp_path):
    """The README says python -m modules.sim takes it: it refused it (unrecognized arguments)."""
    import subprocess
    import sys

    got = subprocess.run([sys.executable, "-m", "modules.sim", "vision", "--unreachable-caller", "0.2"],
                         capture_output=True, text=True, timeout=60)
    assert got.returncode == 2, got.stderr
    assert "expected 0 (never) or at least 1 seconds, got 0.2" in got.stderr and "unrecognized" not in got.stderr
