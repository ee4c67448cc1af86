"""The README against what runs: a retry's failure reason, the topic-and-service module example."""
from __future__ import annotations

import os

from coordinator.testing import succeed
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


def test_the_readmes_topic_and_service_module_is_the_example_files():
    """The README shows modules/example/keywords.py's class as it is (the file runs in the integration tests)."""
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        section = fh.read().split("### A ROS topic or service as a module", 1)[1].split("\n### ", 1)[0]
    shown = section.split("```python\n", 1)[1].split("```", 1)[0]
    with open(os.path.join(ROOT, "modules", "example", "keywords.py"), encoding="utf-8") as fh:
        code = fh.read()

    def tokens(text):   # the code's words, wrapped anywhere, without comments and type annotations
        kept = " ".join(line.split("#")[0] for line in text.split("class Keywords", 1)[1].splitlines())
        for annotation in (": Any", " -> None", " -> Dict[str, Any]", ": String"):
            kept = kept.replace(annotation, "")
        return kept.split()

    assert tokens(shown) == tokens(code)


def test_the_readmes_task_example_checks_and_runs(tmp_path, sim_defs):
    """The tree of "Writing a task" is valid against the simulated robot's definitions, and does what its
    comments say once its functions are scripted."""
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        section = fh.read().split("## Writing a task\n", 1)[1].split("\n## ", 1)[0]
    path = tmp_path / "serve_drink.yaml"
    path.write_text(section.split("```yaml\n", 1)[1].split("```", 1)[0])
    t = TreeTest(str(path), definitions=sim_defs, strict=True)
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    t.mocks["vision.find_object"].script(succeed(position={"x": 0.0}), succeed(position={"x": 1.5}))
    t.mocks["speech.listen"].succeed(text="lemonade")
    t.mocks["speech.say"].succeed()
    run = t.run()
    assert run.succeeded, run
    assert len(run.calls("vision.find_object")) == 2 and run.said() == ["One lemonade, coming.", "Done (succeeded)."]
