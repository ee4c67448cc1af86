"""The scripts of nodes/ (what rosrun runs in a catkin workspace) with a Python that lacks one of
bmtree's dependencies, as catkin's /usr/bin/python3 on Debian 12 lacks py_trees and
rospy_message_converter: one line naming the package and the fix, exit 3, no traceback."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys

import pytest

from tests.conftest import ROOT

SCRIPTS = ("bmtree", "bmtree-blackboard", "bmtree-bridge", "bmtree-module", "bmtree-sim")
SYSTEM_PYTHON = "/usr/bin/python3"
MISSING = re.compile(r"^error: (?P<prog>[\w-]+): the Python package '(?P<pkg>[\w.<>=,]+)' is missing for (?P<py>\S+) "
                     r"\(the Python catkin found, unless the workspace was built with -DPYTHON_EXECUTABLE\): "
                     r"(?P<fix>.+)\n$")
STUB = "raise ModuleNotFoundError(\"No module named '{0}'\", name='{0}')\n"


def _env(**extra):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env.update(extra)
    return env


def _run(argv, env, cwd):
    return subprocess.run(argv, capture_output=True, text=True, timeout=60, env=env, cwd=str(cwd),
                          stdin=subprocess.DEVNULL)


def _stubs(tmp_path):
    """A directory that, first on PYTHONPATH, makes rospy_message_converter and jsonschema unimportable."""
    stubs = tmp_path / "stubs"
    for name in ("rospy_message_converter", "jsonschema"):
        (stubs / name).mkdir(parents=True)
        (stubs / name / "__init__.py").write_text(STUB.format(name))
    return os.pathsep.join([str(stubs), ROOT])


@pytest.mark.parametrize("script", SCRIPTS)
def test_a_missing_dependency_is_one_line_and_exit_3(script, tmp_path):
    """bmtree's venv with rospy_message_converter and jsonschema made unimportable."""
    out = _run([sys.executable, os.path.join(ROOT, "nodes", script), "--help"], _env(PYTHONPATH=_stubs(tmp_path)),
               tmp_path)
    assert out.returncode == 3, out.stdout + out.stderr
    m = MISSING.match(out.stderr)
    assert m, out.stderr
    assert m.group("prog") == script and m.group("pkg") in ("rospy_message_converter", "jsonschema")
    venv = os.path.join(ROOT, ".venv")
    if os.path.realpath(sys.prefix) == os.path.realpath(venv):  # the clone's venv: make setup fills it
        assert m.group("fix") == "run `make setup` in %s, which installs it into this venv" % ROOT
    else:  # another Python (make test's 3.8 run): the clone's venv is the one to build with
        assert m.group("fix").startswith("build the workspace with bmtree's venv, catkin_make -DPYTHON_EXECUTABLE="
                                         "%s" % os.path.join(venv, "bin", "python")), m.group("fix")


@pytest.mark.parametrize("script", SCRIPTS)
def test_with_the_system_python_the_fix_is_the_venv_of_make_setup(script, tmp_path):
    """Debian 12's /usr/bin/python3 (what catkin_make uses unless told otherwise), without the packages
    Debian does not have (hidden by stubs, should someone have installed them there)."""
    assert os.access(SYSTEM_PYTHON, os.X_OK), "Debian 12 has %s" % SYSTEM_PYTHON
    out = _run([SYSTEM_PYTHON, "-s", os.path.join(ROOT, "nodes", script), "--version"],
               _env(PYTHONPATH=_stubs(tmp_path)), tmp_path)
    assert out.returncode == 3, out.stdout + out.stderr
    assert "Traceback" not in out.stderr and out.stdout == ""
    m = MISSING.match(out.stderr)
    assert m, out.stderr
    assert m.group("prog") == script and m.group("py") == SYSTEM_PYTHON
    venv = os.path.join(ROOT, ".venv", "bin", "python")
    fix = "build the workspace with bmtree's venv, catkin_make -DPYTHON_EXECUTABLE=%s" % venv
    assert m.group("fix") in (fix, fix + " (`make setup` in %s makes it)" % ROOT), out.stderr


def test_with_its_dependencies_a_script_runs_as_before(tmp_path):
    from coordinator import __version__

    out = _run([sys.executable, os.path.join(ROOT, "nodes", "bmtree"), "--version"], _env(), tmp_path)
    assert (out.returncode, out.stdout.strip(), out.stderr) == (0, "bmtree %s" % __version__, "")


def _copy_nodes(to):
    os.makedirs(str(to / "nodes"))
    for f in ("bmtree", "bmtree_entry.py"):
        shutil.copy2(os.path.join(ROOT, "nodes", f), str(to / "nodes" / f))
    return str(to / "nodes" / "bmtree")


def test_in_a_workspace_without_a_venv_the_fix_makes_one_beside_src(tmp_path):
    """A clone in a catkin workspace's src/ with no .venv: a venv inside the package would give
    rosrun a second `bmtree` to choose from, so the fix makes it in the workspace."""
    ws = tmp_path / "robot_ws"
    (ws / "src").mkdir(parents=True)
    (ws / ".catkin_workspace").write_text("")
    clone = ws / "src" / "bmtree"
    (clone / "scripts").mkdir(parents=True)
    (clone / "scripts" / "setup.sh").write_text("")
    out = _run([sys.executable, _copy_nodes(clone), "--version"], _env(PYTHONPATH=_stubs(tmp_path)), tmp_path)
    assert out.returncode == 3, out.stdout + out.stderr
    m = MISSING.match(out.stderr)
    assert m, out.stderr
    assert m.group("fix") == (
        "build the workspace with a venv that has it (Debian 12's pip refuses the system Python): cd %s && python3 -m "
        "venv --system-site-packages .venv && .venv/bin/pip install -e src/bmtree && catkin_make "
        "-DPYTHON_EXECUTABLE=%s/.venv/bin/python" % (ws, ws))


def test_installed_scripts_name_the_option(tmp_path):
    """Scripts outside a clone (catkin's install space): the option, with a venv to make."""
    out = _run([sys.executable, _copy_nodes(tmp_path / "lib" / "bmtree"), "--version"],
               _env(PYTHONPATH=_stubs(tmp_path)), tmp_path)
    assert out.returncode == 3, out.stdout + out.stderr
    m = MISSING.match(out.stderr)
    assert m and "catkin_make -DPYTHON_EXECUTABLE=/path/to/venv/bin/python" in m.group("fix"), out.stderr
