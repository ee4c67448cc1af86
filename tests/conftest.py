"""Shared paths for the test suite (the fixtures come from the bmtree pytest plugin)."""
from __future__ import annotations

import contextlib
import logging
import os
import shutil
import tempfile
import time

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REFERENCE = os.path.join(ROOT, "tests", "data", "reference")  # the original authors' module definitions
TREES = os.path.join(ROOT, "trees")
DATA = os.path.join(ROOT, "tests", "data")


@pytest.fixture(scope="session")
def sim_defs():
    from modules.definition import load_definitions
    from modules.sim import SIM_DIR

    return load_definitions([SIM_DIR])


@pytest.fixture(scope="session", autouse=True)
def private_ros_home():
    """Every run is recorded under $ROS_HOME: keep the suite's runs out of the user's ~/.ros."""
    home = tempfile.mkdtemp(prefix="bmtree-test-home-")
    saved = os.environ.get("ROS_HOME")
    os.environ["ROS_HOME"] = home
    try:
        yield home
    finally:
        if saved is None:
            os.environ.pop("ROS_HOME", None)
        else:
            os.environ["ROS_HOME"] = saved
        shutil.rmtree(home, ignore_errors=True)


# tests/reliability holds the long fault runs of `make reliability` (BMTREE_RELIABILITY=1); the
# reduced versions of the others run in the normal suite.
collect_ignore = [] if os.environ.get("BMTREE_RELIABILITY") == "1" else ["reliability"]


@contextlib.contextmanager
def log_records(name, level=logging.NOTSET):
    """The records logger ``name`` emits meanwhile, as a list (pytest's caplog is off in this suite)."""
    records = []
    handler = logging.Handler(level)
    handler.emit = records.append
    logger = logging.getLogger(name)
    logger.addHandler(handler)
    try:
        yield records
    finally:
        logger.removeHandler(handler)


def until(check, timeout=10.0, said=None):
    """Wait until ``check()`` is true; fail the test after ``timeout`` seconds (``said()``: what the
    failure adds, a log's tail)."""
    end = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < end, "condition not met within %gs%s" % (timeout, "\n" + said() if said else "")
        time.sleep(0.02)


def one_file_trees(tmp_path, bmtree_tree, definitions):
    """``make(root_yaml, inputs_yaml="", **kwargs)`` -> a TreeTest of a one-file tree ``t.yaml`` (with
    ``definitions``): the ``tree`` fixture of the language tests, each with its own modules."""

    def make(root: str, inputs: str = "", **kwargs):
        path = tmp_path / "t.yaml"
        path.write_text("format: 1\n" + ("inputs:\n" + inputs if inputs else "") + "root:\n" + root)
        return bmtree_tree(str(path), definitions=definitions, **kwargs)

    return make


def documented_reactions():
    """trees/README.md's two "Reacting while an action runs" patterns (an event beside the action, a value
    polled beside it), each as a tree's ``root:`` (a sequence of the snippet's nodes): the tests run what
    the reference shows, so the two cannot drift apart."""
    import textwrap

    with open(os.path.join(TREES, "README.md"), encoding="utf-8") as fh:
        section = fh.read().split("\n## Reacting while an action runs\n", 1)[1].split("\n## ", 1)[0]
    blocks = [b.split("```", 1)[0] for b in section.split("```yaml\n")[1:3]]
    return tuple("  sequence:\n" + textwrap.indent(textwrap.dedent(b), "    ") for b in blocks)
