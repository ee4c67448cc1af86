"""Steering a real ``bmtree run --sim --control`` with ``bmtree control``: each command's effect
seen on the run stream (a ``bmtree watch --plain`` beside it) and in the run log; bad commands
and a run without --control refuse and change nothing."""
from __future__ import annotations

import os
import re
import subprocess

import rosgraph

from coordinator.runlog import read_log
from tests.conftest import DATA, until
from tests.integration.conftest import bmtree_cmd
from tests.integration.watchkit import Lines, SimRun, slow_world

STEERED = os.path.join(DATA, "watch", "go_kitchen_steered.yaml")


def control(run, *words):
    return subprocess.run(bmtree_cmd("control", *words, "--wait", "60"), capture_output=True, text=True,
                          env=run.env, timeout=120, stdin=subprocess.DEVNULL)


def ok(run, *words):
    out = control(run, *words)
    assert out.returncode == 0, out.stdout + out.stderr
    return out.stdout


def refused(run, *words):
    out = control(run, *words)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "Traceback" not in out.stderr
    return out.stderr


def test_each_command_steers_the_run_and_is_logged(tmp_path):
    run = SimRun(tmp_path, tree=STEERED, world=slow_world(tmp_path, speed=0.4), extra=("--control",))
    watch = None
    try:
        # the run says how to watch its private master (the watch below does just that)
        said = run.out.wait_for("to watch it from another terminal")
        assert "(to watch it from another terminal: ROS_MASTER_URI=%s bmtree watch)" % run.env["ROS_MASTER_URI"] in said
        run.out.wait_for("RUNNING   go to the kitchen")
        watch = subprocess.Popen(bmtree_cmd("watch", "--plain", "--wait", "60"), stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True, env=run.env)
        seen = Lines(watch.stdout)
        seen.wait_for("caught up at tick")
        assert "step works while paused" in refused(run, "step")
        state = rosgraph.Master("/test_control", master_uri=run.env["ROS_MASTER_URI"]).getSystemState()
        node = next(n for _topic, nodes in state[0] for n in nodes if n.startswith("/bmtree_") and
                    not n.startswith(("/bmtree_watch", "/bmtree_control")))
        # --node: a command for another run on the master is not this run's (no run of that node is there)
        other = subprocess.run(bmtree_cmd("control", "pause", "--node", "/bmtree_other", "--wait", "2"),
                               capture_output=True, text=True, env=run.env, timeout=60, stdin=subprocess.DEVNULL)
        assert other.returncode == 3, other.stdout + other.stderr
        assert "refused: no run of node /bmtree_other takes commands on this master (the runs on it: %s)" % node \
            in other.stderr, other.stderr
        assert "will pause before 'arrived' starts" in ok(run, "break", "arrived", "--node", node)
        # pause: the pending call goes on, but no node starts after it
        assert "paused" in ok(run, "pause")
        # bad commands: a clear answer, nothing changes
        assert "no node named 'nobody'" in refused(run, "force", "nobody", "SUCCESS")
        assert "an outcome is SUCCESS or FAILURE" in refused(run, "force", "done", "MAYBE")
        assert "no tree-blackboard key 'nokey'" in refused(run, "set", "nokey", "1")
        assert "text holds str; 5 is int" in refused(run, "set", "text", "5")
        seen.wait_for("event     navigation.arrived")  # the trip ended while paused
        # one tick: the trip's leaf ends, and the next leaf stops at its breakpoint
        assert "one tick" in ok(run, "step")
        seen.wait_for("succeeded navigation.go_to")  # its result is taken at that tick
        seen.wait_for("SUCCESS   go to the kitchen")
        seen.wait_for("control   breakpoint")
        assert "call      speech.say" not in seen.text().split("navigation.arrived")[1]
        # at the breakpoint: change what it will say, and force the last leaf to fail
        assert "text = \"changed by control\"" in ok(run, "set", "text", "changed by control")
        assert "'done' will end in FAILURE" in ok(run, "force", "done", "FAILURE")
        ok(run, "resume")
        seen.wait_for('call      speech.say {"text":"changed by control"}')
        seen.wait_for("FAILURE   done (forced to FAILURE by control)")
        seen.wait_for("end       FAILURE")
        assert run.finish() == 1, run.out.text()
        assert watch.wait(60) == 0
        # the summary says what control changed, each when it took effect and by whom
        steered = [line for line in run.out.text().splitlines() if line.startswith("steered: ")]
        assert len(steered) == 3 and re.search(r"paused \d+\.\d s by /bmtree_control", steered[0]) \
            and "blackboard text = \"changed by control\" by /bmtree_control" in steered[1] \
            and "'done' forced to FAILURE by /bmtree_control" in steered[2], run.out.text()
        # the run log says who did what
        log_path = run.out.wait_for("run log: ").split(": ", 1)[1]
        records = [r for r in read_log(log_path).records if r.get("type") == "control"]
        commands = [(r["command"], r["ok"]) for r in records]
        assert ("force", False) in commands and ("set", False) in commands
        assert ("pause", True) in commands and ("breakpoint", True) in commands and ("resume", True) in commands
        assert all(r["by"].startswith("/bmtree_control") for r in records if r["command"] != "breakpoint")
        says = [r for r in read_log(log_path).records if r.get("type") == "call_start" and r["target"] == "speech.say"]
        assert [s["inputs"]["text"] for s in says] == ["I am going to the kitchen.", "changed by control"]
    finally:
        if watch is not None and watch.poll() is None:
            watch.terminate()
            watch.wait(30)
        run.close()


