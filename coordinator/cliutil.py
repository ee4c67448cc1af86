"""What the ``bmtree`` verbs share: exit codes, error output, common arguments (the ``type=`` of every
option, also of the nodes' commands, and the environment variables read as options), the master."""
from __future__ import annotations

import argparse
import os
import sys
from typing import Any, Callable, Dict, List, Optional

from comm import nodeopts
from comm.nodeopts import _shown
from coordinator.bounds import MAX_COUNT, MAX_SECONDS
from coordinator.errors import EnvironmentProblem, TreeErrors, UsageError
from coordinator.yamlsrc import load_value
from modules.definition import ModuleDefinition
from modules.search import default_definitions

__all__ = ["EXIT_OK", "EXIT_FAILED", "EXIT_INVALID", "EXIT_ENV", "PlainError", "err", "definitions_from", "set_values",
           "legacy_option", "check_master_uri", "master_up", "wait_master", "MAX_SECONDS", "MAX_COUNT", "seconds",
           "count", "factor", "path_arg", "text", "bind_address", "check_local_address", "from_env", "ros_home_problem"]

EXIT_OK, EXIT_FAILED, EXIT_INVALID, EXIT_ENV = 0, 1, 2, 3



def _most(parse: Callable[[Any], Any], most: float, expected: str, name: str) -> Callable[[Any], Any]:
    """``parse`` (an argparse ``type`` of comm.nodeopts, which says what is wrong below its range) with
    the upper end ``most``, so no number is too large to wait on, sleep or store."""
    def bounded(value: Any) -> Any:
        out = parse(value)
        if out > most:
            raise argparse.ArgumentTypeError("expected %s of at most %s, got %s" % (expected, _number(most),
                                                                                   _shown(value)))
        return out
    bounded.__name__ = name  # argparse names the type in its messages
    return bounded


def _number(x: float) -> str:
    return "%d (a year)" % x if x == MAX_SECONDS else "%g" % x if isinstance(x, float) else "%d" % x


def seconds(zero: str = "", most: float = MAX_SECONDS) -> Callable[[Any], float]:
    """A duration: a finite number of seconds greater than 0 (or 0, when ``zero`` says what it means),
    at most ``most``."""
    return _most(nodeopts.seconds(zero), most, "a number of seconds", "seconds")


def count(low: int = 1, what: str = "", most: int = MAX_COUNT) -> Callable[[Any], int]:
    """A whole number from ``low`` to ``most``; ``what`` says why (or what 0 means)."""
    return _most(nodeopts.count(low, None, what), most, "a whole number", "count")


def factor(least: float = 0.001, most: float = 1000.0) -> Callable[[Any], float]:
    """A factor (``replay --speed``) from ``least`` to ``most``: 1e-300 would sleep past any clock."""
    base = nodeopts.factor()

    def parse(value: Any) -> float:
        out = base(value)
        if not least <= out <= most:
            raise argparse.ArgumentTypeError("expected a factor from %g to %g (e.g. 2 for twice as fast), got %s"
                                             % (least, most, _shown(value)))
        return out
    parse.__name__ = "factor"
    return parse


def text(what: str = "a text") -> Callable[[Any], str]:
    """Some text, never empty (an empty one was mostly a variable left unset: ``--world "$W"``) and
    without NUL (no file name, node name or address holds one)."""
    def parse(value: Any) -> str:
        if isinstance(value, bool):  # a private parameter: as rospy would write it
            value = str(value).lower()
        elif isinstance(value, (int, float)):
            value = str(value)
        if not isinstance(value, str) or not value:
            raise argparse.ArgumentTypeError("expected %s, got %s" % (what, "nothing" if value == "" else
                                                                      _shown(value)))
        if "\0" in value:
            raise argparse.ArgumentTypeError("expected %s, got %s: it holds a NUL character" % (what, _shown(value)))
        return value
    parse.__name__ = "text"
    return parse


def path_arg(what: str = "a file") -> Callable[[Any], str]:
    """A file or folder name (see :func:`text`)."""
    return text("the name of %s" % what)


def bind_address(value: Any) -> str:
    """``--bind``: a host name or IPv4 address of this machine the page can listen on (0.0.0.0: all of
    them); an empty one would silently mean all of them."""
    import socket

    host = text("an address of this machine (127.0.0.1, the default: this machine only; 0.0.0.0: every "
                "address)")(value)
    try:
        found = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        raise argparse.ArgumentTypeError("%s is not an address or a host name that resolves (%s)" % (
            _shown(host), getattr(exc, "strerror", None) or exc))
    problem = _bind_problem(found[0][4][0], socket.AF_INET)
    if problem:
        raise argparse.ArgumentTypeError("%s is not an address of this machine (%s); `ip -brief address` lists them"
                                         % (_shown(host), problem))
    return host


def _bind_problem(address: str, family: int) -> str:
    """Why a socket of this machine cannot listen on ``address`` ('' when it can)."""
    import socket

    try:
        with socket.socket(family, socket.SOCK_STREAM) as sock:
            sock.bind((address, 0))
    except OSError as exc:
        return exc.strerror or str(exc)
    return ""


