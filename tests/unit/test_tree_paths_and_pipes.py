"""Tree files that are not plain files, and paths that are no paths: a NUL in an include, a pipe with
no writer (it read as an empty file: "a tree file must be a mapping"), a pipe being written
(bash's ``<(...)``, a ``mkfifo``: read whole); ``bmtree schema --write`` and ``runs --dir`` given
what they cannot use: exit 2 with what is wrong, never a hang, never a half-written file."""
from __future__ import annotations

import errno
import os
import resource
import subprocess
import sys
import tempfile
import threading

import pytest

from comm.textfile import read_text
from coordinator.cli import main as bmtree
from tests.conftest import ROOT, TREES

TREE = "format: 1\nname: t\nroot:\n  wait: 1\n"


def test_a_nul_in_an_include_path_is_a_positioned_error(tmp_path, capsys):
    tree = tmp_path / "t.yaml"
    tree.write_text('format: 1\nname: t\nroot:\n  sequence:\n    - include: "sub\\0.yaml"\n')
    assert bmtree(["check", str(tree)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("%s:5:17: cannot read " % tree) and err.endswith(
        ": a file name cannot hold a NUL character\n"), err
    with pytest.raises(OSError, match="NUL"):
        read_text("a\0b")


def test_a_fifo_with_no_writer_is_refused_not_read_as_empty(tmp_path, capsys):
    fifo = tmp_path / "tree.yaml"
    os.mkfifo(str(fifo))
    assert bmtree(["check", str(fifo)]) == 2
    assert capsys.readouterr().err == (
        "%s:1:1: cannot read %s: a pipe that no program writes to (start the writer first)\n" % (fifo, fifo))


def _fifo_with_writer(tmp_path):
    """A FIFO, a reader keeping it open (so what is written stays until read_text reads it) and a writer."""
    fifo = str(tmp_path / "tree.yaml")
    os.mkfifo(fifo)
    keep = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    return fifo, keep, os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)


@pytest.mark.parametrize("first", ["", "format: 1\nname: t\n"])
def test_a_fifo_being_written_is_read_whole(tmp_path, first):
    """The writer has written nothing yet, or a part: read_text waits for the rest (until it closes)."""
    fifo, keep, writer = _fifo_with_writer(tmp_path)
    os.write(writer, first.encode())

    def rest() -> None:
        os.write(writer, TREE[len(first):].encode())
        os.close(writer)

    later = threading.Timer(0.2, rest)
    later.start()
    try:
        assert read_text(fifo) == TREE
    finally:
        later.join()
        os.close(keep)


def test_a_pipe_as_bash_gives_it_is_read(tmp_path, capsys):
    """``bmtree check <(cat tree.yaml)``: /dev/fd/N of a pipe whose writer wrote and exited."""
    r, w = os.pipe()
    os.write(w, TREE.encode())
    os.close(w)
    try:
        assert bmtree(["check", "/dev/fd/%d" % r]) == 0
        assert capsys.readouterr().out == "/dev/fd/%d: ok\n" % r
    finally:
        os.close(r)
    r, w = os.pipe()
    os.close(w)
    try:
        with pytest.raises(OSError, match="no program writes to"):
            read_text("/dev/fd/%d" % r)
    finally:
        os.close(r)


@pytest.mark.parametrize("target,says", [
    ("folder", "cannot read it: Is a directory"),           # exit 3 before
    ("missing.md", "cannot read it: No such file or directory"),
])
def test_schema_write_to_what_is_no_readme_is_exit_2(tmp_path, capsys, target, says):
    (tmp_path / "folder").mkdir()
    path = str(tmp_path / target)
    assert bmtree(["schema", "--markdown", "--write", path]) == 2
    assert capsys.readouterr().err == (
        "error: --write %s: %s; it should be the language reference, trees/README.md\n" % (path, says))


def test_schema_write_to_a_device_is_refused_not_read_for_ever():
    """``/dev/full`` reads zeros without end: bmtree read it until the memory ran out (a process here,
    its memory bounded, so that a regression fails rather than hangs)."""
    def bounded() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))

    done = subprocess.run([sys.executable, "-m", "coordinator", "schema", "--markdown", "--write", "/dev/full"],
                          cwd=ROOT, capture_output=True, timeout=60, preexec_fn=bounded)
    assert (done.returncode, done.stderr.decode()) == (2, "error: --write /dev/full: cannot read it: not a regular "
                                                          "file; it should be the language reference, trees/README.md\n")


def test_schema_write_that_fails_leaves_the_file_whole(tmp_path, capsys, monkeypatch):
    readme = tmp_path / "README.md"
    with open(os.path.join(TREES, "README.md"), encoding="utf-8") as fh:
        old = fh.read().replace("| `sequence` |", "| `old sequence` |")
    readme.write_text(old, encoding="utf-8")

    def full(*args, **kwargs):
        fd, path = real(*args, **kwargs)
        os.close(fd)
        return os.open("/dev/full", os.O_WRONLY), path

    real = tempfile.mkstemp
    monkeypatch.setattr(tempfile, "mkstemp", full)
    assert bmtree(["schema", "--markdown", "--write", str(readme)]) == 2
    assert capsys.readouterr().err == ("error: --write %s: cannot write it: %s (the file is unchanged)\n"
                                       % (readme, os.strerror(errno.ENOSPC)))
    assert readme.read_text(encoding="utf-8") == old and os.listdir(str(tmp_path)) == ["README.md"]
    monkeypatch.setattr(tempfile, "mkstemp", real)
    os.chmod(str(readme), 0o640)
    assert bmtree(["schema", "--markdown", "--write", str(readme)]) == 0
    assert capsys.readouterr().out == "%s: updated\n" % readme
    assert "| `old sequence` |" not in readme.read_text(encoding="utf-8")
    assert os.stat(str(readme)).st_mode & 0o777 == 0o640


@pytest.mark.parametrize("verb", [["runs"], ["replay", "last"]])
def test_runs_dir_that_is_no_folder_is_exit_2(tmp_path, capsys, verb):
    missing = str(tmp_path / "nonexistent")
    assert bmtree(verb + ["--dir", missing]) == 2
    assert capsys.readouterr().err == (
        "error: --dir %s: no such folder (the default is $ROS_HOME/bmtree/runs)\n" % missing)
    (tmp_path / "file").write_text("")
    assert bmtree(verb + ["--dir", str(tmp_path / "file")]) == 2
    assert capsys.readouterr().err == "error: --dir %s: not a folder\n" % (tmp_path / "file")
