"""A project's folder named like a bmtree package (``modules/`` of definitions, as the README's own
examples name it) does not hide bmtree's package when Python starts in the project (``python -m
pytest``: the working directory comes first). (A regular package of that name is left alone: catkin's
devel space relays bmtree's own packages that way; tests/integration/test_catkin.py runs it.)"""
from __future__ import annotations

import json
import os
import subprocess
import sys

from modules.sim import SIM_DIR

TEST = '''
from modules import BasicModule, default_module_paths

def test_a_tree_and_the_projects_own_definitions(bmtree_tree):
    t = bmtree_tree("go.yaml")
    t.mocks["gripper.open"].succeed()
    assert t.run().succeeded and BasicModule and default_module_paths()
'''


def _project(tmp_path):
    (tmp_path / "modules").mkdir()
    with open(os.path.join(SIM_DIR, "speech.json")) as fh:
        d = json.load(fh)
    d["Basic Module"] = "gripper"
    d["Functions"] = [dict(d["Functions"][0], **{"Name": "open", "Input-params": [], "Output-params": []})]
    (tmp_path / "modules" / "gripper.json").write_text(json.dumps(d))
    (tmp_path / "go.yaml").write_text("format: 1\nroot:\n  call: gripper.open\n")
    (tmp_path / "pytest.ini").write_text("[pytest]\nbmtree_modules = modules/gripper.json\n")
    (tmp_path / "test_go.py").write_text(TEST)


def _python(tmp_path, *args):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run([sys.executable, *args], cwd=str(tmp_path), env=env, capture_output=True, text=True,
                          timeout=120)


def test_a_folder_of_definitions_named_modules_does_not_hide_bmtrees_package(tmp_path):
    _project(tmp_path)
    p = _python(tmp_path, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_go.py")
    assert p.returncode == 0 and "1 passed" in p.stdout, p.stdout + p.stderr
    p = _python(tmp_path, "-c", "import coordinator, modules; print(modules.__file__)")
    assert p.returncode == 0 and p.stdout.strip() == os.path.abspath(modules_init()), p.stderr


def modules_init():
    import modules

    return modules.__file__
