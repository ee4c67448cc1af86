"""Options and environment variables of the commands past what they can mean: numbers too large to wait
on, sleep or store, empty or NUL names, addresses nothing can connect to or listen on, a ROS_HOME that is
no folder. Each is one line naming it (exit 2; 3 for ROS_HOME), before anything waits or starts."""
from __future__ import annotations

import os

import pytest

from coordinator.cli import main
from tests.conftest import TREES

FIND_APPLE = os.path.join(TREES, "find_apple.yaml")


@pytest.fixture
def no_master(monkeypatch, tmp_path):
    monkeypatch.setenv("ROS_MASTER_URI", "http://127.0.0.1:9/")  # the discard port: nothing listens there
    monkeypatch.setenv("ROS_HOME", str(tmp_path / "home"))
    for name in ("BMTREE_KEEP_RUNS", "BMTREE_MAX_LOG_MB"):
        monkeypatch.delenv(name, raising=False)


@pytest.mark.parametrize("argv, says", [
    (["run", FIND_APPLE, "--liveness", "1e10"], "argument --liveness: expected a number of seconds of at most "
                                                "31536000 (a year), got '1e10'"),  # a thread's wait overflowed
    (["run", FIND_APPLE, "--max-duration", "1e300"], "argument --max-duration: expected a number of seconds of at most"),
    (["run", FIND_APPLE, "--max-bytes", "9" * 400], "argument --max-bytes: expected a whole number of at most "
                                                    "1000000000, got '99999"),
    (["blackboard", "dump", "--name", "x", "--history", str(2 ** 63)], "argument --history: expected a whole number "
                                                                       "of at most"),  # SQLite's OverflowError
    (["replay", "last", "--speed", "1e-300"], "argument --speed: expected a factor from 0.001 to 1000"),  # sleep overflow
    (["replay", "last", "--web", "--bind", ""], "argument --bind: expected an address of this machine"),  # all of them
    (["replay", "last", "--web", "--bind", "192.0.2.1"], "argument --bind: '192.0.2.1' is not an address of this machine"),
    (["run", "--sim", FIND_APPLE, "--ros-ip", "0.0.0.0"], "--ros-ip 0.0.0.0 is no address other nodes can connect to"),
    (["run", "--sim", FIND_APPLE, "--port", "70000"], "argument --port: expected a whole number of at most 65535"),
    (["run", FIND_APPLE, "--port", "11400"], "--port is the simulated robot's master's port: it needs --sim"),
    (["run", "--sim", FIND_APPLE, "--ros-ip", "ff02::1"], "--ros-ip ff02::1: the simulated robot's graph runs on IPv4"),
    (["run", FIND_APPLE, "--world", ""], "argument --world: expected the name of a world file, got nothing"),
    (["check", ""], "argument trees: expected the name of a tree file, got nothing"),  # was '.: Is a directory'
    (["render", FIND_APPLE, "-o", "a\0.png"], "argument -o/--output: expected the name of a .dot, .svg or .png file, "
                                              "got 'a\\x00.png': it holds a NUL character"),  # was a ValueError
    (["watch", "--wait", "1e10"], "argument --wait: expected a number of seconds of at most 31536000"),  # hung
    (["control", "pause", "--wait", "1e10"], "argument --wait: expected a number of seconds of at most 31536000"),
    (["watch", "--web", "--bind", ""], "argument --bind: expected an address of this machine"),
    (["run", FIND_APPLE, "--legacy", "navigation=bad name"], "--legacy navigation=bad name: '/bad name' is not a "
                                                             "node name"),  # was checked after --wait, exit 3
])
def test_an_option_past_what_it_can_mean_is_one_line_and_exit_2(no_master, tmp_path, capsys, argv, says):
    argv = argv + (["--wait", "0"] if argv[0] == "run" else ["--dir", str(tmp_path)] if argv[0] == "replay" else [])
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert says in err.strip().splitlines()[-1] and "Traceback" not in err, err


def test_record_in_a_folder_that_cannot_be_made_is_exit_2_before_the_run(no_master, tmp_path, capsys):
    afile = tmp_path / "notes.txt"
    afile.write_text("x\n")
    assert main(["run", FIND_APPLE, "--wait", "0", "--record", str(afile / "run.jsonl")]) == 2
    assert "error: --record %s/run.jsonl: cannot write in %s (Not a directory)" % (afile, afile) in capsys.readouterr().err


@pytest.mark.parametrize("name, value, argv, says", [
    ("BMTREE_KEEP_RUNS", "-5", ["run", FIND_APPLE, "--wait", "0"],
     "error: environment variable BMTREE_KEEP_RUNS: expected a whole number of at least 1, got '-5'"),
    ("BMTREE_MAX_LOG_MB", "0", ["runs"], "error: environment variable BMTREE_MAX_LOG_MB: expected a whole number of "
                                         "at least 1"),  # was the default, silently
    ("BMTREE_MAX_LOG_MB", "x" * 5000, ["runs"], "got 'xxxxxxxx"),
])
def test_a_bad_bmtree_variable_is_exit_2_naming_it(no_master, monkeypatch, capsys, name, value, argv, says):
    monkeypatch.setenv(name, value)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert says in err and len(err) < 300, err


def test_a_ros_home_that_is_a_file_is_exit_3_naming_it(no_master, monkeypatch, tmp_path, capsys):
    home = tmp_path / "home-file"
    home.write_text("")
    monkeypatch.setenv("ROS_HOME", str(home))
    assert main(["run", FIND_APPLE, "--wait", "0"]) == 3
    err = capsys.readouterr().err
    assert "cannot write in %s/bmtree/runs (Not a directory): ROS_HOME=%s is where" % (home, home) in err, err
    assert "no ROS master" not in err


@pytest.mark.parametrize("module, argv", [
    ("modules.bridge", ["--definition", "x.json", "--call-timeout", "1e300"]),
    ("blackboard.node", ["--keep", str(2 ** 63)]),
])
def test_the_nodes_options_have_the_same_limits(capsys, module, argv):
    import importlib

    with pytest.raises(SystemExit) as exc:
        importlib.import_module(module).make_parser().parse_args(argv)
    assert exc.value.code == 2 and "of at most" in capsys.readouterr().err

