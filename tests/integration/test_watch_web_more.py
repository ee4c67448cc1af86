"""The web view in a real browser (headless chromium, as test_watch_web.py): readable panels at
800 px, whole node names and a failed node's reason on the graph, the running node kept in view in
a tree of 240 nodes, a title naming the run, a killed run's replay, the jump to the failure, the
Blackboard node's notices highlighted, NaN and infinities shown as such, and a page opened after
``watch --web``'s run has ended.

The replays are of logs recorded here on mocks (simulated time: no ROS, fast); the live part is a
``bmtree run --sim``."""
from __future__ import annotations

import json
import os
import time

import pytest

from tests.conftest import TREES
from tests.integration.test_watch_web import browser, keep, node_status, start_web, stop, text, wait_until
from tests.integration.watchkit import GO, SimRun, slow_world
from tests.unit.test_nonfinite_values import nan_run_log
from tests.unit.test_recording import recorded

FIND_APPLE = os.path.join(TREES, "find_apple.yaml")

IN_VIEW = """
const g = [...document.querySelectorAll('#tree g.node')].find(e => e.dataset.name === arguments[0]);
if (!g) return null;
const r = g.querySelector('rect').getBoundingClientRect(), v = document.getElementById('graph').getBoundingClientRect();
const top = Math.max(v.top, 0), bottom = Math.min(v.bottom, window.innerHeight);  // seen: in the graph and the window
const left = Math.max(v.left, 0), right = Math.min(v.right, window.innerWidth);
return r.left >= left - 1 && r.right <= right + 1 && r.top >= top - 1 && r.bottom <= bottom + 1;"""
SHOWN = """const g = [...document.querySelectorAll('#tree g.node')].find(e => e.dataset.name === arguments[0]);
return g ? [...g.querySelectorAll('text')].map(t => t.textContent).join(' | ') : null;"""


@pytest.fixture(scope="module")
def driver(tmp_path_factory):
    d = browser(tmp_path_factory.mktemp("web_more"))  # one browser for the file: its start-up is slow
    try:
        yield d
    finally:
        d.quit()


@pytest.fixture
def page(driver):
    """Open ``replay LOG --web`` in the browser; the servers end with the test."""
    started = []

    def open_replay(log, width=1600, height=1000):
        driver.set_window_size(width, height)
        proc, _out, url = start_web("replay", log, "--web", env=dict(os.environ))
        started.append(proc)
        driver.get(url)
        wait_until(driver, lambda d: d.find_element("id", "timeline").is_displayed(), timeout=30)
        return driver

    yield open_replay
    for proc in started:
        stop(proc)


def _records(path):
    return [json.loads(line) for line in open(path)]


def _write(path, records):
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    return str(path)


def camera_down_log(sim_defs, tmp_path):
    """find_apple with the camera down in every room (2 s per drive), a Blackboard node's
    notice put in at 3 s (gone, never back)."""
    from coordinator.testing.mocks import succeed

    def script(m):
        m["navigation.go_to"].script(succeed(delay=2.0))
        m["vision.find_object"].fail("camera driver not responding")

    (tmp_path / "camera").mkdir()
    log = recorded(FIND_APPLE, sim_defs, tmp_path / "camera", script)[0]
    records = _records(log)
    at = next(i for i, r in enumerate(records) if float(r.get("t") or 0.0) > 3.0)
    notice = {"v": 1, "type": "notice", "run": records[0]["run"], "t": 3.0, "what": "blackboard_down",
              "text": "the Blackboard node /blackboard is gone: results from now on are not stored (its process ended)"}
    return _write(tmp_path / "camera.jsonl", records[:at] + [notice] + records[at:])


