"""What the scripts of nodes/ share: run a bmtree entry point, and when the Python that runs it
(catkin's, /usr/bin/python3 unless the workspace was built with -DPYTHON_EXECUTABLE) lacks a
package bmtree needs, say so in one line, with the fix, and exit 3 instead of a traceback.

Standard library only: it must import where bmtree's dependencies do not.
"""
from __future__ import annotations

import importlib
import os
import sys
from typing import Optional

# import name -> the name pip knows it by, for bmtree's own dependencies (setup.py's install_requires)
PIP = {
    "py_trees": "py_trees",
    "rospy_message_converter": "rospy_message_converter",
    "yaml": "pyyaml",
    "jsonschema": "jsonschema",
    "pydot": "pydot",
    "rich": "rich",
}
# ROS 1's own Python packages: Debian's ros-* packages (make setup installs them) or a sourced ROS
ROS = ("rospy", "rosgraph", "roslib", "rosmaster", "roslaunch", "rostopic", "rospkg", "genpy", "genmsg",
       "std_msgs", "geometry_msgs", "sensor_msgs", "std_srvs", "catkin_pkg")
EXIT_ENVIRONMENT = 3


def _checkout() -> Optional[str]:
    """The bmtree clone these scripts are in (None when they were installed elsewhere)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return root if os.path.isfile(os.path.join(root, "scripts", "setup.sh")) else None


def _workspace(root: str) -> Optional[str]:
    """The catkin workspace whose sources hold ``root`` (None: not in one)."""
    here = os.path.dirname(root)
    while os.path.dirname(here) != here:
        if any(os.path.exists(os.path.join(here, mark)) for mark in (".catkin_workspace", ".catkin_tools")):
            return here
        here = os.path.dirname(here)
    return None


def missing_message(package: str, program: str) -> str:
    """The one line that says which package ``program`` cannot import here, and what to do."""
    python = sys.executable or "python3"
    root = _checkout()
    venv = os.path.join(root, ".venv") if root else None
    ws = _workspace(root) if root else None
    if package in ROS:
        fix = ("install ROS 1's Python packages (`make setup` in the bmtree clone installs Debian's) or source "
               "your ROS setup.bash")
    elif venv and os.path.realpath(sys.prefix) == os.path.realpath(venv):
        fix = "run `make setup` in %s, which installs it into this venv" % root
    elif venv and os.access(os.path.join(venv, "bin", "python"), os.X_OK):
        fix = "build the workspace with bmtree's venv, catkin_make -DPYTHON_EXECUTABLE=%s" % os.path.join(
            venv, "bin", "python")
    elif ws:  # a venv beside src/, not in the package, where rosrun would find its scripts too
        fix = ("build the workspace with a venv that has it (Debian 12's pip refuses the system Python): cd %s && "
               "python3 -m venv --system-site-packages .venv && .venv/bin/pip install -e %s && "
               "catkin_make -DPYTHON_EXECUTABLE=%s" % (ws, os.path.relpath(root, ws), os.path.join(ws, ".venv", "bin", "python")))
    else:
        fix = ("build the workspace with a venv that has bmtree's dependencies, catkin_make "
               "-DPYTHON_EXECUTABLE=/path/to/venv/bin/python (`make setup` in a bmtree clone makes one, .venv)")
    return ("%s: the Python package '%s' is missing for %s (the Python catkin found, unless the workspace was "
            "built with -DPYTHON_EXECUTABLE): %s" % (program, PIP.get(package, package), python, fix))


def _missing(exc: ImportError) -> Optional[str]:
    """The dependency an ImportError says is missing (None: not one of bmtree's dependencies)."""
    name = (getattr(exc, "name", None) or "").split(".")[0]
    return name if isinstance(exc, ModuleNotFoundError) and (name in PIP or name in ROS) else None


def run(module: str, function: str = "main") -> int:
    """``module.function()``'s exit code; 3 with one line on stderr when a dependency is missing."""
    program = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else module
    try:
        return getattr(importlib.import_module(module), function)()
    except ModuleNotFoundError as exc:
        package = _missing(exc)
        if package is None:
            raise
        sys.stderr.write("error: %s\n" % missing_message(package, program))
        return EXIT_ENVIRONMENT
