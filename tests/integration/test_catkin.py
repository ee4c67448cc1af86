"""bmtree in a catkin workspace: built with Debian's catkin, run through rosrun and roslaunch.

The repository is copied into a temporary workspace beside a team package (``my_robot``) that
exports a gripper's definition in its package.xml; ``catkin_make`` builds both with this test's
Python (its venv has py_trees & co.); every command then runs in a shell that sourced
``devel/setup.bash``, as a user's would. roslaunch brings up its own master on a private port.
"""
from __future__ import annotations

import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
import xmlrpc.client

import pytest

from coordinator.graph import LOOPBACK, free_port
from tests.conftest import DATA, ROOT, until

GRIPPER = os.path.join(DATA, "gripper")
IGNORE = shutil.ignore_patterns(".git", ".venv*", "build", "devel", "install", "*.egg-info", "__pycache__",
                                ".pytest_cache", ".ruff_cache", "results")


def _package_xml(name, export=""):
    return ('<?xml version="1.0"?>\n<package format="3">\n  <name>%s</name>\n  <version>1.0.0</version>\n'
            '  <description>test</description>\n  <maintainer email="t@example.org">t</maintainer>\n'
            '  <license>MIT</license>\n  <buildtool_depend>catkin</buildtool_depend>\n'
            '  <exec_depend>bmtree</exec_depend>\n  <export>%s</export>\n</package>\n' % (name, export))


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    if shutil.which("catkin_make") is None or shutil.which("rosrun") is None:
        pytest.fail("catkin_make and rosrun are needed: `make setup` installs Debian's catkin and rosbash")
    ws = tmp_path_factory.mktemp("catkin_ws")
    shutil.copytree(ROOT, str(ws / "src" / "bmtree"), ignore=IGNORE, symlinks=True)
    team = ws / "src" / "my_robot"
    (team / "definitions").mkdir(parents=True)
    (team / "nodes").mkdir()
    shutil.copy(os.path.join(GRIPPER, "gripper.json"), str(team / "definitions"))
    for f in ("gripper.py", "clumsy.py", "grasp.yaml"):
        shutil.copy(os.path.join(GRIPPER, f), str(team / "nodes" / f))
    (team / "package.xml").write_text(_package_xml("my_robot", '<bmtree definitions="definitions"/>'))
    (team / "CMakeLists.txt").write_text("cmake_minimum_required(VERSION 3.10)\nproject(my_robot)\n"
                                         "find_package(catkin REQUIRED)\ncatkin_package()\n")
    env = dict(os.environ)
    for k in ("CMAKE_PREFIX_PATH", "ROS_PACKAGE_PATH", "PYTHONPATH", "BMTREE_MODULE_PATH"):
        env.pop(k, None)
    env["PWD"] = str(ws)
    out = subprocess.run(["catkin_make", "-C", str(ws), "-DPYTHON_EXECUTABLE=%s" % sys.executable], cwd=str(ws), env=env,
                         capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return ws


class Shell:
    """Commands in a shell that sourced the workspace, on a private master at ``port``."""

    def __init__(self, ws, port):
        self.ws = ws
        self.port = port
        self.home = str(ws / ("home-%d" % port))
        self.procs = []

    def env(self):
        env = {k: v for k, v in os.environ.items() if k not in ("CMAKE_PREFIX_PATH", "ROS_PACKAGE_PATH", "PYTHONPATH",
                                                                 "ROS_HOSTNAME", "BMTREE_MODULE_PATH")}
        env.update(ROS_MASTER_URI="http://%s:%d/" % (LOOPBACK, self.port), ROS_IP=LOOPBACK, ROS_HOME=self.home, PWD=str(self.ws),
                   PYTHONUNBUFFERED="1")
        env.pop("ROS_LOG_DIR", None)
        return env

    def argv(self, command):
        return ["bash", "-c", "source %s && exec %s" % (shlex.quote(str(self.ws / "devel" / "setup.bash")), command)]

    def run(self, command, timeout=180):
        return subprocess.run(self.argv(command), capture_output=True, text=True, timeout=timeout, env=self.env(),
                              cwd=str(self.ws), stdin=subprocess.DEVNULL)

    def start(self, command, name):
        log = open(str(self.ws / ("%s-%d.out" % (name, self.port))), "w")
        proc = subprocess.Popen(self.argv(command), stdout=log, stderr=subprocess.STDOUT, env=self.env(),
                                cwd=str(self.ws), stdin=subprocess.DEVNULL, start_new_session=True)
        proc.log_path = log.name
        log.close()
        self.procs.append(proc)
        return proc

    def wait_modules(self, *names, timeout=60.0):
        from modules.discovery import live_modules

        end = time.monotonic() + timeout
        uri = self.env()["ROS_MASTER_URI"]
        while True:
            try:
                live = set(live_modules(uri))
            except OSError:
                live = set()
            if set(names) <= live:
                return
            for p in self.procs:
                assert p.poll() is None, open(p.log_path).read()
            assert time.monotonic() < end, "modules %s did not come up (live: %s)" % (names, sorted(live))
            time.sleep(0.2)

    def stop(self, p):
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGINT)  # roslaunch's own group, started by this test
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(10)
        if p in self.procs:
            self.procs.remove(p)

    def close(self):
        for p in reversed(list(self.procs)):
            self.stop(p)


