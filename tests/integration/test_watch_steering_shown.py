"""A ``bmtree run --sim --control`` watched in a real terminal (tmux), on the page (headless chromium) and
as ``--plain`` lines: a retry's attempt while it runs and while it waits its delay, a breakpoint's mark,
the node it holds shown held (not working), a forced outcome marked forced, how long a ``wait`` has
waited; the answer to a key shown a few seconds, and no keys nor buttons once the run has ended."""
from __future__ import annotations

import subprocess

from tests.integration.conftest import bmtree_cmd
from tests.integration.test_control import ok
from tests.integration.test_watch_terminal import Tmux, _cmd
from tests.integration.test_watch_web import browser, start_web, stop, text, wait_until
from tests.integration.watchkit import Lines, SimRun

TREE = """format: 1
name: marks
root:
  sequence:
    name: errand
    children:
      - call: speech.say
        name: greet
        inputs: {text: hello}
      - selector:
          name: try or rest
          children:
            - retry: 2
              name: keep trying
              delay: 6
              child:
                sequence:
                  name: one try
                  children:
                    - wait: 4
                      name: try
                    - fail: "not yet"
                      name: give up
            - wait: 120
              name: rest
      - call: speech.say
        name: announce
        inputs: {text: done}
"""


def node(driver, name, what):
    """A node's box on the page: its data-… attribute, or its lines of text (``text``)."""
    return driver.execute_script(
        "const g=[...document.querySelectorAll('#tree g.node')].find(e=>e.dataset.name===arguments[0]);"
        "return !g ? null : arguments[1] === 'text' ? [...g.querySelectorAll('text')].map(t=>t.textContent)"
        ".join('|') : g.dataset[arguments[1]];", name, what)


def test_attempts_breakpoints_and_forced_outcomes_are_shown(tmp_path):
    path = tmp_path / "marks.yaml"
    path.write_text(TREE)
    driver = browser(tmp_path)
    run = SimRun(tmp_path, tree=str(path), extra=("--control",))
    term = web = plain = None
    try:
        plain = subprocess.Popen(bmtree_cmd("watch", "--plain", "--wait", "60"), stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True, env=run.env)
        seen = Lines(plain.stdout)
        term = Tmux(tmp_path, "marks", 120, 40, _cmd("watch", "--follow", "--wait", "60"), run.env)
        web, _out, url = start_web("watch", "--web", "--wait", "60", env=run.env)
        driver.get(url)
        term.wait_screen("bmtree watch marks", "q quit  p pause/resume")
        assert "will pause before 'announce' starts" in ok(run, "break", "announce")
        term.wait_screen("- ● announce")
        wait_until(driver, lambda d: node(d, "announce", "break") == "1")
        # the retry between its attempts (its delay), then its second attempt, with the wait's time
        shown = term.wait_screen("keep trying [retry]  RUNNING  next attempt in", "(2 of 2)")
        assert "x one try [sequence]  was FAILURE" in shown or "one try" in shown, shown
        wait_until(driver, lambda d: "next attempt in" in node(d, "keep trying", "text"))
        shown = term.wait_screen("keep trying [retry]  RUNNING  attempt 2 of 2", "try  RUNNING  waited ")
        wait_until(driver, lambda d: "retry · RUNNING|attempt 2 of 2" in node(d, "keep trying", "text"))
        wait_until(driver, lambda d: "wait · RUNNING|waited " in node(d, "try", "text"))
        # given up: its attempts called so; the next child waits
        shown = term.wait_screen("FAILURE  failed in attempt 2 of 2", "rest  RUNNING  waited ")
        assert "run 2 of 2" not in shown, shown
        # a key's answer stays a few seconds, then the keys again (it stayed for good)
        term.tmux("send-keys", "-t", term.name, "p")
        term.wait_screen("PAUSED", "ok: paused")
        term.wait_screen("PAUSED", "q quit  p pause/resume", timeout=30)
        assert "'rest' will end in SUCCESS" in ok(run, "force", "rest", "SUCCESS")
        term.tmux("send-keys", "-t", term.name, "p")   # resume: rest forced, then announce held at its breakpoint
        shown = term.wait_screen("rest  SUCCESS (forced)", "* ● announce  RUNNING (held at breakpoint)", "PAUSED")
        wait_until(driver, lambda d: node(d, "announce", "note") == "held at breakpoint")
        assert "RUNNING (held at breakpoint)" in node(driver, "announce", "text")
        assert node(driver, "rest", "note") == "forced" and node(driver, "announce", "status") == "RUNNING"
        wait_until(driver, lambda d: d.find_element("id", "controls").is_displayed())
        driver.find_element("id", "resume").click()
        wait_until(driver, lambda d: text(d, "answer") == "ok: resumed")
        wait_until(driver, lambda d: "result: SUCCESS" in text(d, "result"))
        assert not driver.find_element("id", "controls").is_displayed()   # an ended run takes no commands
        assert run.finish() == 0, run.out.text()
        shown = term.wait_screen("SUCCESS in", "q quit  (the run has ended: it takes no more commands)")
        assert "announce  SUCCESS" in shown and "(held at breakpoint)" not in shown, shown
        assert plain.wait(60) == 0
        said = seen.all_text()
        for line in ("attempt   keep trying: attempt 2 of 2", "FAILURE   keep trying (failed in attempt 2 of 2)",
                     "SUCCESS   rest (forced)", "RUNNING   announce (held at breakpoint)"):
            assert line in said, said
        # its delay: a line of its own, or the watch's catching up said it (a watch that attached late)
        assert ("attempt   keep trying: next attempt in " in said
                or "keep trying RUNNING (next attempt in " in said), said
        assert "keep trying: attempt 1" not in said, said   # its first attempt is its RUNNING line
        assert "Traceback" not in said
    finally:
        driver.quit()
        for proc in (web, plain):
            if proc is not None:
                stop(proc)
        if term is not None:
            term.close()
        run.close()
