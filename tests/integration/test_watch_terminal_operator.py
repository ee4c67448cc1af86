"""``bmtree watch`` in a real terminal (tmux) while a second run starts on the same master and the
run it shows is then killed outright: the view stays on its run with a notice of the other one,
its keys steer that run only, and once the watch has ended, the normal screen (not the alternate one, which went with the view)
keeps the end, the whole reason and the call the killed run may have left running."""
from __future__ import annotations

import re
import shlex
import signal
import subprocess
import time

from tests.integration.conftest import bmtree_cmd
from tests.integration.faultkit import PROBE_JSON
from tests.integration.test_watch_terminal import Tmux, _cmd
from tests.integration.watchkit import Lines

FIRST = """format: 1
name: huge
root:
  sequence:
    name: errand
    children:
      - call: probe.echo
        name: say hello
        inputs: {tag: hello}
      - call: probe.work
        name: long work
        inputs: {seconds: 120.0, tag: a}
        timeout: 200
"""
SECOND = "format: 1\nname: find_apple\nroot:\n  wait: 60\n  name: wait a minute\n"


def _start(env, tmp_path, name, text, *extra):
    path = tmp_path / name
    path.write_text(text)
    proc = subprocess.Popen(bmtree_cmd("run", str(path), "--modules", PROBE_JSON, *extra), env=env, text=True,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    return proc, Lines(proc.stdout)


def test_a_second_run_and_a_killed_run_in_a_real_terminal(own_graph, tmp_path):
    own_graph.start_node(["-m", "modules.node", "--definition", PROBE_JSON, "--class",
                          PROBE_JSON.replace("probe.json", "probe_module.py") + ":Probe"], "/bm_probe")
    env = dict(own_graph.env, ROS_HOME=str(tmp_path / "home"))
    first, out = _start(env, tmp_path, "huge.yaml", FIRST, "--control")
    second = term = None
    try:
        out.wait_for("RUNNING   long work")
        time.sleep(1.0)  # the watch attaches a second into the call: it catches up from a snapshot of then
        command = "sh -c %s" % shlex.quote('%s; echo "[watch exited $?]"' % _cmd("watch", "--wait", "30"))
        term = Tmux(tmp_path, "op", 80, 24, command, env)
        term.wait_screen("bmtree watch huge", "long work  RUNNING", "probe.work")
        second, out2 = _start(env, tmp_path, "apple.yaml", SECOND)
        out2.wait_for("RUNNING   wait a minute")
        shown = term.wait_screen("another run started: find_apple (bmtree watch --run")
        assert shown.split("\n")[0].startswith("bmtree watch huge"), shown  # it stayed on its run
        assert "wait a minute" not in shown
        # its keys steer the run it shows, not the other one (which takes no commands and would refuse)
        term.tmux("send-keys", "-t", term.name, "p")
        shown = term.wait_screen("PAUSED", "ok: paused")
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        term.wait_screen("[watch exited 3]", timeout=30)
        history = term.tmux("capture-pane", "-p", "-S", "-1000", "-t", term.name).stdout
        after = history[history.rindex("bmtree watch huge"):]  # the last frame, left on the normal screen
        print(after)
        assert "result: UNFINISHED, gone at about" in after, history
        reason = " ".join(after[after.index("reason: "):].split())
        said = re.search(r"reason: the run \(pid %d, node /bmtree_\S+\) is gone, its last tick \(2\) at (\d+\.\d+)s "
                         r"\(\d\d:\d\d:\d\d\), found gone at about (\d+\.\d)s: its process ended; it did not stop "
                         r"its calls" % first.pid, reason)
        assert said, reason
        # the time of the tick (the echo's answer), not of the catch-up, a second later at least
        assert float(said.group(1)) < 1.0 <= float(said.group(2)), reason
        assert "maybe still running (run gone): probe.work since" in after and "'long work'" in after
        assert "the run did not finish (exit 3)" in after
        assert "bmtree watch --run" in after  # the other run, and how to watch it
        assert "Traceback" not in history
    finally:
        if term is not None:
            term.close()
        for proc in (first, second):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(30)
                except subprocess.TimeoutExpired:
                    proc.kill()
