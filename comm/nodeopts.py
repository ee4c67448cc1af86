"""Node options from the command line or, for any option not given there, private ROS parameters.

roslaunch users write ``<param name="world" value="..."/>`` inside a ``<node>``; command-line
users write ``--world ...``. Both reach the same argparse namespace: an option left at its
default is looked up as ``~<dest>`` (``--call-timeout`` is ``~call_timeout``) on the master
*before* ``rospy.init_node``, so a node can validate its options and fail fast with exit 2
before it joins the graph. ROS remapping arguments (``name:=value``, ``__name:=``) are
removed from argv first, as ``rospy.myargv`` does.
"""
from __future__ import annotations

import argparse
import math
import os
import xmlrpc.client
from typing import Any, Callable, Dict, List, Optional, Sequence

from comm.address import warn_own_address
from comm.rpc import proxy

__all__ = ["myargv", "private_namespace", "parse_node_args", "node_params", "fill_from_params", "seconds", "factor",
           "count", "PORT", "node_name"]


def seconds(zero: str = "") -> Callable[[Any], float]:
    """An argparse ``type`` for a duration: a finite number of seconds, more than 0 (or also 0
    when ``zero`` says what 0 means, e.g. ``"off"``), so a typo never becomes a busy loop or a
    call that fails at once."""
    def parse(text: Any) -> float:
        try:
            value = float(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError("expected a number of seconds, got %r" % (text,))
        if not math.isfinite(value) or value < 0 or (value == 0 and not zero):
            raise argparse.ArgumentTypeError("expected a finite number of seconds %s, got %r" % (
                "of 0 or more (0: %s)" % zero if zero else "greater than 0", text))
        return value
    parse.__name__ = "seconds"  # argparse names the type in its messages
    return parse


def factor() -> Callable[[Any], float]:
    """An argparse ``type`` for a factor (``replay --speed``: times the recorded pace): a finite
    number greater than 0."""
    def parse(text: Any) -> float:
        try:
            value = float(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError("expected a number (a factor, e.g. 2 for twice as fast), got %r" % (text,))
        if not math.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError("expected a factor greater than 0 (e.g. 2 for twice as fast), got %r"
                                             % (text,))
        return value
    parse.__name__ = "factor"
    return parse


def count(low: int = 1, high: Optional[int] = None, what: str = "") -> Callable[[Any], int]:
    """An argparse ``type`` for a whole number from ``low`` (to ``high``); ``what`` says why."""
    def parse(text: Any) -> int:
        try:
            value = int(text) if not isinstance(text, float) or text.is_integer() else None
        except (TypeError, ValueError):
            value = None
        if value is None or isinstance(text, bool) or value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError("expected a whole number %s%s, got %r" % (
                "from %d to %d" % (low, high) if high is not None else "of at least %d" % low,
                " (%s)" % what if what else "", text))
        return value
    parse.__name__ = "count"
    return parse


PORT = count(0, 65535, "0: any free port")


def node_name(text: Any) -> str:
    """An argparse ``type`` for a node's own name (rospy refuses others in ``init_node``)."""
    import rosgraph.names

    if not isinstance(text, str) or not text or not rosgraph.names.is_legal_base_name(text):
        raise argparse.ArgumentTypeError("%r is not a node name: letters, digits and '_', starting with a letter "
                                         "(no namespace: give one with __ns:=)" % (text,))
    return text


def myargv(argv: Sequence[str]) -> List[str]:
    """argv without ROS remappings (``a:=b``), like ``rospy.myargv``."""
    return [a for a in argv if ":=" not in a]


def _mappings(argv: Sequence[str]) -> Dict[str, str]:
    out = {}
    for a in argv:
        key, sep, value = a.partition(":=")
        if sep and key.startswith("__"):
            out[key] = value
    return out


def private_namespace(argv: Sequence[str], default_name: str) -> str:
    """The node's private namespace (``/ns/name/``) from ``__name:=``/``__ns:=`` or ``ROS_NAMESPACE``."""
    maps = _mappings(argv)
    name = maps.get("__name", default_name)
    if name.startswith("/"):
        return name.rstrip("/") + "/"
    ns = maps.get("__ns", os.environ.get("ROS_NAMESPACE", "/")) or "/"
    ns = "/" + ns.strip("/")
    return (ns.rstrip("/") + "/" + name).rstrip("/") + "/"


def _private_params(argv: Sequence[str], default_name: Optional[str], timeout: float) -> Dict[str, Any]:
    """The node's private parameters on the master, overridden by ``_name:=value`` arguments.

    rospy would set the ``_name:=value`` ones only in ``init_node``; reading them here too lets
    a node check every option before it joins the graph. Without ``__name:=`` and without a
    default name (a node named after its input), only the arguments count.
    """
    import yaml

    out: Dict[str, Any] = {}
    uri = os.environ.get("ROS_MASTER_URI", "")
    if uri and (default_name or "__name" in _mappings(argv)):
        namespace = private_namespace(argv, default_name or "")
        try:
            code, _msg, value = proxy(uri, timeout).getParam(namespace.rstrip("/") + "/_", namespace)
            if code == 1 and isinstance(value, dict):
                out.update(value)
        except (OSError, xmlrpc.client.Error):
            pass
    for a in argv:
        key, sep, value = a.partition(":=")
        if sep and key.startswith("_") and not key.startswith("__"):
            try:
                out[key[1:]] = yaml.safe_load(value)
            except yaml.YAMLError:
                out[key[1:]] = value
    return out


def _as_option(action: argparse.Action, value: Any) -> Any:
    if isinstance(action, argparse._AppendAction):
        if isinstance(value, dict):  # e.g. ~set: {object: book}
            return ["%s=%s" % (k, v) for k, v in value.items()]
        return [str(v) for v in value] if isinstance(value, list) else [str(value)]
    if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)):
        return bool(value)
    if action.type is not None and not isinstance(value, bool):
        return action.type(value) if not isinstance(value, (dict, list)) else value
    return value if isinstance(value, (bool, int, float)) else str(value)


