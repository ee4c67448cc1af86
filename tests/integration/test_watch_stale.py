"""``bmtree watch`` of a run whose process stops answering (SIGSTOP: as a Wi-Fi link that dropped,
or a hung machine, it sends nothing and refuses nothing): ``--plain``, the terminal (tmux) and the
page (headless chromium; BMTREE_SCREENSHOTS=DIR keeps its screenshot), all watching one ``bmtree run
--sim`` that waits on a long navigation call, say that what they show may be stale, and stop saying
it once the run answers again (SIGCONT)."""
from __future__ import annotations

import re
import signal
import subprocess

from tests.integration.conftest import bmtree_cmd
from tests.integration.test_watch_terminal import Tmux, _cmd
from tests.integration.test_watch_web import browser, keep, start_web, stop, text, wait_until
from tests.integration.watchkit import Lines, SimRun, slow_world


def test_a_stopped_run_is_said_stale_until_it_answers_again(tmp_path):
    driver = browser(tmp_path)  # first: its start-up is slow
    run = SimRun(tmp_path, world=slow_world(tmp_path, speed=0.3))  # the navigation takes about half a minute
    term = watch = web = None
    try:
        run.out.wait_for("RUNNING   go to the kitchen")
        watch = subprocess.Popen(bmtree_cmd("watch", "--plain", "--wait", "60"), stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True, env=run.env)
        out = Lines(watch.stdout)
        term = Tmux(tmp_path, "stale", 120, 40, _cmd("watch", "--wait", "60"), run.env)
        web, _web_out, url = start_web("watch", "--web", "--wait", "60", env=run.env)
        driver.get(url)
        out.wait_for("caught up at tick")
        term.wait_screen("go to the kitchen  RUNNING", "navigation.go_to")
        wait_until(driver, lambda d: "navigation.go_to" in text(d, "pending"))
        # idle, waiting on its call, and answering: nothing said
        assert "no answer" not in term.screen() and not driver.find_element("id", "stale").is_displayed()
        node = "the run's node /bmtree_%d_" % run.proc.pid
        run.proc.send_signal(signal.SIGSTOP)
        try:
            said = out.wait_for("has not answered for")
            assert said.startswith("[") and node in said, said
            # said once 3 s passed without an answer (asked once a second: 3 or more under load)
            quiet = re.search(r"has not answered for (\d+) s \(its machine unreachable, or its process stopped\): "
                              r"what is shown may be stale", said)
            assert quiet is not None and int(quiet.group(1)) >= 3, said
            shown = term.wait_screen("no answer from " + node)
            header = " ".join(line.strip() for line in shown.split("\n")[1:3])  # under the first line, wrapped
            assert header.startswith("no answer from " + node) and " s (its machine unreachable, or its process " \
                                                                    "stopped): what is shown may be stale" in header
            wait_until(driver, lambda d: d.find_element("id", "stale").is_displayed())
            assert text(driver, "stale").startswith("no answer from " + node), text(driver, "stale")
            assert "may be stale" in text(driver, "stale")
            keep(driver, tmp_path, "watch-web-stale.png")
        finally:
            run.proc.send_signal(signal.SIGCONT)
        again = out.wait_for("answers again after")
        assert node in again and again.startswith("["), again
        shown = term.wait_screen("answers again after")  # (among the last events)
        assert "no answer from" not in shown, shown
        wait_until(driver, lambda d: not d.find_element("id", "stale").is_displayed())
        assert "answers again after" in text(driver, "events")
        assert run.proc.poll() is None and watch.poll() is None, out.text()  # the run goes on, watched
        assert "Traceback" not in out.text()
    finally:
        driver.quit()
        if term is not None:
            term.close()
        if web is not None:
            stop(web)
        run.proc.send_signal(signal.SIGCONT)  # never left stopped: a stopped process acts on no SIGTERM
        run.close()
        if watch is not None:
            stop(watch)