def test_a_failed_run_reads_well_names_itself_and_jumps_to_its_failure(page, sim_defs, tmp_path):
    log = camera_down_log(sim_defs, tmp_path)
    run_id = _records(log)[0]["run"]
    d = page(log, 800, 700)
    wait_until(d, lambda d: "result: FAILURE" in text(d, "result"))
    # the title names the tree, the run and that it is a replay
    assert "find_apple" in d.title and "replay" in d.title and run_id in d.title and "FAILURE" in d.title, d.title
    # at 800 px: keys, times and statuses on one line each ("it/e/m", "succeed/ed" and "0.00/s" were not)
    heights = d.execute_script(
        "const h = (sel) => [...document.querySelectorAll(sel)].map(c => c.getBoundingClientRect().height);"
        "return {keys: h('#blackboard tr td:first-child'), calls: [0, 2, 3].map(k => h('#calls tr td:nth-child(' + (k + 1) + ')')).flat(),"
        " line: parseFloat(getComputedStyle(document.querySelector('aside')).fontSize) * 1.6};")
    assert heights["keys"] and heights["calls"], heights
    assert max(heights["keys"] + heights["calls"]) <= heights["line"] + 2, heights
    # whole names on the graph, and the failure's reason under its node and in the panel
    assert "visit rooms until the apple is seen" in d.execute_script(SHOWN, "visit rooms until the apple is seen")
    shown = d.execute_script(SHOWN, "look for the object")
    assert "vision.find_object failed: camera" in shown, shown
    assert "camera driver not responding" in text(d, "why") and d.find_element("id", "why").is_displayed()
    # the failure that ended the run is in view on load (deep in the tree, right of the root)
    assert d.execute_script(IN_VIEW, "look for the object"), "the failed leaf is off-screen"
    keep(d, tmp_path, "web-more-failed-800.png")
    # the Blackboard node's notice, highlighted as failures are, and said in the header while it lasts
    row = d.execute_script("const r = [...document.querySelectorAll('#events tr')].find(r => r.textContent.includes('Blackboard node'));"
                           "return r ? [r.className, getComputedStyle(r.cells[0]).backgroundColor] : null;")
    assert row is not None and "down" in row[0] and row[1] not in ("rgba(0, 0, 0, 0)", "transparent"), row
    assert d.find_element("id", "alert").is_displayed() and "Blackboard node down since 3.00s" in text(d, "alert")
    # scrub to the start, then jump: the tick where the leaf failed, the leaf in view
    d.set_window_size(1600, 1000)
    d.execute_script("const s=document.getElementById('scrub'); s.value=0; s.dispatchEvent(new Event('input'));")
    wait_until(d, lambda d: text(d, "at").startswith("0.00s of"))
    assert text(d, "result") == "" and not d.find_element("id", "alert").is_displayed()
    jump = d.find_element("id", "jump")
    assert jump.is_displayed() and "look for the object" in jump.get_attribute("title")
    jump.click()
    wait_until(d, lambda d: node_status(d, "look for the object") in ("FAILURE", "was FAILURE"))
    at = float(d.execute_script("return document.getElementById('scrub').value"))
    assert at > 5.0 and abs(float(text(d, "at").split("s of")[0]) - at) <= 0.011, (at, text(d, "at"))
    assert d.execute_script(IN_VIEW, "look for the object")
    assert "culprit" in d.execute_script(
        "return [...document.querySelectorAll('#tree g.node')].find(e => e.dataset.name === 'look for the object').getAttribute('class')")


def test_a_killed_run_replays_as_unfinished_over_its_real_length(page, sim_defs, tmp_path):
    full = _records(camera_down_log(sim_defs, tmp_path))
    cut = [r for r in full if float(r.get("t") or 0.0) < 2.5 and r.get("type") != "end"]  # killed while driving
    log = _write(tmp_path / "killed.jsonl", cut)
    started = cut[0]["started"]
    os.utime(log, (started + 5.0, started + 5.0))  # the writer's heartbeat: last seen alive 5 s in
    d = page(log)
    wait_until(d, lambda d: "UNFINISHED" in text(d, "result"))
    assert text(d, "at") == "5.00s of 5.00s" and text(d, "clock").startswith("t=5.00s")
    killed = d.find_element("id", "killed")
    assert killed.is_displayed() and "last seen alive at 5.00s" in killed.text, killed.text
    assert "UNFINISHED" in d.title
    assert node_status(d, "go to the room (retrying)") == "RUNNING"
    assert d.find_elements("css selector", "#tree.stale")  # what ran is only what it was when last seen
    assert d.execute_script("return document.getElementById('scrub').max") == "5"
    keep(d, tmp_path, "web-more-killed.png")


def huge_tree(tmp_path, groups=40, steps=5):
    lines = ["format: 1", "name: huge", "root:", "  sequence:", "    name: everything", "    children:"]
    for g in range(groups):
        lines += ["      - sequence:", "          name: group %d with a rather long descriptive name to test wrapping" % g,
                  "          children:"]
        for s in range(steps):
            lines += ["            - call: speech.say", "              name: g%d step %d say something" % (g, s),
                      "              inputs: {text: \"group %d step %d\"}" % (g, s)]
    path = tmp_path / "huge.yaml"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def test_a_huge_tree_keeps_the_root_then_the_running_node_in_view(page, sim_defs, tmp_path):
    from coordinator.testing.mocks import succeed

    log = recorded(huge_tree(tmp_path), sim_defs, tmp_path, lambda m: m["speech.say"].script(succeed(delay=0.1)))[0]
    d = page(log, 1400, 900)
    wait_until(d, lambda d: "result: SUCCESS" in text(d, "result"))
    assert len(d.find_elements("css selector", "#tree g.node")) == 241
    assert d.execute_script(IN_VIEW, "everything"), "the root is off-screen on load"
    # the page itself does not scroll: the graph does, inside the window
    assert d.execute_script("return document.documentElement.scrollHeight <= window.innerHeight + 1")
    d.execute_script("const s=document.getElementById('scrub'); s.value=13.05; s.dispatchEvent(new Event('input'));")
    wait_until(d, lambda d: node_status(d, "g26 step 0 say something") == "RUNNING")
    assert d.execute_script(IN_VIEW, "g26 step 0 say something"), "the running leaf is off-screen"
    assert "group 26 with a rather long descriptive name to test wrapping" in d.execute_script(
        SHOWN, "group 26 with a rather long descriptive name to test wrapping").replace(" | ", " ")
    keep(d, tmp_path, "web-more-huge.png")
    # the user scrolls away: the view stays where the user put it
    d.execute_script("document.getElementById('graph').scrollTop = 0")
    time.sleep(0.3)
    d.execute_script("const s=document.getElementById('scrub'); s.value=18.05; s.dispatchEvent(new Event('input'));")
    wait_until(d, lambda d: node_status(d, "g36 step 0 say something") == "RUNNING")
    assert d.execute_script("return document.getElementById('graph').scrollTop") == 0
    assert not d.execute_script(IN_VIEW, "g36 step 0 say something")