def _given(parser: argparse.ArgumentParser, argv: List[str]) -> set:
    """Dests given on the command line: argparse sets a default only where the namespace has none."""
    unset = object()
    accumulating = (argparse._AppendAction, argparse._AppendConstAction, argparse._CountAction)
    ns = argparse.Namespace(**{a.dest: None if isinstance(a, accumulating) else unset
                               for a in parser._actions if a.dest != argparse.SUPPRESS})
    parser.parse_args(argv, namespace=ns)
    return {k for k, v in vars(ns).items() if v is not unset and v is not None}


def parse_node_args(parser: argparse.ArgumentParser, argv: Sequence[str], default_name: Optional[str],
                    timeout: float = 2.0) -> argparse.Namespace:
    """Parse ``argv`` (ROS remappings removed); fill options not given from private parameters.

    Positional arguments made optional (``nargs="?"``) can come from parameters too. A
    parameter with a wrong type (``_keep:=many``) is a usage error, exit 2, like a bad option.
    The node starts next: an advertised address the other nodes cannot reach (a loopback
    ``ROS_IP`` while the master is on another machine) is warned of here, once per process
    (:func:`comm.address.warn_own_address`).
    """
    plain = myargv(argv)
    args = fill_from_params(parser, parser.parse_args(plain), plain, _private_params(argv, default_name, timeout))
    warn_own_address()
    return args


def node_params(argv: Sequence[str], default_name: Optional[str], timeout: float = 2.0) -> Dict[str, Any]:
    """Private parameters of the node ``argv`` starts (see :func:`_private_params`)."""
    return _private_params(argv, default_name, timeout)


def fill_from_params(parser: argparse.ArgumentParser, args: argparse.Namespace, plain: List[str],
                     params: Dict[str, Any]) -> argparse.Namespace:
    """Set each option of ``parser`` not given in ``plain`` from ``params[dest]``."""
    if not params:
        return args
    given = _given(parser, plain)
    for action in parser._actions:
        if action.dest in ("help", "version") or action.dest in given:
            continue
        names = [o[2:].replace("-", "_") for o in action.option_strings if o.startswith("--")] + [action.dest]
        key = next((n for n in names if n in params), None)
        if key is None:
            continue
        try:
            value = _as_option(action, params[key])
        except (TypeError, ValueError, argparse.ArgumentTypeError) as exc:
            why = ": %s" % exc if isinstance(exc, argparse.ArgumentTypeError) else ""
            parser.error("private parameter ~%s: %r is not valid for %s%s" % (
                key, params[key], "/".join(action.option_strings) or action.dest, why))
        if action.choices is not None and value not in action.choices:
            parser.error("private parameter ~%s: %r is not one of %s" % (
                key, value, ", ".join(map(str, action.choices))))
        setattr(args, action.dest, value)
    return args
