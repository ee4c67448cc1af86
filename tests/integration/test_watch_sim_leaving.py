"""``bmtree watch --web`` of a ``--sim`` run that ends normally: once the run (and its private master) is
gone, the watch leaves without a word about a master that does not answer (README, "Watching a run":
there is nothing to leave); it printed "the ROS master … does not answer: leaving without unregistering
(… rosnode cleanup …)"."""
from __future__ import annotations

import signal

from tests.integration.test_watch_web import start_web, stop
from tests.integration.watchkit import SimRun

TREE = """format: 1
name: short
root:
  sequence:
    name: errand
    children:
      - call: speech.say
        name: greet
        inputs: {text: hello}
      - wait: 3
        name: a moment
"""


def test_the_watch_of_an_ended_sim_run_leaves_quietly(tmp_path):
    path = tmp_path / "short.yaml"
    path.write_text(TREE)
    run = SimRun(tmp_path, tree=str(path))
    web = None
    try:
        web, out, _url = start_web("watch", "--web", "--wait", "60", env=run.env)
        out.wait_for("the run ended: SUCCESS")
        assert run.finish() == 0, run.out.text()   # the run, and its master, are gone
        # no page was opened: it serves the end on; Ctrl-C ends it, with the master gone
        out.wait_for("no page has shown the end yet")
        web.send_signal(signal.SIGINT)
        assert web.wait(30) == 0, out.text()
        said = out.all_text()
        assert "does not answer" not in said and "rosnode cleanup" not in said, said
        assert "out of sync" not in said and "[WARN]" not in said and "Traceback" not in said, said
    finally:
        if web is not None:
            stop(web)
        run.close()
