"""``bmtree watch --follow`` (``--plain`` and ``--web`` in headless chromium) over two runs on one master:
the second run's header comes before its first lines (not after its first long call), under the first
run's end; each run's catching up is said once; the page shows no control buttons while it waits for
a run, and the second run's quick first call ended, in its call log, while its long call runs."""
from __future__ import annotations

import re
import signal
import subprocess

from tests.integration.conftest import bmtree_cmd
from tests.integration.faultkit import PROBE_JSON
from tests.integration.test_watch_terminal_operator import _start
from tests.integration.test_watch_web import browser, start_web, stop, text, wait_until
from tests.integration.watchkit import Lines

TREE = """format: 1
name: greet_then_work
root:
  sequence:
    name: errand
    children:
      - call: probe.echo
        name: greet
        inputs: {tag: hello}
      - call: probe.work
        name: long work
        inputs: {seconds: 4.0, tag: a}
        timeout: 30
"""


def test_follow_shows_each_run_from_its_start(own_graph, tmp_path):
    own_graph.start_node(["-m", "modules.node", "--definition", PROBE_JSON, "--class",
                          PROBE_JSON.replace("probe.json", "probe_module.py") + ":Probe"], "/bm_probe")
    env = dict(own_graph.env, ROS_HOME=str(tmp_path / "home"))
    driver = browser(tmp_path)
    plain = web = None
    runs = []
    try:
        plain = subprocess.Popen(bmtree_cmd("watch", "--plain", "--follow", "--wait", "60"), env=env, text=True,
                                 stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        seen = Lines(plain.stdout)
        web, out, url = start_web("watch", "--web", "--follow", "--wait", "60", env=env)
        driver.get(url)
        # waiting for a run: no control buttons (nothing would take them)
        wait_until(driver, lambda d: text(d, "title") == "(waiting for a run)" and d.execute_script(
            "return document.querySelector('#clock').textContent !== ''"))
        assert not driver.find_element("id", "controls").is_displayed()
        for k in range(2):
            proc, said = _start(env, tmp_path, "errand%d.yaml" % k, TREE)
            runs.append(proc)
            said.wait_for("RUNNING   long work")
            header = seen.wait_for("greet_then_work (3 nodes)") if k == 0 else _second_header(seen)
            run_id = re.search(r"run (\d{8}-\d{6}-[0-9a-f]+)", header).group(1)
            # the page, on each run: its quick greeting has ended (in the call log, not pending) while it works
            wait_until(driver, lambda d, r=run_id: r in text(d, "run") and "probe.work" in text(d, "pending"))
            assert "probe.echo" not in text(driver, "pending"), text(driver, "pending")
            wait_until(driver, lambda d: "probe.echo" in text(d, "calls"))
            assert proc.wait(60) == 0, said.text()
            wait_until(driver, lambda d: "result: SUCCESS" in text(d, "result"))
        seen.wait_for("end       SUCCESS")
        lines = seen.text().splitlines()
        heads = [k for k, line in enumerate(lines) if line.startswith("run ")]
        assert len(heads) == 2, lines
        # the second run: under the first one's end, its header, then its own lines from its start
        assert "] end       SUCCESS" in lines[heads[1] - 1], lines
        second = lines[heads[1] + 1:]
        firsts = [line for line in second if "] call      probe.echo" in line or "RUNNING   greet" in line]
        assert len(firsts) == 2 and all(line.startswith("[  0.0") for line in firsts), second
        assert sum("caught up at tick" in line for line in second) <= 1, second
        assert sum("caught up at tick" in line for line in lines[:heads[1]]) <= 1, lines
        assert sum("] end       SUCCESS" in line for line in second) == 1, second
    finally:
        driver.quit()
        for proc in [plain, web] + runs:
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(30)
                except subprocess.TimeoutExpired:
                    proc.kill()
        if web is not None:
            stop(web)


def _second_header(seen):
    """The second run's header line (it may come a moment after the first run's end)."""
    import time

    for _ in range(300):
        heads = [line for line in seen.text().splitlines() if line.startswith("run ")]
        if len(heads) >= 2:
            return heads[1]
        time.sleep(0.1)
    raise AssertionError("no second run header:\n" + seen.text())
