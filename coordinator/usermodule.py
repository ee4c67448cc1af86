"""``bmtree run --sim --module DEF.json=…``: the user's own module beside the simulated robot, read from
the command line and checked before anything starts (a Python class, a C++ module's executable, or a
scripted stand-in)."""
from __future__ import annotations

import os
from typing import Any

from comm.nodeopts import _shown
from coordinator.cliutil import PlainError
from coordinator.errors import TreeErrors, UsageError

__all__ = ["user_module"]


def user_module(spec: str) -> Any:
    """``DEFINITION.json=FILE.py:CLASS`` (or ``=package.module:Class``), ``DEFINITION.json=EXECUTABLE`` (no
    ``:``: a C++ module's node, :mod:`coordinator.simcpp`), or ``DEFINITION.json=SCRIPT.yaml`` (a scripted
    stand-in, :mod:`coordinator.testing.mocknode`) for ``run --sim --module``: a
    :class:`coordinator.simgraph.UserModule`."""
    from coordinator.simcpp import check_executable  # (what only a run with --module needs)
    from coordinator.simgraph import UserModule
    from modules.definition import load_definition

    definition, sep, cls = spec.partition("=")
    if sep and definition and cls.lower().endswith((".yaml", ".yml")):
        loaded = load_definition(definition)
        return UserModule(os.path.abspath(definition), "", loaded, script=_mock_script(cls, loaded, spec))
    if sep and definition and cls and ":" not in cls:
        loaded = load_definition(definition)
        return UserModule(os.path.abspath(definition), "", loaded, check_executable(cls, loaded))
    if not sep or not definition or ":" not in cls:
        raise UsageError("--module takes DEFINITION.json=FILE.py:CLASS, DEFINITION.json=EXECUTABLE or "
                         "DEFINITION.json=SCRIPT.yaml, got %s" % _shown(spec))
    where = cls.rsplit(":", 1)[0]
    if where.endswith(".py"):
        if not os.path.isfile(where):
            raise UsageError("--module %s: no such file %s" % (spec, where))
        with open(where, "rb") as fh:
            source = fh.read()
        try:  # compiled, never run here: a syntax error is one line before the graph starts
            compile(source, where, "exec", dont_inherit=True)
        except SyntaxError as exc:
            raise PlainError("%s:%s:%s: syntax error: %s" % (where, exc.lineno, exc.offset or 0, exc.msg))
        except ValueError as exc:  # NUL bytes: not a Python source file at all
            raise PlainError("%s: not a Python source file (%s)" % (where, exc))
        cls = os.path.abspath(where) + ":" + cls.rsplit(":", 1)[1]
    return UserModule(os.path.abspath(definition), cls, load_definition(definition))


def _mock_script(path: str, definition: Any, spec: str) -> str:
    """The absolute path of a scripted stand-in's script for ``definition``'s module, checked now: its
    mistakes are ``SCRIPT:LINE:COLUMN`` lines before anything starts."""
    from coordinator.testing.mocknode import load_script

    if not os.path.isfile(path):
        raise UsageError("--module %s: no such file %s" % (spec, path))
    try:
        load_script(path, {definition.name: definition})
    except TreeErrors as exc:
        raise PlainError(str(exc)) from None
    return os.path.abspath(path)
