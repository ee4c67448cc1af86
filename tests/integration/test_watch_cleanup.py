"""``bmtree watch`` (a real tmux terminal, and ``--web`` in headless chromium) of a ``bmtree run --sim``
of a tree with ``cleanup:``, stopped with Ctrl-C (SIGINT) while root drives: root halted, the cleanup
running (its pending calls said to be the cleanup's), then ending; the notices, and the end line with
the run's result (root's, ``INTERRUPTED``) and the cleanup's own; root's call the Ctrl-C halted said
``interrupted`` and the top node ``INTERRUPTED``, as ``bmtree run`` says them. Then ``bmtree replay`` of
that run."""
from __future__ import annotations

import signal
import subprocess

from tests.integration.conftest import bmtree_cmd
from tests.integration.test_watch_terminal import Tmux, _cmd
from tests.integration.test_watch_web import browser, node_status, start_web, stop, text, wait_until
from tests.integration.watchkit import SimRun, slow_world

TREE = """format: 1
name: go_and_back
root:
  sequence:
    name: errand
    children:
      - call: navigation.go_to
        name: drive
        inputs: {place: kitchen}
        timeout: 60
      - call: speech.say
        inputs: {text: arrived}
cleanup:
  sequence:
    children:
      - call: speech.say
        name: say why
        inputs: {text: "I was {ended}."}
      - call: navigation.go_to
        name: go back
        inputs: {place: living_room}
        timeout: 60
cleanup_timeout: 60
"""


def test_watch_and_the_page_show_a_cleanup_after_ctrl_c_and_replay_lists_it(tmp_path):
    tree = tmp_path / "go_and_back.yaml"
    tree.write_text(TREE)
    driver = browser(tmp_path)
    run = SimRun(tmp_path, tree=str(tree), world=slow_world(tmp_path, speed=0.3))
    term = web = None
    try:
        run.out.wait_for("RUNNING   drive")
        term = Tmux(tmp_path, "cleanup", 120, 40, _cmd("watch", "--wait", "60"), run.env)
        web, out, url = start_web("watch", "--web", "--wait", "60", env=run.env)
        driver.get(url)
        shown = term.wait_screen("drive  RUNNING", "go_and_back [with_cleanup]")
        wait_until(driver, lambda d: node_status(d, "drive") == "RUNNING")
        assert node_status(driver, "go_and_back") == "RUNNING" and node_status(driver, "cleanup") == "IDLE"
        run.proc.send_signal(signal.SIGINT)   # Ctrl-C: root halted, then the cleanup runs
        # the cleanup drives back: its pending call is the cleanup's, root's drive was halted
        shown = term.wait_screen("go back  RUNNING", "pending calls of the cleanup (root stopped)")
        assert "~ drive  HALTED" in shown and "running the cleanup" in shown, shown
        # root's call the Ctrl-C halted: "interrupted" in the call log, as the run's summary says it
        shown = term.wait_screen("navigation.go_to interrupted")
        assert "halted by the tree" not in shown, shown
        wait_until(driver, lambda d: node_status(d, "go back") == "RUNNING")
        wait_until(driver, lambda d: text(d, "pendingh") == "pending calls of the cleanup (root stopped)")
        assert node_status(driver, "drive") == "HALTED" and "navigation.go_to" in text(driver, "pending")
        events = driver.execute_script(
            "return [...document.querySelectorAll('#events tr')].map(r => r.textContent)")
        # (a row's text is its cells': time, what it is about, the notice)
        assert any("scleanupinterrupted while 'drive' was running: running the cleanup" in e for e in events), events
        assert not any("ROS graph" in e for e in events), events
        # the end: the run's result is root's, the cleanup's own is said beside it
        assert run.finish() == 3, run.out.text()
        assert "go_and_back: INTERRUPTED in" in run.out.text() and "cleanup (root stopped): succeeded in" in run.out.text()
        wait_until(driver, lambda d: "result: INTERRUPTED" in text(d, "result"))
        assert "cleanup (root stopped): succeeded in" in text(driver, "result"), text(driver, "result")
        assert node_status(driver, "cleanup") == "SUCCESS" and text(driver, "pendingh") == "pending calls"
        # the top node stands for the run; root's call the Ctrl-C halted is said so, not "halted by the tree"
        wait_until(driver, lambda d: node_status(d, "go_and_back") == "INTERRUPTED")
        assert node_status(driver, "errand") == "HALTED"
        calls = driver.execute_script("return [...document.querySelectorAll('#calls tr')].map(r => r.textContent)")
        assert any("navigation.go_tointerrupted" in c for c in calls), calls
        assert not any("halted by the tree" in c for c in calls), calls
        assert web.wait(30) == 0, out.text()
        history = term.wait_screen("result: INTERRUPTED", "cleanup (root stopped): succeeded in", timeout=60)
        assert "reason: interrupted while 'drive' was running" in history, history
        assert "go_and_back [with_cleanup]  INTERRUPTED" in history and "halted by the tree" not in history, history
        assert any("navigation.go_to" in line and " interrupted " in line for line in history.splitlines()), history
        assert "Traceback" not in out.all_text()
        # replay: the cleanup's notices under their own heading, not the ROS graph's
        replay = subprocess.run(bmtree_cmd("replay", "last"), capture_output=True, text=True, env=run.env, timeout=60)
        assert replay.returncode == 0, replay.stderr
        assert "go_and_back: INTERRUPTED in" in replay.stdout
        assert "the cleanup:\n" in replay.stdout and "the ROS graph:" not in replay.stdout, replay.stdout
        assert "cleanup (root stopped): succeeded in" in replay.stdout
        assert "navigation.go_to           interrupted" in replay.stdout, replay.stdout
    finally:
        driver.quit()
        if web is not None:
            stop(web)
        if term is not None:
            term.close()
        run.close()