def check_local_address(option: str, address: str) -> None:
    """UsageError unless ``address`` is an IPv4 unicast address of this machine (``--ros-ip``: the private
    graph listens and advertises there: 0.0.0.0 or a multicast address is no address another node
    connects to, and rosmaster runs on IPv4 unless ROS_IPV6 is set)."""
    import ipaddress
    import socket

    try:
        ip = ipaddress.ip_address(address)
    except ValueError:
        raise UsageError("%s %s is not an IP address (e.g. 192.168.1.10)" % (option, _shown(address)))
    if ip.version != 4:
        raise UsageError("%s %s: the simulated robot's graph runs on IPv4: give an IPv4 address of this machine "
                         "(e.g. 192.168.1.10)" % (option, address))
    if ip.is_unspecified or ip.is_multicast or ip == ipaddress.IPv4Address("255.255.255.255"):
        raise UsageError("%s %s is no address other nodes can connect to: give one address of this machine "
                         "(`ip -brief address` lists them)" % (option, address))
    problem = _bind_problem(address, socket.AF_INET)
    if problem:
        raise UsageError("%s %s is not an address of this machine (%s); `ip -brief address` lists them" % (
            option, address, problem))


def from_env(name: str, parse: Callable[[Any], Any]) -> Any:
    """The environment variable ``name`` read with the option type ``parse``; None when it is unset or
    empty; UsageError (exit 2) naming it and what it takes when it is not one."""
    value = os.environ.get(name, "")
    if not value:
        return None
    try:
        return parse(value)
    except (argparse.ArgumentTypeError, ValueError) as exc:
        raise UsageError("environment variable %s: %s" % (name, exc))


def ros_home_problem(folder: str) -> Optional[EnvironmentProblem]:
    """An EnvironmentProblem (exit 3) naming ROS_HOME when ``folder`` (below it) cannot be made or written
    in; None when it can."""
    try:
        os.makedirs(folder, exist_ok=True)
        writable = os.access(folder, os.W_OK | os.X_OK)
        why = "" if writable else "Permission denied"
    except OSError as exc:
        why = exc.strerror or str(exc)
    except ValueError as exc:   # a NUL in the name
        why = str(exc)
    if not why:
        return None
    home = os.environ.get("ROS_HOME")
    return EnvironmentProblem("cannot write in %s (%s): %s is where ROS and bmtree keep their files; set ROS_HOME "
                              "to a folder you can write in" % (folder, why, "ROS_HOME=%s" % home if home
                                                                 else "~/.ros (ROS_HOME is not set)"))


class PlainError(UsageError):
    """An exit-2 error already written as ``file:line:column: message``."""


def err(text: str) -> None:
    """A line (or lines) on stderr; control characters in it (a module's error text) escaped."""
    from coordinator.runevents import terminal_text

    sys.stderr.write(terminal_text(text.rstrip("\n")) + "\n")
    sys.stderr.flush()  # Python 3.8 buffers a piped stderr in blocks: a watcher of the pipe would wait for it


def definitions_from(paths: Optional[List[str]]) -> Dict[str, ModuleDefinition]:
    """The default definitions plus ``paths`` (``--modules`` adds; a later one replaces a module by name)."""
    return default_definitions(paths or ())


def set_values(pairs: Optional[List[str]]) -> Dict[str, Any]:
    """``--set KEY=VALUE``: YAML values read with the tree files' limits (size, depth, nodes, aliases)."""
    out = {}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        if not sep or not key.isidentifier():
            raise UsageError("--set takes KEY=VALUE, got %s" % _shown(pair))
        try:
            out[key] = load_value(value, "--set " + key) if value else ""
        except TreeErrors as exc:
            e = exc.errors[0]
            where = "column %d" % e.pos.column if e.pos.line == 1 else "line %d, column %d" % e.pos[1:]
            raise UsageError("--set %s: not a plain YAML value (%s): %s" % (key, where, e.message))
    return out


def legacy_option(pairs: Optional[List[str]], defs: Optional[Dict[str, ModuleDefinition]]) -> Dict[str, str]:
    """``--legacy MODULE=/node``: the node of an original module not named ``/<module>``. With ``defs``
    None only the form is checked (before bmtree waits for anything), the module's definition too else."""
    import rosgraph.names

    out = {}
    for pair in pairs or []:
        module, sep, node = str(pair).partition("=")
        if not sep or not module or not node:
            raise UsageError("--legacy takes MODULE=/node, got %s" % _shown(pair))
        node = node if node.startswith("/") else "/" + node
        if not rosgraph.names.is_legal_name(node) or "//" in node or (len(node) > 1 and node.endswith("/")):
            raise UsageError("--legacy %s: %s is not a node name (letters, digits, '_' and '/', each part starting "
                             "with a letter)" % (_shown(pair)[1:-1], _shown(node)))
        if defs is not None and module not in defs:
            raise UsageError("--legacy names module %r, which has no definition (give it with --modules)" % module)
        out[module] = node
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
        raise EnvironmentProblem("ROS_MASTER_URI=%s is not a master's address: expected http://HOST:PORT/, e.g. "
                                 "http://localhost:11311/" % _shown(uri))


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