BLACKBOARD = "return [...document.querySelectorAll('#blackboard tr')].map(r => [...r.cells].map(c => c.textContent))"


def test_nan_and_infinities_are_shown_as_such(page, sim_defs, tmp_path):
    """A run whose values hold NaN and infinities (a Float64 output, ``.inf`` in the tree, an event's
    param): the page stayed blank, ``(waiting for a run)``, its JSON.parse refusing Python's NaN."""
    d = page(nan_run_log(sim_defs, tmp_path))
    wait_until(d, lambda d: "result: SUCCESS" in text(d, "result"))
    assert d.execute_script(BLACKBOARD) == [["far", "Infinity"], ["level", "NaN"], ["limit", "NaN"],
                                            ["low_at", "-Infinity"], ["near", "-Infinity"]]
    assert 'battery.low{"percentage":-Infinity}' in text(d, "events")
    d.execute_script("const s=document.getElementById('scrub'); s.value=0; s.dispatchEvent(new Event('input'));")
    wait_until(d, lambda d: text(d, "at").startswith("0.00s of"))
    assert ["level", "NaN"] in d.execute_script(BLACKBOARD) and "low_at" not in text(d, "blackboard")


def test_a_page_opened_after_the_run_ended_still_gets_its_end(driver, tmp_path):
    """``watch --web`` used to end 5 s after the run when no page was open: it serves the end on
    until a page has it. A tab closed during a long poll prints no traceback."""
    driver.set_window_size(1600, 1000)
    run = SimRun(tmp_path, tree=GO, world=slow_world(tmp_path, speed=1.0))
    web = None
    try:
        run.out.wait_for("RUNNING   go to the kitchen")
        web, out, url = start_web("watch", "--web", "--wait", "60", env=run.env)
        driver.get(url)
        # (a loaded machine may take longer than the 8 s drive to start the watch and the browser)
        wait_until(driver, lambda d: node_status(d, "go to the kitchen") in ("RUNNING", "SUCCESS"))
        assert "go_kitchen" in driver.title and "watch" in driver.title, driver.title
        assert not driver.find_element("id", "timeline").is_displayed()  # live: no slider
        driver.get("about:blank")  # the tab goes away during its long poll
        out.wait_for("the run ended: SUCCESS", timeout=60)
        assert run.finish() == 0, run.out.text()
        out.wait_for("no page has shown the end yet", timeout=15)
        time.sleep(1.0)
        assert web.poll() is None, out.text()  # still serving, past the 5 s it used to give
        driver.get(url)
        wait_until(driver, lambda d: "result: SUCCESS" in text(d, "result"))
        assert node_status(driver, "arrived") == "SUCCESS"
        assert web.wait(15) == 0, out.text()  # a page has the end: the watch ends
        assert "Traceback" not in out.all_text() and "BrokenPipe" not in out.all_text(), out.all_text()
    finally:
        if web is not None:
            stop(web)
        run.close()


def test_a_page_opened_during_a_long_call_counts_it_from_its_start(driver, tmp_path):
    """The page counted the run's time from its last record when it was opened: a call running for 5 s
    showed 0.0 s of its 30 (the terminal said 5); the watch's own "now" comes with the state."""
    import re

    run = SimRun(tmp_path, tree=GO, world=slow_world(tmp_path, speed=0.2))
    web = None
    try:
        web, out, url = start_web("watch", "--web", "--wait", "60", env=run.env)
        run.out.wait_for("RUNNING   go to the kitchen")
        time.sleep(5.0)
        driver.get(url)
        wait_until(driver, lambda d: "navigation.go_to" in text(d, "pending"))
        shown = re.search(r"navigation\.go_to([\d.]+)s / 30s", text(driver, "pending"))
        assert shown and float(shown.group(1)) >= 4.5, text(driver, "pending")
    finally:
        if web is not None:
            stop(web)
        run.close()
