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
import sys
import xmlrpc.client
from typing import Any, Callable, Dict, List, Optional, Sequence

from comm.address import warn_own_address
from comm.errors import ProtocolError
from comm.limits import check_depth
from comm.rpc import proxy

__all__ = ["myargv", "private_namespace", "parse_node_args", "node_params", "fill_from_params", "seconds", "factor",
           "count", "PORT", "node_name", "ParamError"]


class ParamError(ValueError):
    """A ``_name:=value`` argument that rospy could not set (not YAML, or no XML-RPC value)."""


def _shown(value: Any) -> str:
    """``repr(value)``, cut short: a parameter's value may be long."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _float(text: Any) -> float:
    """A number given as text or as a number (a parameter), never a bool (``_x:=true`` is no 1 s)."""
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise TypeError("not a number")
    return float(text)


def seconds(zero: str = "") -> Callable[[Any], float]:
    """An argparse ``type`` for a duration: a finite number of seconds, more than 0 (or also 0
    when ``zero`` says what 0 means, e.g. ``"off"``), so a typo never becomes a busy loop or a
    call that fails at once."""
    def parse(text: Any) -> float:
        try:
            value = _float(text)
        except (TypeError, ValueError, OverflowError):
            raise argparse.ArgumentTypeError("expected a number of seconds, got %s" % _shown(text))
        if not math.isfinite(value) or value < 0 or (value == 0 and not zero):
            raise argparse.ArgumentTypeError("expected a finite number of seconds %s, got %s" % (
                "of 0 or more (0: %s)" % zero if zero else "greater than 0", _shown(text)))
        return value
    parse.__name__ = "seconds"  # argparse names the type in its messages
    return parse


def factor() -> Callable[[Any], float]:
    """An argparse ``type`` for a factor (``replay --speed``: times the recorded pace): a finite
    number greater than 0."""
    def parse(text: Any) -> float:
        try:
            value = _float(text)
        except (TypeError, ValueError, OverflowError):
            raise argparse.ArgumentTypeError("expected a number (a factor, e.g. 2 for twice as fast), got %s"
                                             % _shown(text))
        if not math.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError("expected a factor greater than 0 (e.g. 2 for twice as fast), got %s"
                                             % _shown(text))
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
            raise argparse.ArgumentTypeError("expected a whole number %s%s, got %s" % (
                "from %d to %d" % (low, high) if high is not None else "of at least %d" % low,
                " (%s)" % what if what else "", _shown(text)))
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
        if ":=" not in a:
            continue
        parts = [x.strip() for x in a.split(":=")]   # as rospy reads them (rospy.client)
        key = parts[0]
        if len(key) < 2 or key[0] != "_" or key[1] == "_":
            continue
        if len(parts) != 2:
            raise ParamError("private parameter %s: one ':=' between the name and the value, got %s" % (
                key, _shown(a)))
        if parts[1]:   # rospy sets no parameter for an empty value
            out[key[1:]] = _param_value(key, parts[1])
    return out


def _param_value(key: str, text: str) -> Any:
    """The value of ``key:=text`` as rospy would set it; ParamError when it could not (rospy would raise
    from init_node, after the node started): bounded YAML, a value XML-RPC carries."""
    import yaml

    try:
        check_depth(text)
        value = yaml.safe_load(text)
    except (ProtocolError, RecursionError) as exc:
        raise ParamError("private parameter %s: nested too deeply (%s)" % (key, exc or "recursion"))
    except Exception as exc:  # yaml.YAMLError, and PyYAML's own ValueError/TypeError on tags like !!int x
        raise ParamError("private parameter %s:=%s: not valid YAML (%s)" % (key, _shown(text)[1:-1], " ".join(
            str(exc).split())[:120]))
    if value is None:
        raise ParamError("private parameter %s: null is no ROS parameter value (give a value, or quote it: "
                         "%s:=\"null\")" % (key, key))
    try:
        xmlrpc.client.dumps((value,))
    except (TypeError, OverflowError, ValueError, RecursionError) as exc:
        why = ("whole numbers from -2147483648 to 2147483647; quote a larger one as text" if isinstance(exc, OverflowError)
               else "texts, numbers, true/false, lists and mappings with text keys; quote it as text")
        raise ParamError("private parameter %s: %s is no ROS parameter value (%s)" % (key, _shown(text)[1:-1], why))
    return value


def _scalar(action: argparse.Action, value: Any) -> Any:
    """One value of an option, as its ``type`` takes it (text when it has none)."""
    if isinstance(value, (dict, list)) or value is None:
        raise argparse.ArgumentTypeError("expected %s, got %s" % (
            "a single value" if action.type is not None else "a text", "a list" if isinstance(value, list)
            else "a mapping" if isinstance(value, dict) else "nothing"))
    if action.type is not None:
        return action.type(value)
    return str(value).lower() if isinstance(value, bool) else str(value)


def _as_option(action: argparse.Action, value: Any) -> Any:
    """A parameter's value as the option ``action`` would hold it from the command line; TypeError,
    ValueError or argparse.ArgumentTypeError (saying what is expected) when it cannot be."""
    if isinstance(action, argparse._AppendAction):
        if isinstance(value, dict):  # e.g. ~set: {object: book}
            return ["%s=%s" % (k, v) for k, v in value.items()]
        if value == "":   # none (a launch file sets the parameter always, '' when its argument is not given)
            return []
        return [str(v) for v in value] if isinstance(value, list) else [str(value)]
    if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)):
        if not isinstance(value, bool) and value not in (0, 1):
            raise argparse.ArgumentTypeError("expected true or false")
        return bool(value)
    if action.nargs in ("*", "+"):
        return [_scalar(action, v) for v in (value if isinstance(value, list) else [value])]
    return _scalar(action, value)


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
    args = parser.parse_args(plain)
    try:
        params = _private_params(argv, default_name, timeout)
    except ParamError as exc:
        parser.error(str(exc))
    args = fill_from_params(parser, args, plain, params)
    warn_own_address()
    return args


def node_params(argv: Sequence[str], default_name: Optional[str], timeout: float = 2.0) -> Dict[str, Any]:
    """Private parameters of the node ``argv`` starts (see :func:`_private_params`); a ``_name:=value``
    argument rospy could not set is said on stderr, and ends the process with exit 2 (SystemExit)."""
    try:
        return _private_params(argv, default_name, timeout)
    except ParamError as exc:
        sys.stderr.write("error: %s\n" % exc)
        raise SystemExit(2)


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
        except (TypeError, ValueError, OverflowError, argparse.ArgumentTypeError) as exc:
            why = ": %s" % exc if isinstance(exc, argparse.ArgumentTypeError) else ""
            parser.error("private parameter ~%s: %s is not valid for %s%s" % (
                key, _shown(params[key]), "/".join(action.option_strings) or action.dest, why))
        if action.choices is not None and any(v not in action.choices for v in
                                              (value if isinstance(value, list) else [value])):
            parser.error("private parameter ~%s: %s is not one of %s" % (
                key, _shown(value), ", ".join(map(str, action.choices))))
        setattr(args, action.dest, value)
    return args