def test_a_run_without_control_refuses_every_command(tmp_path):
    """... and the viewers do not offer commands it would refuse: the terminal's footer says why,
    the page has no control buttons."""
    from tests.integration.test_watch_terminal import Tmux, _cmd
    from tests.integration.test_watch_web import browser, start_web, text, wait_until

    driver = browser(tmp_path)
    # a 16 s drive: the control command, the terminal and the page join while it runs, also on a loaded machine
    run = SimRun(tmp_path, tree=STEERED, world=slow_world(tmp_path, speed=0.5))
    term = web = None
    try:
        run.out.wait_for("RUNNING   go to the kitchen")
        assert "control is not enabled for this run" in refused(run, "pause")
        term = Tmux(tmp_path, "nokeys", 100, 24, _cmd("watch", "--follow", "--wait", "60"), run.env)
        term.wait_screen("go to the kitchen", "this run takes no commands: it was started without --control")
        assert "p pause/resume" not in term.screen()
        web, _out, url = start_web("watch", "--web", "--follow", "--wait", "60", env=run.env)
        driver.get(url)
        wait_until(driver, lambda d: "go to the kitchen" in str(d.execute_script(
            "return [...document.querySelectorAll('#tree g.node title')].map(t=>t.textContent).join('|')")))
        assert not driver.find_element("id", "controls").is_displayed()
        assert run.finish() == 0, run.out.text()  # it ran on, unpaused
        wait_until(driver, lambda d: "result: SUCCESS" in text(d, "result"))
        assert not driver.find_element("id", "controls").is_displayed()
        log_path = run.out.wait_for("run log: ").split(": ", 1)[1]
        controls = [r for r in read_log(log_path).records if r.get("type") == "control"]
        assert [(r["command"], r["ok"]) for r in controls] == [("pause", False)]
    finally:
        _close(driver, web, term, run)


def _close(driver, web, term, run):
    """End what a viewer test started: the browser, the web watch, the terminal, the run."""
    from tests.integration.test_watch_web import stop

    driver.quit()
    if web is not None:
        stop(web)
    if term is not None:
        term.close()
    run.close()


def _clock(text: str) -> float:
    """The seconds of a view's clock, ``t=12.3s  tick 40`` or ``12.3s``."""
    return float(text.replace("t=", "").split()[0].rstrip("s"))