@pytest.fixture
def shell(workspace):
    sh = Shell(workspace, free_port())
    yield sh
    sh.close()


def test_rosrun_from_the_workspace(shell, workspace):
    from coordinator import __version__

    out = shell.run("rosrun bmtree bmtree --version")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "bmtree %s" % __version__
    # the Python packages come from the workspace, and my_robot's exported definition is found
    out = shell.run("rosrun bmtree bmtree modules")
    assert out.returncode == 0, out.stderr
    assert "src/bmtree/modules/sim/navigation.json" in out.stdout
    assert "gripper  (src/my_robot/definitions/gripper.json)" in out.stdout
    grasp = workspace / "src" / "my_robot" / "nodes" / "grasp.yaml"
    out = shell.run("rosrun bmtree bmtree check %s" % grasp)
    assert out.returncode == 0, out.stderr
    for exe in ("bmtree-module", "bmtree-blackboard", "bmtree-sim"):
        out = shell.run("rosrun bmtree %s --help" % exe)
        assert out.returncode == 0 and out.stdout.startswith("usage: "), out.stdout + out.stderr


def test_roslaunch_sim_modules_and_trees(shell, workspace):
    team = workspace / "src" / "my_robot"
    definition = team / "definitions" / "gripper.json"
    launch = shell.start("roslaunch -p %d bmtree sim.launch" % shell.port, "sim")
    shell.wait_modules("navigation", "vision", "speech")
    gripper = shell.start("roslaunch bmtree module.launch module:=gripper definition:=%s class:=%s:Gripper" % (
        definition, team / "nodes" / "gripper.py"), "gripper")
    shell.wait_modules("gripper")
    out = shell.run("rosrun bmtree bmtree run -q %s" % (team / "nodes" / "grasp.yaml"))
    assert out.returncode == 0, out.stdout + out.stderr
    assert "grasp_apple: SUCCESS" in out.stdout and "gripper.close" in out.stdout
    # run.launch: the tree as a node, its options as private parameters
    out = shell.run("roslaunch bmtree run.launch tree:=%s set:=object=apple call_timeout:=20" % (
        workspace / "src" / "bmtree" / "trees" / "find_apple.yaml"))
    assert "find_apple: SUCCESS" in out.stdout, out.stdout[-3000:] + out.stderr[-3000:]
    # a launch's option is not left on the master for the next one (the node's name does not change):
    # after max_duration:=0.05, a launch without it ran with the 0.05 s limit and was cut short
    apple = workspace / "src" / "bmtree" / "trees" / "find_apple.yaml"
    out = shell.run("roslaunch bmtree run.launch tree:=%s max_duration:=0.05" % apple)
    assert "reason: stopped after 0.05 s" in out.stdout, out.stdout[-3000:] + out.stderr[-3000:]
    out = shell.run("roslaunch bmtree run.launch tree:=%s" % apple)
    assert "find_apple: SUCCESS" in out.stdout, out.stdout[-3000:] + out.stderr[-3000:]
    assert launch.poll() is None

    # a module whose method raises: the traceback reaches the module's screen and /rosout
    shell.stop(gripper)
    module = shell.start("roslaunch bmtree module.launch module:=gripper definition:=%s class:=%s:Gripper" % (
        definition, team / "nodes" / "clumsy.py"), "clumsy")
    shell.wait_modules("gripper")
    out = shell.run("rosrun bmtree bmtree run -q %s" % (team / "nodes" / "grasp.yaml"))
    assert out.returncode == 1, out.stdout + out.stderr
    assert "ZeroDivisionError: float division by zero" in out.stdout  # the failure reason
    end = time.monotonic() + 30
    screen = rosout = ""
    while time.monotonic() < end:
        with open(module.log_path) as fh:
            screen = fh.read()
        logs = [os.path.join(d, f) for d, _, fs in os.walk(shell.home) for f in fs if f == "rosout.log"]
        rosout = "".join(open(p).read() for p in logs)
        if "Traceback" in screen and "ZeroDivisionError" in rosout:
            break
        time.sleep(0.2)
    # the module's terminal (roslaunch screen output) shows where in the author's file it broke
    assert "Traceback (most recent call last)" in screen and 'clumsy.py", line 7, in open' in screen, screen
    # and /rosout has it (rosout.log is what the rosout node received, what rqt_console shows)
    assert "gripper.open raised" in rosout and "ZeroDivisionError" in rosout, rosout[-3000:]


