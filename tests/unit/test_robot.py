"""On the robot, without a master: CLI details, definitions from ROS packages, node options,
start-up checks of a module class, the catkin package's files."""
from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

from coordinator.cli import main
from tests.conftest import DATA, ROOT, TREES

GRIPPER = os.path.join(DATA, "gripper")
GRASP = os.path.join(GRIPPER, "grasp.yaml")
FIND_APPLE = os.path.join(TREES, "find_apple.yaml")
NO_MASTER = "http://127.0.0.1:9/"  # the discard port: nothing listens there


@pytest.fixture
def no_master(monkeypatch):
    monkeypatch.setenv("ROS_MASTER_URI", NO_MASTER)
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("BMTREE_MODULE_PATH", raising=False)


# small CLI things -----------------------------------------------------------------------------
def test_version_is_the_same_everywhere(capsys):
    with pytest.raises(SystemExit) as exc:
        from coordinator.cli import make_parser

        make_parser().parse_args(["--version"])
    assert exc.value.code == 0
    printed = capsys.readouterr().out.strip()
    assert main(["--version"]) == 0
    from coordinator import __version__

    assert printed == "bmtree %s" % __version__
    assert ET.parse(os.path.join(ROOT, "package.xml")).getroot().findtext("version") == __version__
    with open(os.path.join(ROOT, "setup.py")) as fh:
        assert 'version="%s"' % __version__ in fh.read()