def test_keys_in_the_terminal_and_buttons_on_the_page(tmp_path):
    from tests.integration.test_watch_terminal import Tmux, _cmd
    from tests.integration.test_watch_web import browser, start_web, text, wait_until

    driver = browser(tmp_path)
    run = SimRun(tmp_path, tree=STEERED, world=slow_world(tmp_path, speed=0.4), extra=("--control",))
    term = web = None
    try:
        run.out.wait_for("RUNNING   go to the kitchen")
        term = Tmux(tmp_path, "keys", 80, 24, _cmd("watch", "--wait", "60"), run.env)
        term.wait_screen("go to the kitchen", "navigation.go_to", "q quit  p pause/resume  s step")
        term.tmux("send-keys", "-t", term.name, "p")
        term.wait_screen("PAUSED", "ok: paused")
        term.tmux("send-keys", "-t", term.name, ":force done FAILURE", "Enter")
        term.wait_screen("ok: 'done' will end in FAILURE")
        term.tmux("send-keys", "-t", term.name, ":set text 5", "Enter")
        term.wait_screen("refused: text holds str; 5 is int")
        web, _out, url = start_web("watch", "--web", "--wait", "60", env=run.env)
        driver.get(url)
        wait_until(driver, lambda d: d.find_element("id", "controls").is_displayed())
        wait_until(driver, lambda d: d.find_element("id", "paused").is_displayed())
        # the events panel says the commands as the terminal does (it showed {"node":"done",…} JSON, and a
        # refusal looked like a success)
        events = text(driver, "events")
        assert "control force 'done' FAILURE" in events and "refused: text holds str" in events, events
        refused = driver.execute_script("return [...document.querySelectorAll('#events tr.failed')]"
                                        ".map(r => r.textContent).join('|')")
        assert "control set 'text' 5" in refused and "force" not in refused, refused
        driver.find_element("id", "resume").click()
        wait_until(driver, lambda d: text(d, "answer") == "ok: resumed")
        wait_until(driver, lambda d: not d.find_element("id", "paused").is_displayed())
        wait_until(driver, lambda d: "result: FAILURE" in text(d, "result"), timeout=150)
        assert "steered: " in text(driver, "result") and "'done' forced to FAILURE by /bmtree_" in text(driver, "result")
        assert "forced to FAILURE by control" in text(driver, "events") + str(driver.execute_script(
            "return [...document.querySelectorAll('#tree g.node title')].map(t=>t.textContent).join('|')"))
        assert run.finish() == 1, run.out.text()
    finally:
        _close(driver, web, term, run)


QUIET = "format: 1\nname: quiet\nroot:\n  wait: 120\n"


def test_the_page_clock_counts_on_while_the_run_is_paused(tmp_path):
    """A paused run makes no records while it waits; its time goes on (calls would run on), and
    the page's clock counts it as the terminal's does (it used to stop at the last record)."""
    from tests.integration.test_watch_terminal import Tmux, _cmd
    from tests.integration.test_watch_web import browser, start_web, text, wait_until

    tree = tmp_path / "quiet.yaml"
    tree.write_text(QUIET)
    driver = browser(tmp_path)
    run = SimRun(tmp_path, tree=str(tree), extra=("--control",))
    term = web = None
    try:
        run.out.wait_for("RUNNING   wait 120")
        assert "paused" in ok(run, "pause")
        web, _out, url = start_web("watch", "--web", "--wait", "60", env=run.env)
        driver.get(url)
        wait_until(driver, lambda d: d.find_element("id", "paused").is_displayed())
        shown = _clock(text(driver, "clock"))
        wait_until(driver, lambda d: _clock(text(d, "clock")) >= shown + 1.5)
        assert driver.find_element("id", "paused").is_displayed()
        term = Tmux(tmp_path, "quiet", 80, 24, _cmd("watch", "--wait", "60"), run.env)
        shown = _clock(term.wait_screen("PAUSED").split("t=", 1)[1])
        until(lambda: _clock(term.screen().split("t=", 1)[1]) >= shown + 1.5, 30)
    finally:
        _close(driver, web, term, run)
