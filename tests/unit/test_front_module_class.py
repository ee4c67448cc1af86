"""``bmtree-module --class MODULE:CLASS`` for a module that is not on the path: the error says how
to give the file instead (README "Writing a basic module")."""
from __future__ import annotations

import os
import shutil
import sys

import pytest

from modules.node import load_class, main
from tests.conftest import DATA

GRIPPER = os.path.join(DATA, "gripper")


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """The module author's folder, the current directory, holding gripper.py and gripper.json."""
    for f in ("gripper.py", "gripper.json"):
        shutil.copy(os.path.join(GRIPPER, f), str(tmp_path / f))
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", ".", str(tmp_path))])
    yield tmp_path
    for name in ("gripper", "shelf", "shelf.gripper", "broken"):
        sys.modules.pop(name, None)


def _module_main(capsys, *args):
    code = main(["bmtree-module", "--definition", "gripper.json", *args])
    return code, capsys.readouterr().err


def test_a_module_name_whose_file_is_in_the_current_directory_says_give_the_file(folder, capsys):
    code, err = _module_main(capsys, "--class", "gripper:Gripper")
    assert code == 2
    assert err == ("error: gripper:Gripper: no Python module 'gripper' on the path (PYTHONPATH): give the file, "
                   "--class gripper.py:Gripper\n")
    assert "gripper" not in sys.modules  # the current directory was not searched behind the author's back
    assert load_class("gripper.py:Gripper").__name__ == "Gripper"  # and the file form the error gives works


def test_a_dotted_module_name_points_at_its_file(folder, capsys):
    (folder / "shelf").mkdir()
    shutil.move(str(folder / "gripper.py"), str(folder / "shelf" / "gripper.py"))
    code, err = _module_main(capsys, "--class", "shelf.gripper:Gripper")
    assert code == 2
    assert err == ("error: shelf.gripper:Gripper: no Python module 'shelf.gripper' on the path (PYTHONPATH): "
                   "give the file, --class %s:Gripper\n" % os.path.join("shelf", "gripper.py"))


def test_a_module_name_with_no_file_here_says_what_module_and_file_forms_need(folder, capsys):
    code, err = _module_main(capsys, "--class", "grabber:Gripper")
    assert code == 2
    assert err == ("error: grabber:Gripper: no Python module 'grabber' on the path (PYTHONPATH): MODULE must be "
                   "importable (on PYTHONPATH, or installed); --class FILE.py:Gripper loads a file directly\n")


def test_an_importable_module_that_imports_something_missing_says_where(folder, capsys, monkeypatch):
    (folder / "broken.py").write_text("import no_such_package_here  # noqa\n")
    monkeypatch.syspath_prepend(str(folder))
    code, err = _module_main(capsys, "--class", "broken:Gripper")
    assert code == 2
    assert err.startswith("error: %s:1: No module named 'no_such_package_here'" % (folder / "broken.py")), err


def test_an_importable_module_loads(folder, monkeypatch):
    monkeypatch.syspath_prepend(str(folder))
    assert load_class("gripper:Gripper").__name__ == "Gripper"


def test_a_class_file_imports_the_modules_beside_it(folder, monkeypatch, capsys):
    """A driver wrapper beside the class file (``from driverlib import force``) imports, as with ``python
    gripper.py``; before, the node said ``No module named 'driverlib'`` unless PYTHONPATH had the folder."""
    (folder / "shelf").mkdir()
    (folder / "shelf" / "driverlib_beside.py").write_text("FORCE = 7.5\n")
    (folder / "shelf" / "wrapped.py").write_text(
        "from driverlib_beside import FORCE\nfrom modules import BasicModule\n\n\n"
        "class Wrapped(BasicModule):\n    force = FORCE\n")
    monkeypatch.chdir(str(folder / ".."))   # not from its folder
    try:
        cls = load_class("%s:Wrapped" % (folder / "shelf" / "wrapped.py"))
        assert cls.force == 7.5
    finally:
        sys.modules.pop("driverlib_beside", None)
