"""The web view in a real browser: headless Debian chromium driven by selenium, watching a
``bmtree run --sim`` on a slow world as it progresses, then the recorded run with its timeline.

Set BMTREE_SCREENSHOTS=DIR to keep the screenshots (docs/watch-web.png comes from here)."""
from __future__ import annotations

import os
import shutil
import signal
import subprocess

from tests.integration.conftest import bmtree_cmd
from tests.integration.watchkit import LONG_TREE, Lines, SimRun, ask_tree, slow_world


def browser(tmp_path):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for a in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run",
              "--disable-background-networking", "--disable-component-update", "--disable-sync",
              "--window-size=1600,1000", "--user-data-dir=%s" % (tmp_path / "chromium")):
        opts.add_argument(a)
    return webdriver.Chrome(service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"), options=opts)


def wait_until(driver, check, timeout=90):
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(driver, timeout, poll_frequency=0.2).until(lambda d: check(d))


def node_status(driver, name):
    found = driver.execute_script(
        "const g=[...document.querySelectorAll('#tree g.node')].find(e=>e.dataset.name===arguments[0]);"
        "return g ? g.dataset.status : null;", name)
    return found


def text(driver, element_id):
    """What an element shows (its text, also when it is scrolled out of view)."""
    return driver.execute_script("return document.getElementById(arguments[0]).textContent", element_id)


def keep(driver, tmp_path, name):
    path = str(tmp_path / name)
    driver.save_screenshot(path)
    where = os.environ.get("BMTREE_SCREENSHOTS")
    if where:
        shutil.copy(path, os.path.join(where, name))
    with open(path, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"


def start_web(*args, env):
    proc = subprocess.Popen(bmtree_cmd(*args, "--port", "0"), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, text=True, env=env)
    out = Lines(proc.stdout)
    url = out.wait_for("page at http://").split("page at ", 1)[1].split()[0]
    return proc, out, url


def stop(proc):
    if proc.poll() is None:
        proc.terminate()
        proc.wait(30)


def with_a_notice(env, tmp_path):
    """The newest run log of ``env``'s ROS_HOME, copied with a notice of a master restart put in."""
    import json

    from coordinator.replay import find_run

    path = find_run("last", os.path.join(env["ROS_HOME"], "bmtree", "runs"))
    records = [json.loads(line) for line in open(path)]
    notice = {"v": 1, "type": "notice", "run": records[0]["run"], "t": records[1]["t"], "what": "master_back",
              "text": "the ROS master at http://robot:11311/ answers again"}
    copy = tmp_path / "with_notice.jsonl"
    copy.write_text("".join(json.dumps(r) + "\n" for r in records[:1] + [notice] + records[1:]))
    return str(copy)


def test_the_page_follows_a_sim_run_and_scrubs_its_recording(tmp_path):
    driver = browser(tmp_path)  # first: its start-up is slow, the trip is not endless
    run = SimRun(tmp_path, tree=LONG_TREE, world=slow_world(tmp_path, speed=0.4))  # ~22 s of its 30
    web = None
    try:
        run.out.wait_for("RUNNING   go to the kitchen")
        web, out, url = start_web("watch", "--web", "--wait", "60", env=run.env)
        driver.get(url)
        wait_until(driver, lambda d: node_status(d, "go to the kitchen") == "RUNNING")
        assert text(driver, "title") == "long_errand"
        assert node_status(driver, "before 8") == "SUCCESS" and node_status(driver, "after 1") == "IDLE"
        wait_until(driver, lambda d: "navigation.go_to" in text(d, "pending"))
        assert "/ 30s" in text(driver, "pending")
        assert driver.find_elements("css selector", "path.edge.RUNNING")  # the running path is drawn
        assert "speech.say" in text(driver, "calls")
        keep(driver, tmp_path, "watch-web.png")
        # the page follows the run to its end without a reload
        wait_until(driver, lambda d: "result: SUCCESS" in text(d, "result"), timeout=150)
        assert node_status(driver, "after 8") == "SUCCESS" and node_status(driver, "long errand") == "SUCCESS"
        assert "none" == text(driver, "pending")
        # the watch ends with the run, as on a terminal, once the page has shown the result
        assert web.wait(30) == 0, out.text()
        assert "the run ended: SUCCESS" in out.all_text() and "Traceback" not in out.all_text()
        wait_until(driver, lambda d: d.find_element("id", "gone").is_displayed())
        assert "result: SUCCESS" in text(driver, "result") and node_status(driver, "after 8") == "SUCCESS"
        assert run.finish() == 0, run.out.text()

        env = dict(run.env)
        web, _out, url = start_web("replay", with_a_notice(env, tmp_path), "--web", env=env)
        driver.get(url)
        wait_until(driver, lambda d: d.find_element("id", "timeline").is_displayed())
        assert "result: SUCCESS" in text(driver, "result")
        assert "ROS graph" in text(driver, "events") and "master at http://robot:11311/ answers" in text(driver, "events")
        driver.execute_script("const s=document.getElementById('scrub'); s.value=s.max/2;"
                              "s.dispatchEvent(new Event('input'));")
        wait_until(driver, lambda d: node_status(d, "go to the kitchen") == "RUNNING")
        assert text(driver, "result") == ""
        assert node_status(driver, "after 1") == "IDLE"
        assert "navigation.go_to" in text(driver, "pending")
        keep(driver, tmp_path, "replay-web.png")
    finally:
        driver.quit()
        if web is not None:
            stop(web)
        run.close()


def test_a_reset_node_is_drawn_faded_with_its_last_outcome_and_ctrl_c_after_the_run_is_quiet(tmp_path):
    """A selector's failed child, reset by py_trees a tick later, is drawn ``was FAILURE`` (faded,
    not as never ticked) while the next child runs. ``--follow`` keeps serving after the run; its
    Ctrl-C once the ``--sim`` master is gone ends it without rospy's unregistering warnings."""
    driver = browser(tmp_path)
    run = SimRun(tmp_path, tree=ask_tree(tmp_path), world=slow_world(tmp_path, speed=0.8))
    web = None
    try:
        run.out.wait_for("running ask_around")
        web, out, url = start_web("watch", "--web", "--follow", "--wait", "60", env=run.env)
        driver.get(url)
        wait_until(driver, lambda d: node_status(d, "ask a person") == "RUNNING")
        wait_until(driver, lambda d: node_status(d, "look for it") == "was FAILURE")
        faded = driver.execute_script(
            "const g=[...document.querySelectorAll('#tree g.node')].find(e=>e.dataset.name==='look for it');"
            "return [g.getAttribute('class'), getComputedStyle(g).opacity, g.textContent];")
        assert faded[0] == "node was-FAILURE" and float(faded[1]) < 1, faded
        assert "call · was FAILURE" in faded[2] and "answered success: false" in faded[2], faded
        assert node_status(driver, "announce") == "SUCCESS"
        keep(driver, tmp_path, "watch-web-was.png")
        assert run.finish() == 0, run.out.text()
        wait_until(driver, lambda d: "result: SUCCESS" in text(d, "result"))
        assert node_status(driver, "look for it") == "was FAILURE" and node_status(driver, "ask a person") == "SUCCESS"
        web.send_signal(signal.SIGINT)  # the run and its master are gone
        assert web.wait(30) == 0
        assert "out of sync" not in out.all_text() and "[WARN]" not in out.all_text(), out.all_text()
        wait_until(driver, lambda d: d.find_element("id", "gone").is_displayed())
    finally:
        driver.quit()
        if web is not None:
            stop(web)
        run.close()
