"""What the ``bmtree`` verbs share: exit codes, error output, common arguments, the master."""
from __future__ import annotations

import os
import sys
from typing import Any, Dict, List, Optional

from coordinator.errors import EnvironmentProblem, TreeErrors, UsageError
from coordinator.yamlsrc import load_value
from modules.definition import ModuleDefinition
from modules.search import default_definitions

__all__ = ["EXIT_OK", "EXIT_FAILED", "EXIT_INVALID", "EXIT_ENV", "PlainError", "err", "definitions_from", "set_values",
           "legacy_option", "check_master_uri", "master_up", "wait_master"]

EXIT_OK, EXIT_FAILED, EXIT_INVALID, EXIT_ENV = 0, 1, 2, 3


class PlainError(UsageError):
    """An exit-2 error already written as ``file:line:column: message``."""


def err(text: str) -> None:
    """A line (or lines) on stderr; control characters in it (a module's error text) escaped."""
    from coordinator.runevents import terminal_text

    sys.stderr.write(terminal_text(text.rstrip("\n")) + "\n")


def definitions_from(paths: Optional[List[str]]) -> Dict[str, ModuleDefinition]:
    """The default definitions plus ``paths`` (``--modules`` adds; a later one replaces a module by name)."""
    return default_definitions(paths or ())


def set_values(pairs: Optional[List[str]]) -> Dict[str, Any]:
    """``--set KEY=VALUE``: YAML values read with the tree files' limits (size, depth, nodes, aliases)."""
    out = {}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        if not sep or not key.isidentifier():
            raise UsageError("--set takes KEY=VALUE, got %r" % pair)
        try:
            out[key] = load_value(value, "--set " + key) if value else ""
        except TreeErrors as exc:
            e = exc.errors[0]
            where = "column %d" % e.pos.column if e.pos.line == 1 else "line %d, column %d" % e.pos[1:]
            raise UsageError("--set %s: not a plain YAML value (%s): %s" % (key, where, e.message))
    return out


def legacy_option(pairs: Optional[List[str]], defs: Dict[str, ModuleDefinition]) -> Dict[str, str]:
    """``--legacy MODULE=/node``: the node of an original module not named ``/<module>``."""
    out = {}
    for pair in pairs or []:
        module, sep, node = pair.partition("=")
        if not sep or not module or not node:
            raise UsageError("--legacy takes MODULE=/node, got %r" % pair)
        if module not in defs:
            raise UsageError("--legacy names module %r, which has no definition (give it with --modules)" % module)
        out[module] = node if node.startswith("/") else "/" + node
    return out


def check_master_uri() -> None:
    """EnvironmentProblem (exit 3) unless ``$ROS_MASTER_URI`` is an ``http://host:port/`` address
    (rosgraph raises a bare ValueError on anything else)."""
    import urllib.parse

    uri = os.environ.get("ROS_MASTER_URI")
    if uri is None:
        return  # rosgraph's default, http://localhost:11311/
    try:
        parts = urllib.parse.urlsplit(uri)
        ok = parts.scheme == "http" and bool(parts.hostname) and parts.port is not None
    except ValueError:  # a port out of range
        ok = False
    if not ok:
        raise EnvironmentProblem("ROS_MASTER_URI=%r is not a master's address: expected http://HOST:PORT/, e.g. "
                                 "http://localhost:11311/" % uri)


#: seconds one question to the master may take while bmtree waits for it (one that is stopped, or
#: whose machine is unreachable, answers nothing: rosgraph's own check waited minutes, Ctrl-C ignored)
MASTER_QUESTION = 1.0


def master_up(timeout: float) -> bool:
    """True once the master answers; False when it did not within ``timeout`` seconds (at most
    about a second more: every question is bounded). A Ctrl-C meanwhile is raised."""
    import time

    import rosgraph

    from comm.rpc import master_answers

    check_master_uri()
    uri = rosgraph.get_master_uri()
    end = time.monotonic() + timeout
    while True:
        left = end - time.monotonic()
        if master_answers(min(MASTER_QUESTION, max(left, 0.5)), uri):
            return True
        left = end - time.monotonic()
        if left <= 0:
            return False
        time.sleep(min(0.2, left))


def wait_master(timeout: float) -> bool:
    """Wait for the master, saying at once that it is not there yet and for how long bmtree waits."""
    if master_up(0.0):
        return True
    err("no ROS master at %s yet; waiting up to %g s (--wait) ..." % (
        os.environ.get("ROS_MASTER_URI", "http://localhost:11311/"), timeout))
    return master_up(timeout)