def test_a_set_key_the_tree_does_not_declare_is_exit_2_with_a_suggestion(no_master, capsys):
    assert main(["run", "--sim", "--set", "objet=book", FIND_APPLE]) == 2
    err = capsys.readouterr().err
    assert "declares no input 'objet'" in err and "did you mean 'object'?" in err
    # without --sim too, and at once: the tree is checked before bmtree waits for a master
    assert main(["run", "--wait", "600", "--set", "objet=book", FIND_APPLE]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'object'?" in err and "waiting" not in err


def test_run_validates_the_tree_before_it_waits_for_a_master(no_master, tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: 1\nroot:\n  sequence:\n    - call: speech.sya\n      inputs: {text: hi}\n")
    assert main(["run", "--wait", "600", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "%s:4:" % bad in err and "did you mean 'say'?" in err and "waiting" not in err


def test_a_module_known_only_to_the_live_graph_is_checked_once_the_master_answers(no_master, tmp_path, capsys):
    tree = tmp_path / "arm.yaml"
    tree.write_text("format: 1\nroot:\n  call: arm.grasp\n")
    assert main(["run", "--wait", "0.2", str(tree)]) == 3  # not refused offline: a live module may define it
    assert "no ROS master at %s yet" % NO_MASTER in capsys.readouterr().err


def test_run_without_a_master_says_so_at_once_and_how_long_it_waits(no_master, capsys):
    assert main(["run", "--wait", "0.3", FIND_APPLE]) == 3
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "no ROS master at %s yet; waiting up to 0.3 s (--wait) ..." % NO_MASTER
    # why, for an operator on a robot ("use --sim" alone was no advice there)
    assert err[-1] == ("error: no ROS master at %s after 0.3 s: nothing listens on port 9 of 127.0.0.1: no master runs "
                       "there (start one: roscore), or ROS_MASTER_URI names the wrong port. Without a robot, bmtree run "
                       "--sim brings up a simulated one" % NO_MASTER)


def test_a_master_host_whose_name_does_not_resolve_is_said_so(capsys, monkeypatch):
    from comm.rpc import master_absence

    assert master_absence("http://nosuchhost.invalid:11311/") == (
        "nosuchhost.invalid is no host name this machine can resolve (check ROS_MASTER_URI)")


def _scenario(tmp_path, body):
    path = tmp_path / "s.scenarios.yaml"
    path.write_text("tree: %s\nscenarios:\n%s" % (FIND_APPLE, body))
    return str(path)


def _no_traceback(text):
    assert "Traceback" not in text, text


def test_scenario_event_without_event_key_is_a_positioned_error(tmp_path, capsys):
    path = _scenario(tmp_path, "  - name: x\n    events:\n      - {at: 1.0, params: {person: Ana}}\n")
    assert main(["test", path]) == 2
    err = capsys.readouterr().err
    _no_traceback(err)
    assert "%s:5:9: an event needs 'event: module.event'" % path in err


def test_scenario_max_duration_not_a_number_names_file_and_line(tmp_path, capsys):
    path = _scenario(tmp_path, "  - name: x\n    max_duration: ten\n")
    assert main(["test", path]) == 2
    err = capsys.readouterr().err
    _no_traceback(err)
    assert "%s:4:19: max_duration must be a number of seconds >= 0, got 'ten'" % path in err


def test_blackboard_dump_of_a_file_that_is_not_a_store(tmp_path, capsys):
    path = tmp_path / "not-a-database"
    path.write_text("hello, I am text\n" * 100)
    assert main(["blackboard", "dump", "--db", str(path)]) == 2
    err = capsys.readouterr().err
    _no_traceback(err)
    assert "is not a Blackboard store" in err
    assert path.read_text() == "hello, I am text\n" * 100  # untouched


def test_blackboard_dump_never_writes_into_the_file_it_is_given(tmp_path, capsys):
    import sqlite3

    empty = tmp_path / "notes.yaml"
    empty.write_text("")
    other = tmp_path / "other.sqlite"
    with sqlite3.connect(str(other)) as db:
        db.execute("CREATE TABLE mine (x)")
    before = other.read_bytes()
    for path in (empty, other):
        assert main(["blackboard", "dump", "--db", str(path)]) == 2
        assert "is not a Blackboard store (it has no table of Blackboard values)" in capsys.readouterr().err
    assert empty.read_bytes() == b"" and other.read_bytes() == before
    assert main(["blackboard", "dump", "--db", str(tmp_path)]) == 2
    assert "is not a Blackboard store (not a file)" in capsys.readouterr().err


def test_blackboard_dump_of_an_unknown_name_says_so(tmp_path, capsys):
    from blackboard.store import Store

    db = str(tmp_path / "bb.sqlite")
    store = Store(db)
    store.add([("room", "std_msgs/String", '{"data": "kitchen"}', "navigation", "go_to", "c1", 1.0)])
    store.close()
    assert main(["blackboard", "dump", "--db", db, "--name", "rooom"]) == 1
    err = capsys.readouterr().err
    assert "has no value named 'rooom' (did you mean 'room'?)" in err
    assert main(["blackboard", "dump", "--db", db, "--name", "room"]) == 0
    assert "kitchen" in capsys.readouterr().out


# --modules adds; definitions from ROS packages ----------------------------------------------
def test_modules_option_adds_to_the_default_definitions(no_master, capsys):
    assert main(["check", "--modules", os.path.join(GRIPPER, "gripper.json"), GRASP]) == 0
    assert main(["check", GRASP]) == 2
    assert "unknown module 'gripper'" in capsys.readouterr().err


def test_a_given_definition_replaces_the_simulated_one_of_the_same_name(no_master, tmp_path, capsys):
    import json

    from modules.sim import definition_path

    with open(definition_path("speech")) as fh:
        speech = json.load(fh)
    speech["Functions"] = [f for f in speech["Functions"] if f["Name"] != "say"]
    (tmp_path / "speech.json").write_text(json.dumps(speech))
    assert main(["check", "--modules", str(tmp_path / "speech.json"), FIND_APPLE]) == 2
    assert "module 'speech' has no function 'say'" in capsys.readouterr().err


def _package(root, name, export='<export><bmtree definitions="definitions"/></export>', defs=True):
    pkg = root / name
    (pkg / "definitions").mkdir(parents=True)
    if defs:
        with open(os.path.join(GRIPPER, "gripper.json")) as fh:
            (pkg / "definitions" / "gripper.json").write_text(fh.read())
    (pkg / "package.xml").write_text('<?xml version="1.0"?>\n<package format="3"><name>%s</name>'
                                     '<version>1.0.0</version>%s</package>\n' % (name, export))
    return pkg


def test_definitions_exported_by_a_package_on_ros_package_path(no_master, tmp_path, monkeypatch, capsys):
    _package(tmp_path / "src", "my_robot")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "src"))
    assert main(["modules"]) == 0
    out = capsys.readouterr().out
    assert "gripper  (" in out and "navigation  (" in out
    assert main(["check", GRASP]) == 0
    assert main(["test", os.path.join(ROOT, "tests", "scenarios", "find_apple.scenarios.yaml")]) == 0


def test_package_search_is_bounded_and_careful(tmp_path):
    from modules.search import MAX_DEPTH, package_exports

    src = tmp_path / "src"
    _package(src, "plain")
    deep = src
    for i in range(MAX_DEPTH + 1):
        deep = deep / ("d%d" % i)
    _package(deep, "too_deep")
    _package(src / "ignored_dir", "ignored")
    (src / "ignored_dir" / "CATKIN_IGNORE").write_text("")
    _package(src / "hidden" / ".cache", "hidden")
    _package(src, "bomb", export='<export><bmtree definitions="&lol;"/></export>')
    bomb = src / "bomb" / "package.xml"
    bomb.write_text('<?xml version="1.0"?>\n<!DOCTYPE package [<!ENTITY lol "definitions">]>\n'
                    + bomb.read_text().split("\n", 1)[1])
    _package(src, "missing", export='<export><bmtree definitions="nowhere"/></export>')
    _package(src, "broken", export='<export><bmtree definitions="definitions"/></export>')
    broken = src / "broken" / "package.xml"
    broken.write_text(broken.read_text().replace("</package>", ""))
    _package(src, "unrelated")  # broken too, but not ours to judge: it does not mention bmtree
    (src / "unrelated" / "package.xml").write_text("<package><name>unrelated</name>")
    (src / "linked").symlink_to(src / "plain")
    problems = []
    found = package_exports(str(src), problems)
    assert [e.package for e in found] == ["plain"]
    assert sorted(problems) == sorted([
        "%s: it declares a DTD or entities, which bmtree does not read; its bmtree export is not used" % bomb,
        "%s: not well-formed XML: no element found: line %d, column 0; its bmtree export is not used" % (
            broken, broken.read_text().count("\n") + 1),
        next(p for p in problems if "package missing exports definitions" in p)])


# a module's class at start-up -----------------------------------------------------------------
def _module_main(*argv):
    return subprocess.run([sys.executable, "-m", "modules.node", *argv], capture_output=True, text=True,
                          timeout=60, env=dict(os.environ, ROS_MASTER_URI=NO_MASTER), stdin=subprocess.DEVNULL)


def test_a_method_whose_parameters_do_not_match_the_inputs_names_both():
    out = _module_main("--definition", os.path.join(GRIPPER, "gripper.json"),
                       "--class", os.path.join(GRIPPER, "wrong_params.py") + ":Gripper")
    assert out.returncode == 2
    _no_traceback(out.stderr)
    assert "method Gripper.open(size) does not match function 'open'" in out.stderr
    assert "parameter 'size' is not an input; input 'width' has no parameter" in out.stderr


def test_signature_check_accepts_defaults_and_kwargs():
    from modules import BasicModule
    from modules.binding import signature_problems
    from modules.definition import load_definition

    d = load_definition(os.path.join(GRIPPER, "gripper.json"))

    class Ok(BasicModule):
        def open(self, width, speed=1.0):
            return {}

        def close(self, **extra):
            return {}

    class Bad(BasicModule):
        def open(self, **inputs):
            return {}

        def close(self, force):
            return {}

    assert signature_problems(d, Ok()) == []
    assert signature_problems(d, Bad()) == [
        "method Bad.close(force) does not match function 'close' of %s (inputs: none): parameter 'force' is "
        "not an input" % d.source]


def test_a_syntax_error_in_the_class_file_is_one_line(tmp_path):
    bad = tmp_path / "gripper_bad.py"
    bad.write_text("from modules import BasicModule\n\n\nclass Gripper(BasicModule)\n    pass\n")
    out = _module_main("--definition", os.path.join(GRIPPER, "gripper.json"), "--class", "%s:Gripper" % bad)
    assert out.returncode == 2
    one_line = re.compile(r"^%s:4:\d+: syntax error: \S.*$" % re.escape(str(bad)))  # the text varies by Python
    assert one_line.match(out.stderr.strip()) and out.stderr.count("\n") == 1, out.stderr
    # and bmtree run --sim --module says the same before it starts anything
    run = subprocess.run([sys.executable, "-m", "coordinator", "run", "--sim", "--module",
                          "%s=%s:Gripper" % (os.path.join(GRIPPER, "gripper.json"), bad), GRASP],
                         capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert run.returncode == 2
    assert run.stderr == out.stderr
    assert "starting" not in run.stdout


def test_an_exception_while_loading_the_class_file_names_file_and_line(tmp_path):
    bad = tmp_path / "boom.py"
    bad.write_text("from modules import BasicModule\nWIDTH = 1 / 0\n")
    out = _module_main("--definition", os.path.join(GRIPPER, "gripper.json"), "--class", "%s:Gripper" % bad)
    assert out.returncode == 2
    assert out.stderr.strip() == "error: %s:2: ZeroDivisionError: division by zero" % bad


def test_an_import_that_fails_in_the_class_file_names_file_and_line_and_a_misspelt_class_a_near_one(tmp_path):
    bad = tmp_path / "arm.py"
    bad.write_text("from modules import BasicModule\nimport rospyy\n")
    out = _module_main("--definition", os.path.join(GRIPPER, "gripper.json"), "--class", "%s:Gripper" % bad)
    assert out.returncode == 2 and out.stderr.strip() == "error: %s:2: No module named 'rospyy'" % bad, out.stderr
    out = _module_main("--definition", os.path.join(GRIPPER, "gripper.json"),
                       "--class", "%s:Griper" % os.path.join(GRIPPER, "gripper.py"))
    assert out.returncode == 2 and "has no class 'Griper' (did you mean 'Gripper'?)" in out.stderr, out.stderr


def test_a_class_file_that_is_not_python_or_a_class_not_of_basic_module_is_one_line(no_master, tmp_path, capsys):
    binary = tmp_path / "binary.py"
    binary.write_bytes(b"class Gripper:\n    pass\0\n")
    plain = tmp_path / "plain.py"
    plain.write_text("class Gripper:\n    def open(self, width):\n        return {}\n")
    definition = os.path.join(GRIPPER, "gripper.json")
    out = _module_main("--definition", definition, "--class", "%s:Gripper" % binary)
    assert out.returncode == 2
    assert out.stderr.strip() == "error: %s: not a Python source file (it contains NUL bytes)" % binary
    out = _module_main("--definition", definition, "--class", "%s:Gripper" % plain)
    assert out.returncode == 2
    assert out.stderr.strip() == ("error: %s: Gripper is not a subclass of BasicModule (from modules.runtime import "
                                  "BasicModule; class Gripper(BasicModule): ...)" % plain)
    out = _module_main("--definition", definition, "--class", "%s:Gripper" % plain, "--node-name", "bad//name")
    assert out.returncode == 2 and "argument --node-name: 'bad//name' is not a node name" in out.stderr
    assert main(["run", "--sim", "--module", "%s=%s:Gripper" % (definition, binary), GRASP]) == 2
    assert capsys.readouterr().err.strip() == (
        "%s: not a Python source file (source code string cannot contain null bytes)" % binary)


def test_run_module_option_errors(no_master, capsys):
    spec = "%s=%s:Gripper" % (os.path.join(GRIPPER, "gripper.json"), os.path.join(GRIPPER, "gripper.py"))
    assert main(["run", "--module", spec, GRASP]) == 2
    assert "it needs --sim" in capsys.readouterr().err
    assert main(["run", "--world", "house.yaml", GRASP]) == 2
    assert "--world chooses the simulated robot's world: it needs --sim" in capsys.readouterr().err
    assert main(["run", "--ros-ip", "10.0.0.5", GRASP]) == 2
    assert "--ros-ip is the simulated robot's address: it needs --sim" in capsys.readouterr().err
    assert main(["run", "--sim", "--module", "gripper.json", GRASP]) == 2
    assert "--module takes DEFINITION.json=FILE.py:CLASS" in capsys.readouterr().err
    assert main(["run", "--sim", "--modules", os.path.join(GRIPPER, "gripper.json"), GRASP]) == 2
    assert "which --sim does not start" in capsys.readouterr().err


# node options: command line or private parameters ------------------------------------------
def test_node_options_from_private_parameter_arguments(no_master):
    from comm.nodeopts import parse_node_args, private_namespace
    from modules.node import make_parser

    args = parse_node_args(make_parser(), ["_definition:=g.json", "_class:=g.py:G", "__name:=bm_g"], None)
    assert (args.definition, args.cls) == ("g.json", "g.py:G")
    args = parse_node_args(make_parser(), ["--definition", "cli.json", "_definition:=g.json"], None)
    assert args.definition == "cli.json"  # the command line wins
    assert private_namespace(["__name:=bm_g", "__ns:=/robot"], "x") == "/robot/bm_g/"
    assert private_namespace([], "blackboard") == "/blackboard/"


def test_node_option_from_a_parameter_is_checked_like_the_option(no_master, capsys):
    from modules.sim.__main__ import main as sim_main

    with pytest.raises(SystemExit) as exc:
        sim_main(["sim", "_module:=navi"])
    assert exc.value.code == 2
    assert "private parameter ~module: 'navi' is not one of battery, navigation, speech, vision" in capsys.readouterr().err


def test_run_options_from_private_parameters(no_master, monkeypatch):
    from comm.nodeopts import fill_from_params
    from coordinator.cli import make_parser

    parser = make_parser()
    args = parser.parse_args(["run", "t.yaml", "--set", "a=1"])
    run_parser = args.command_parser
    fill_from_params(run_parser, args, ["t.yaml", "--set", "a=1"],
                     {"call_timeout": 5, "set": {"b": 2}, "wait": 1.5, "quiet": True})
    assert (args.call_timeout, args.set, args.wait, args.quiet) == (5.0, ["a=1"], 1.5, True)


def test_basic_mod_argument_renames_the_module_and_names_its_node_after_it(monkeypatch):
    from modules.definition import load_definition
    from modules.node import renamed_by_argument

    d = load_definition(os.path.join(GRIPPER, "gripper.json"))
    assert renamed_by_argument(d, ["--definition", "x", "_basic_mod:=left_gripper"]).name == "left_gripper"
    assert renamed_by_argument(d, ["--definition", "x"]) is d
    from modules.definition import DefinitionError

    with pytest.raises(DefinitionError, match="_basic_mod:=two words: not a module name"):
        renamed_by_argument(d, ["_basic_mod:=two words"])


# the catkin package's files ------------------------------------------------------------------
def test_launch_files_use_the_package_executables():
    nodes = set(os.listdir(os.path.join(ROOT, "nodes")))
    for name in ("blackboard", "module", "sim", "run"):
        root = ET.parse(os.path.join(ROOT, "launch", "%s.launch" % name)).getroot()
        for node in root.iter("node"):
            if node.get("pkg") == "bmtree":
                assert node.get("type") in nodes, (name, node.get("type"))
    scripts = [n for n in nodes if n.startswith("bmtree") and not n.endswith(".py")]
    assert len(scripts) == 5, scripts
    for n in scripts:
        path = os.path.join(ROOT, "nodes", n)
        assert os.access(path, os.X_OK), path
        with open(path) as fh:
            module = re.search(r'^    sys.exit\(run\("([\w.]+)"\)\)$', fh.read(), re.M).group(1)
        if n != "bmtree-bridge" or os.path.exists(os.path.join(ROOT, "modules", "bridge.py")):
            assert callable(importlib.import_module(module).main), module


def test_package_xml_names_its_dependencies_by_rosdep_keys():
    root = ET.parse(os.path.join(ROOT, "package.xml")).getroot()
    assert root.get("format") in ("2", "3") and root.findtext("name") == "bmtree"
    deps = {e.text for e in root if e.tag.endswith("depend")}
    assert {"catkin", "rospy", "std_msgs", "geometry_msgs", "rospy_message_converter", "py_trees",
            "python3-yaml", "python3-jsonschema"} <= deps


# launch files: relative paths are from where roslaunch was started -------------------------------
LAUNCH_PATH_ARGS = {"module": ("definition", "class"), "run": ("tree", "modules"), "sim": ("world",), "blackboard": ("db",)}


def _launch_uses(name):
    """The <arg>s of launch/NAME.launch and (element, attribute, value) of each attribute using one."""
    root = ET.parse(os.path.join(ROOT, "launch", "%s.launch" % name)).getroot()
    return list(root.iter("arg")), [(e, k, v) for e in root.iter() for k, v in e.attrib.items() if "arg" in v]


def test_launch_file_path_args_are_made_absolute_against_the_launch_directory():
    for name, paths in LAUNCH_PATH_ARGS.items():
        uses = _launch_uses(name)[1]
        for arg in paths:
            used = [(k, v) for _, k, v in uses if k not in ("if", "unless") and ("$(arg %s)" % arg in v or "arg('%s')" % arg in v)]
            assert used, (name, arg)
            for k, v in used:  # only inside an $(eval) that joins it to $PWD
                assert v.startswith("$(eval ") and "(str(arg('%s')), optenv('PWD'))" % arg in v, (name, k, v)
                assert "$(arg %s)" % arg not in v, (name, k, v)


def test_launch_file_path_args_resolve_with_roslaunch_substitution(monkeypatch):
    from roslaunch import substitution_args
    monkeypatch.setenv("PWD", "/home/me/robot")

    def resolved(name, **given):
        decl, uses = _launch_uses(name)
        args = dict({a.get("name"): a.get("default", "") for a in decl}, **given)
        return {"%s %s" % (e.get("name"), k): substitution_args.resolve_args(v, {"arg": dict(args)})
                for e, k, v in uses if "optenv('PWD')" in v}

    def values(name, **given):  # in order (module.launch's two nodes have one name)
        decl, uses = _launch_uses(name)
        args = dict({a.get("name"): a.get("default", "") for a in decl}, **given)
        return [substitution_args.resolve_args(v, {"arg": dict(args)}) for _e, _k, v in uses if "optenv('PWD')" in v]

    # module.launch: the options on the command line (a node respawned after a master restart finds no parameters)
    assert values("module", module="g", definition="defs/g.json", **{"class": "g.py:G"}) == [
        "--definition '/home/me/robot/defs/g.json' --class '/home/me/robot/g.py:G' --max-bytes 1048576 "
        "--unreachable-caller 0 _basic_mod:=g",
        "--definition '/home/me/robot/defs/g.json' --unreachable-caller 0 _basic_mod:=g "]
    assert values("module", module="g", definition="/opt/g.json", bridge_args="-x 1", unreachable_caller="5",
                  **{"class": "my.g:G"}) == [
        "--definition '/opt/g.json' --class 'my.g:G' --max-bytes 1048576 --unreachable-caller 5 _basic_mod:=g",
        "--definition '/opt/g.json' --unreachable-caller 5 _basic_mod:=g -x 1"]   # a module: as given
    assert "--class '/opt/g.py:G'" in values("module", module="g", definition="g.json", **{"class": "/opt/g.py:G"})[0]
    assert resolved("run", tree="trees/t.yaml", set="object=book", modules="defs") == {
        "coordinator args": "run -q /home/me/robot/trees/t.yaml --set object=book", "modules value": "/home/me/robot/defs"}
    assert resolved("run", tree="/srv/t.yaml")["coordinator args"] == "run -q /srv/t.yaml"
    assert set(resolved("sim", world="w.yaml").values()) == {"/home/me/robot/w.yaml"}
    assert set(resolved("sim", world="/srv/w.yaml").values()) == {"/srv/w.yaml"}
    assert resolved("blackboard", db="bb.sqlite") == {
        "blackboard args": "--db '/home/me/robot/bb.sqlite' --keep 1000 --max-bytes 1048576"}
    assert resolved("blackboard", db=":memory:") == {"blackboard args": "--db ':memory:' --keep 1000 --max-bytes 1048576"}
    assert resolved("blackboard") == {"blackboard args": "--keep 1000 --max-bytes 1048576"}
    monkeypatch.delenv("PWD")  # no $PWD: the path is passed on as given
    assert resolved("blackboard", db="bb.sqlite") == {"blackboard args": "--db 'bb.sqlite' --keep 1000 --max-bytes 1048576"}
