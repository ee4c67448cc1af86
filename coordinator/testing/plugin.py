"""The bmtree pytest plugin (entry point ``pytest11: bmtree``).

Fixtures:
    bmtree_tree: ``bmtree_tree("trees/x.yaml", inputs={...}, modules=["modules/gripper.json"])`` -> a TreeTest
        (mocked modules, simulated clock); ``inputs`` must give every tree input without a default (else a
        UsageError there); ``modules`` adds your definitions, as does the ini key ``bmtree_modules``;
        ``strict=True`` (or the ini key ``bmtree_strict_mocks = true``) fails a test whose tree calls a
        function it did not script. An invalid tree fails the test at that line with its ``file:line:column``
        errors, without the kit's frames.
    ros_master: a real ``rosmaster --core`` on a free port for the session (its own ROS_HOME); yields the URI.
    ros_graph: start nodes as processes against that master; they are stopped (by pid) after the test.
    ros_probe: publish/collect topics from the test process (one rospy node per session).

Option ``--bmtree-coverage``: after the session, report which tree nodes ran and their outcomes.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from typing import Any, Callable, Iterator, List

import pytest

from coordinator.errors import UsageError
from coordinator.testing.kit import Coverage, TreeTest

__all__ = ["bmtree_tree", "ros_master", "ros_graph", "ros_probe"]

_COVERAGE = pytest.StashKey[Coverage]() if hasattr(pytest, "StashKey") else None


def pytest_addoption(parser: Any) -> None:
    group = parser.getgroup("bmtree")
    group.addoption("--bmtree-coverage", action="store_true", default=False,
                    help="report which nodes of the tested trees ran and which outcomes they reached")
    parser.addini("bmtree_strict_mocks", type="bool", default=False,
                  help="a call to a mocked function the test did not script fails the test (default: it "
                       "succeeds with empty outputs, and a warning lists those whose outputs say more)")
    parser.addini("bmtree_modules", type="linelist", default=[],
                  help="module definition files or folders every bmtree_tree gets (your own modules), "
                       "relative to the ini file; '#' starts a comment")


def _ini_folder(config: Any) -> str:
    return os.path.dirname(str(config.inipath)) if getattr(config, "inipath", None) else str(config.rootpath)


def tree_path(path: str, config: Any, test_file: str) -> str:
    """Where ``bmtree_tree``'s ``path`` is: as given (absolute, or from the working directory), else
    beside the ini file (as ``bmtree_modules``), else beside the test file; so a test finds its tree
    wherever pytest was started. UsageError naming every place tried when it is in none."""
    if os.path.isabs(path) or os.path.exists(path):
        return path
    tried = [os.path.abspath(path)]
    for folder in (_ini_folder(config), os.path.dirname(os.path.abspath(test_file))):
        candidate = os.path.normpath(os.path.join(folder, path))
        if os.path.exists(candidate):
            return candidate
        if candidate not in tried:
            tried.append(candidate)
    raise UsageError("bmtree_tree(%r): no such file; tried %s (a relative path is taken from the working "
                     "directory, then from the ini file's folder, then from the test file's)" % (
                         path, ", ".join(tried)))


def configured_modules(config: Any) -> List[str]:
    """The ini key ``bmtree_modules``: paths separated by spaces or lines, relative to the ini file.
    A ``#`` comment ends a line (pytest's own ``pathlist`` would take each word of an end-of-line
    comment for a file, and every test would fail)."""
    base = _ini_folder(config)
    paths = []
    for line in config.getini("bmtree_modules"):
        for word in line.split():
            if word.startswith("#"):
                break
            paths.append(os.path.normpath(os.path.join(base, os.path.expanduser(word))))
    return paths


def pytest_configure(config: Any) -> None:
    config.addinivalue_line("markers", "ros: needs a real rosmaster (integration test)")
    if _COVERAGE is not None:
        config.stash[_COVERAGE] = Coverage()
    else:  # pytest < 7
        config._bmtree_coverage = Coverage()


def _coverage(config: Any) -> Coverage:
    return config.stash[_COVERAGE] if _COVERAGE is not None else config._bmtree_coverage


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: Any) -> None:
    if config.getoption("--bmtree-coverage"):
        cov = _coverage(config)
        if cov.trees:
            terminalreporter.write_sep("-", "bmtree tree coverage")
            terminalreporter.write_line(cov.report())


@pytest.fixture
def bmtree_tree(request: Any) -> Callable[..., TreeTest]:
    """Factory: ``bmtree_tree(path, definitions=None, inputs=None, modules=(), strict=None)`` -> TreeTest;
    ``inputs`` gives the tree's inputs (every one without a default); ``modules`` come after the ini key
    ``bmtree_modules``'s; ``strict`` (default: the ini key ``bmtree_strict_mocks``): an unscripted call fails."""
    cov = _coverage(request.config)
    configured = configured_modules(request.config)
    strict = bool(request.config.getini("bmtree_strict_mocks"))

    def make(path: str, **kwargs: Any) -> TreeTest:
        __tracebackhide__ = True
        given = configured + [os.path.abspath(m) for m in kwargs.get("modules") or ()]
        kwargs["modules"] = list(dict.fromkeys(given))  # a file given both ways is loaded once
        if kwargs.get("strict") is None:
            kwargs["strict"] = strict
        try:
            found = tree_path(path, request.config, str(getattr(request.node, "path", None) or request.node.fspath))
        except UsageError as exc:
            raise exc.with_traceback(None)
        return TreeTest(found, coverage=cov, **kwargs)

    return make


@pytest.fixture(scope="session")
def ros_master() -> Iterator[str]:
    from coordinator.graph import RosGraph

    home = tempfile.mkdtemp(prefix="bmtree-test-ros-")
    graph = RosGraph(home)
    uri = graph.start_master()
    restore = graph.adopt(home=True)  # the probe and in-process coordinators advertise loopback
    try:
        yield uri
    finally:
        graph.close()
        shutil.rmtree(home, ignore_errors=True)
        restore()


@pytest.fixture
def ros_graph(ros_master: str) -> Iterator[Any]:
    from coordinator.graph import RosGraph

    graph = RosGraph(os.environ["ROS_HOME"], master_uri=ros_master)
    try:
        yield graph
    finally:
        graph.close()


@pytest.fixture(scope="session")
def ros_probe(ros_master: str) -> Any:
    from coordinator.testing.ros import RosProbe

    return RosProbe()
