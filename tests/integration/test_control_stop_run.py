"""``bmtree control stop`` against a real ``bmtree run --sim --control``: another process preempts the
task (SMACH's ``request_preempt``): root halted, its call cancelled, the cleanup run with ``ended`` =
stopped and the reason naming who stopped it, a second stop during the cleanup refused, exit 1 as a
``--max-duration`` stop, all of it in the run log."""
from __future__ import annotations

from coordinator.runlog import read_log
from tests.integration.test_control import ok, refused
from tests.integration.watchkit import SimRun, slow_world

TREE = """format: 1
name: errand
inputs:
  released: {default: false}
root:
  sequence:
    - call: speech.say
      inputs: {text: "I am going to the kitchen."}
    - call: navigation.go_to
      name: go to the kitchen
      inputs: {place: kitchen}
      timeout: 120
cleanup:
  sequence:
    - call: speech.say
      name: say how it ended
      inputs: {text: "{ended}: {ended_reason}"}
    - repeat: 600
      until: released
      child: {wait: 0.1}
cleanup_timeout: 60
"""


def test_a_stop_from_another_process_preempts_the_task_and_the_cleanup_runs(tmp_path):
    tree = tmp_path / "errand.yaml"
    tree.write_text(TREE)
    run = SimRun(tmp_path, tree=str(tree), world=slow_world(tmp_path, speed=0.2), extra=("--control",))
    try:
        run.out.wait_for("RUNNING   go to the kitchen")
        assert "stopping: root is halted and its calls cancelled, then the cleanup runs (at most 60 s)" in ok(run, "stop")
        run.out.wait_for("running the cleanup")
        again = refused(run, "stop")
        assert "root was stopped already (stopped by control (/bmtree_control" in again
        assert "a stop does not cut the cleanup short" in again
        # the cleanup goes on until the test lets it end (a loaded machine may take seconds to start a command)
        assert "released = true" in ok(run, "set", "released", "true")
        assert run.finish() == 1, run.out.text()   # as a --max-duration stop: the task was not done
        out = run.out.all_text()
        assert "errand: FAILURE in" in out
        assert "reason: stopped by control (/bmtree_control" in out and "while 'go to the kitchen' was running" in out
        assert "cleanup (root stopped): succeeded" in out
        log = read_log(run.out.wait_for("run log: ").split(": ", 1)[1])
        assert [(r["command"], r["ok"]) for r in log.of_type("control")] == [("stop", True), ("stop", False), ("set", True)]
        assert all(r["by"].startswith("/bmtree_control") for r in log.of_type("control"))
        assert log.end["status"] == "FAILURE" and log.end["reason"].startswith("stopped by control (/bmtree_control")
        halted = [r for r in log.of_type("call_end") if r.get("target") == "navigation.go_to"]
        assert [r["status"] for r in halted] == ["halted"]
        said = [r["inputs"]["text"] for r in log.of_type("call_start") if r["target"] == "speech.say"]
        assert said[1].startswith("stopped: stopped by control (/bmtree_control") and said[1].endswith(
            "while 'go to the kitchen' was running")
    finally:
        run.close()


SHARED = """format: 1
name: shared
root:
  sequence:
    - call: speech.say
      inputs: {text: "I am going to the kitchen."}
    - call: navigation.go_to
      name: go to the kitchen
      inputs: {place: kitchen}
      timeout: 120
    - call: speech.say
      inputs: {text: "I am in the kitchen."}
"""


def test_the_viewers_refuse_a_shared_name_in_full_and_the_page_stops_the_run(tmp_path):
    """The terminal's footer shows the whole refusal of a shared name (80×24), the page offers each such
    node by its NAME@ID, and its Stop button (confirmed) stops the run."""
    from tests.integration.test_control import _close
    from tests.integration.test_watch_terminal import Tmux, _cmd
    from tests.integration.test_watch_web import browser, start_web, text, wait_until

    tree = tmp_path / "shared.yaml"
    tree.write_text(SHARED)
    driver = browser(tmp_path)
    run = SimRun(tmp_path, tree=str(tree), world=slow_world(tmp_path, speed=0.2), extra=("--control",))
    term = web = None
    try:
        run.out.wait_for("RUNNING   go to the kitchen")
        term = Tmux(tmp_path, "names", 80, 24, _cmd("watch", "--wait", "60"), run.env)
        term.wait_screen("go to the kitchen", "stop, break NODE")
        term.tmux("send-keys", "-t", term.name, ":force speech.say SUCCESS", "Enter")
        shown = " ".join(term.wait_screen("refused: 2 nodes are named 'speech.say'").split())   # wrapped: as words
        assert ("speech.say@1 (shared.yaml:5, in sequence), speech.say@3 (shared.yaml:11, in sequence); say which "
                "one by its id (force speech.say@1 SUCCESS), or give them names of their own (name: in the tree)"
                in shown), shown   # before: cut at the width
        web, _out, url = start_web("watch", "--web", "--wait", "60", env=run.env)
        driver.get(url)
        wait_until(driver, lambda d: d.find_element("id", "controls").is_displayed())
        values = driver.execute_script("return [...document.querySelectorAll('#node option')].map(o=>o.value)")
        assert "speech.say@1" in values and "speech.say@3" in values and "go to the kitchen" in values, values
        driver.find_element("id", "stop").click()
        driver.switch_to.alert.accept()
        wait_until(driver, lambda d: text(d, "answer").startswith("ok: stopping"))
        wait_until(driver, lambda d: "result: FAILURE" in text(d, "result"))
        assert run.finish() == 1, run.out.text()
        assert "reason: stopped by control (/bmtree_watch" in run.out.all_text()
    finally:
        _close(driver, web, term, run)