CPP_TREE = """format: 1
root:
  sequence:
    - call: right_gripper.set_fingers
      inputs: {left: 0.01, right: 0.05}
      outputs: {opening: gap}
    - check: 'gap > 0.039'
    - call: right_gripper.reach
      inputs: {target: {x: 0.3, y: 0.4, z: 0.0}}
      outputs: {distance: far}
    - check: 'far > 0.49'
"""


def test_roslaunch_a_cpp_module_behind_the_bridge(shell, workspace):
    """module.launch's C++ branch: the bridge and the workspace's C++ example, started together,
    under a new module name (``module:=`` renames the bridge's module and the C++ node's topics)."""
    definition = workspace / "src" / "bmtree" / "modules" / "cpp" / "example" / "gripper.json"
    launch = shell.start("roslaunch -p %d bmtree module.launch module:=right_gripper definition:=%s cpp_pkg:=bmtree "
                         "cpp_type:=gripper" % (shell.port, definition), "cpp")
    shell.wait_modules("right_gripper")
    tree = workspace / ("cpp-%d.yaml" % shell.port)
    tree.write_text(CPP_TREE)
    out = shell.run("rosrun bmtree bmtree run -q %s" % tree)
    assert out.returncode == 0, out.stdout + out.stderr + open(launch.log_path).read()[-3000:]
    assert "right_gripper.set_fingers" in out.stdout and "right_gripper.reach" in out.stdout
    topics = shell.run("rostopic list").stdout.split()
    assert "/right_gripper/BM_input" in topics and "/gripper/BM_input" not in topics, topics
    assert launch.poll() is None


SLEEPY = '''import os

from modules import BasicModule

MARK = %r


class Sleepy(BasicModule):
    """Its first open hangs (until killed); the node restarted after that answers at once."""

    def open(self, width):
        if not os.path.exists(MARK):
            with open(MARK, "w") as fh:
                fh.write(str(os.getpid()))
            self.context.sleep(120)
        return {"success": True}

    def close(self):
        return {"success": True, "holding": True}
'''

# each attempt made while the node is down fails module_lost within half a second: the delay between
# attempts leaves the respawn time
RETRIED_OPEN = "format: 1\nroot:\n  retry: 5\n  delay: 1\n  child:\n    call: gripper.open\n    inputs: {width: 0.08}\n    timeout: 60\n"


