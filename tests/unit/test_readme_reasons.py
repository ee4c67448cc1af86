"""The README's example of a retry's failure reason is what a run gives."""
from __future__ import annotations

import os

from coordinator.testing.kit import TreeTest
from tests.conftest import ROOT

RETRY = """format: 1
name: r
root:
  retry: 3
  name: go to the room
  child:
    call: navigation.go_to
    inputs: {place: kitchen}
"""


def test_the_readmes_retry_reason_is_the_runs(tmp_path, sim_defs):
    path = tmp_path / "r.yaml"
    path.write_text(RETRY)
    t = TreeTest(str(path), definitions=sim_defs)
    t.mocks["navigation.go_to"].fail("blocked")
    run = t.run()
    assert run.reason == "go to the room: navigation.go_to failed: blocked (3 of 3 attempts)"
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        readme = fh.read()
    assert "A `retry` above it that gave up adds the attempts:\n`%s`" % run.reason in readme
    assert '"reason":"%s"' % run.reason in readme
