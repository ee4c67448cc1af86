"""Bad input to the commands and nodes: out-of-range numbers, files and addresses that cannot be
used, a master URI that is not one; each is one line and exit 2 (or 3 for the environment)
before anything starts."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from coordinator.cli import main
from tests.conftest import ROOT, TREES

FIND_APPLE = os.path.join(TREES, "find_apple.yaml")
NO_MASTER = "http://127.0.0.1:9/"  # the discard port: nothing listens there


@pytest.fixture
def no_master(monkeypatch):
    monkeypatch.setenv("ROS_MASTER_URI", NO_MASTER)


@pytest.mark.parametrize("address, says", [
    ("not an ip", "--ros-ip 'not an ip' is not an IP address"),
    ("999.999.1.1", "--ros-ip '999.999.1.1' is not an IP address"),
    ("192.0.2.1", "--ros-ip 192.0.2.1 is not an address of this machine"),  # TEST-NET-1: never assigned
])
def test_ros_ip_must_be_an_address_of_this_machine(no_master, capsys, address, says):
    assert main(["run", "--sim", "--ros-ip", address, FIND_APPLE]) == 2
    out = capsys.readouterr()
    assert says in out.err and "starting the simulated robot" not in out.out + out.err


@pytest.mark.parametrize("uri", ["notaurl", "", "http://127.0.0.1:99999/", "localhost:11311"])
def test_a_master_uri_that_is_not_an_address_is_an_environment_error(monkeypatch, capsys, uri):
    monkeypatch.setenv("ROS_MASTER_URI", uri)
    for argv in (["modules", "--live", "--wait", "0"], ["run", FIND_APPLE, "--wait", "0"], ["control", "pause"]):
        assert main(argv) == 3
        err = capsys.readouterr().err
        assert "ROS_MASTER_URI=%r is not a master's address: expected http://HOST:PORT/" % uri in err, err
        assert "Traceback" not in err


@pytest.mark.parametrize("argv, says", [
    (["run", "--period", "0"], "argument --period: expected a finite number of seconds greater than 0, got '0'"),
    (["run", "--call-timeout", "-1"], "argument --call-timeout: expected a finite number of seconds greater than 0"),
    (["run", "--max-duration", "nan"], "argument --max-duration: expected a finite number of seconds of 0 or more (0: no limit)"),
    (["run", "--liveness", "-1"], "argument --liveness: expected a finite number of seconds of 0 or more (0: off)"),
    (["run", "--wait", "soon"], "argument --wait: expected a number of seconds, got 'soon'"),
    (["run", "--max-bytes", "0"], "argument --max-bytes: expected a whole number of at least 1024 (a ping's answer"),
    (["run", "--keep-runs", "-2"], "argument --keep-runs: expected a whole number of at least 1, got '-2'"),
    (["demo", "--period", "inf"], "argument --period: expected a finite number of seconds greater than 0"),
    (["runs", "-n", "-1"], "argument -n/--limit: expected a whole number of at least 0 (0: all), got '-1'"),
    (["replay", "last", "--port", "70000"], "argument --port: expected a whole number from 0 to 65535"),
    (["watch", "--wait", "-3"], "argument --wait: expected a finite number of seconds of 0 or more (0: do not wait)"),
])
def test_a_number_option_out_of_range_is_exit_2_before_anything_starts(no_master, capsys, argv, says):
    full = argv + ([FIND_APPLE] if argv[0] == "run" else [])
    assert main(full) == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err


def test_render_into_a_folder_that_does_not_exist_is_a_usage_error(no_master, tmp_path, capsys):
    out = tmp_path / "nosuch" / "tree.png"
    assert main(["render", FIND_APPLE, "-o", str(out)]) == 2
    assert capsys.readouterr().err.strip() == "error: -o %s: folder %s does not exist" % (out, out.parent)


def test_a_world_that_cannot_be_read_is_exit_2_before_the_simulated_robot_starts(no_master, tmp_path, capsys):
    bad = tmp_path / "world.yaml"
    bad.write_text("rooms:\n  kitchen: {x: 1, y: [\n")
    for world, says in ((tmp_path / "nosuch.yaml", "cannot read: No such file or directory"),
                        (bad, "%s:3:1: not valid YAML: " % bad)):
        assert main(["run", "--sim", "--world", str(world), FIND_APPLE]) == 2
        out = capsys.readouterr()
        assert out.err.startswith("error: --world %s" % world) and says in out.err
        assert "starting the simulated robot" not in out.out + out.err


def test_a_number_parameter_out_of_range_is_refused_like_the_option(no_master, capsys):
    from comm.nodeopts import fill_from_params
    from coordinator.cli import make_parser

    args = make_parser().parse_args(["run", "t.yaml"])
    with pytest.raises(SystemExit) as exc:
        fill_from_params(args.command_parser, args, ["t.yaml"], {"period": 0})
    assert exc.value.code == 2
    assert ("private parameter ~period: 0 is not valid for --period: expected a finite number of seconds greater "
            "than 0, got 0") in capsys.readouterr().err


def test_node_number_options_are_checked_before_the_node_starts(no_master, tmp_path):
    """bmtree-module and bmtree-blackboard refuse them with exit 2 (the master is not even asked)."""
    for argv, says in (
            (["-m", "modules.node", "--definition", "g.json", "--class", "g.py:G", "--max-bytes", "10"],
             "argument --max-bytes: expected a whole number of at least 1024"),
            (["-m", "modules.node", "--definition", "g.json", "--class", "g.py:G", "_max_bytes:=-1"],
             "private parameter ~max_bytes: -1 is not valid for --max-bytes"),
            (["-m", "blackboard.node", "--keep", "0"], "argument --keep: expected a whole number of at least 1"),
            (["-m", "blackboard.node", "_keep:=-1"], "private parameter ~keep: -1 is not valid for --keep")):
        out = subprocess.run([sys.executable] + argv, cwd=ROOT, capture_output=True, text=True, timeout=60,
                             env=dict(os.environ, ROS_HOME=str(tmp_path)))
        assert out.returncode == 2, out.stderr
        assert says in out.stderr and "Traceback" not in out.stderr


def test_home_relative_paths_from_a_launch_file_are_expanded(no_master, monkeypatch, tmp_path, capsys):
    """roslaunch passes world:=~/w.yaml on as written (no shell expands it)."""
    monkeypatch.setenv("HOME", str(tmp_path))
    (tmp_path / "w.yaml").write_text("rooms: [\n")
    assert main(["run", "--sim", "--world", "~/w.yaml", FIND_APPLE]) == 2
    assert capsys.readouterr().err.startswith("error: --world %s:2:1: not valid YAML" % (tmp_path / "w.yaml"))
    out = subprocess.run([sys.executable, "-m", "modules.sim", "vision", "--world", "~/w.yaml"], cwd=ROOT,
                         capture_output=True, text=True, timeout=60, env=dict(os.environ, HOME=str(tmp_path)))
    assert out.returncode == 2 and out.stderr.startswith("error: %s:2:1: not valid YAML" % (tmp_path / "w.yaml"))