def test_roslaunch_respawns_a_killed_module_and_the_run_retries_on_it(shell, workspace):
    """module.launch respawn:=true: a module node killed during a call is started again by roslaunch;
    the run notices the death at once (not after the call's 60 s timeout) and its retry reaches
    the respawned node."""
    team = workspace / "src" / "my_robot"
    mark = workspace / ("sleepy-%d.mark" % shell.port)
    module = workspace / ("sleepy_%d.py" % shell.port)
    module.write_text(SLEEPY % str(mark))
    tree = workspace / ("retried-%d.yaml" % shell.port)
    tree.write_text(RETRIED_OPEN)
    shell.start("roslaunch -p %d bmtree module.launch module:=gripper definition:=%s class:=%s:Sleepy respawn:=true "
                "respawn_delay:=0.5" % (shell.port, team / "definitions" / "gripper.json", module), "sleepy")
    shell.wait_modules("gripper")
    run = shell.start("rosrun bmtree bmtree run %s" % tree, "retried")
    end = time.monotonic() + 60
    while not (mark.exists() and mark.read_text()):
        assert run.poll() is None and time.monotonic() < end, open(run.log_path).read()
        time.sleep(0.05)
    first = int(mark.read_text())
    os.kill(first, signal.SIGKILL)
    run.wait(50)
    out = open(run.log_path).read()
    assert run.returncode == 0, out
    calls = [line.split() for line in out.split("calls:")[1].splitlines() if "gripper.open" in line]
    assert calls[0][3] == "module_lost" and calls[-1][3] == "succeeded", out
    assert all(c[3] == "module_lost" for c in calls[1:-1]), out
    code, _, uri = xmlrpc.client.ServerProxy(shell.env()["ROS_MASTER_URI"]).lookupNode("/test", "/bm_gripper")
    assert code == 1 and xmlrpc.client.ServerProxy(uri).getPid("/test")[2] not in (first, 0)  # respawned


RECALL_OPEN = "format: 1\nroot:\n  sequence:\n    - recall: {opened: gripper/open/success}\n    - check: opened\n"
OPEN = "format: 1\nroot:\n  call: gripper.open\n  inputs: {width: 0.05}\n"


def _pid_of(shell, node):
    """The pid of ``node`` on the shell's master (None: no master, not registered, or gone)."""
    try:
        code, _, uri = xmlrpc.client.ServerProxy(shell.env()["ROS_MASTER_URI"]).lookupNode("/test", node)
        return xmlrpc.client.ServerProxy(uri).getPid("/test")[2] if code == 1 else None
    except OSError:
        return None


def test_nodes_respawned_after_a_master_restart_keep_their_options(shell, workspace):
    """A restarted master has lost every private parameter: nodes launched with their options as
    parameters came back without them (a module without --definition, in a respawn loop; a
    Blackboard on the default store, its values gone)."""
    team = workspace / "src" / "my_robot"
    master = shell.start("rosmaster --core -p %d" % shell.port, "master")
    db = workspace / ("kept-%d.sqlite" % shell.port)
    shell.start("roslaunch bmtree blackboard.launch db:=%s respawn:=true respawn_delay:=0.2" % db, "bb")
    until(lambda: _pid_of(shell, "/blackboard"), 30)  # one roslaunch at a time: they race for the run_id
    shell.start("roslaunch bmtree module.launch module:=gripper definition:=%s class:=%s:Gripper respawn:=true "
                "respawn_delay:=0.2" % (team / "definitions" / "gripper.json", team / "nodes" / "gripper.py"),
                "respawned")
    shell.wait_modules("gripper")
    for name, text in (("open", OPEN), ("recall_open", RECALL_OPEN)):
        (workspace / ("%s-%d.yaml" % (name, shell.port))).write_text(text)
    out = shell.run("rosrun bmtree bmtree run -q %s" % (workspace / ("open-%d.yaml" % shell.port)))
    assert out.returncode == 0, out.stdout + out.stderr
    os.kill(master.pid, signal.SIGKILL)
    master.wait(10)
    shell.procs.remove(master)
    shell.start("rosmaster --core -p %d" % shell.port, "master2")
    until(lambda: _pid_of(shell, "/bm_gripper") and _pid_of(shell, "/blackboard"), 30)  # registered again
    for node in ("/bm_gripper", "/blackboard"):
        first = _pid_of(shell, node)
        os.kill(first, signal.SIGKILL)
        until(lambda n=node, f=first: _pid_of(shell, n) not in (None, f), 30)  # respawned
    shell.wait_modules("gripper")
    out = shell.run("rosrun bmtree bmtree run -q %s" % (workspace / ("recall_open-%d.yaml" % shell.port)))
    assert out.returncode == 0, out.stdout + out.stderr  # the Blackboard came back on its own store
    out = shell.run("rosrun bmtree bmtree run -q %s" % (workspace / ("open-%d.yaml" % shell.port)))
    assert out.returncode == 0, out.stdout + out.stderr  # the module came back with its definition and class
