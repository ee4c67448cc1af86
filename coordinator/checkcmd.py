"""``bmtree check``: trees and module definitions validated without running them, each problem where it is."""
from __future__ import annotations

import argparse
import os
from typing import Any, Dict

from comm.textfile import read_text
from coordinator.cliutil import EXIT_INVALID, EXIT_OK, definitions_from, err
from coordinator.errors import TreeErrors
from modules.definition import DefinitionError, load_definition

__all__ = ["cmd_check"]


def cmd_check(args: argparse.Namespace) -> int:
    from coordinator.language import load_tree

    defs = definitions_from(args.modules)
    problems = warned = 0
    # definitions given beside trees are checked, and the trees are checked against them (as with --modules)
    given: Dict[str, Any] = {}
    for path in args.trees:
        if not _not_checked_here(path) and _is_definition(path):
            try:
                given[path] = load_definition(path)
            except DefinitionError as exc:
                given[path] = exc
    defs.update({d.name: d for d in given.values() if not isinstance(d, DefinitionError)})
    for path in args.trees:
        other = _not_checked_here(path)
        if other:
            problems += 1
            err(other)
            continue
        if path in given:   # a module's definition: checked as one (it is no tree)
            d = given[path]
            if isinstance(d, DefinitionError):
                problems += 1
                err(str(d))
                continue
            print("%s: ok (the definition of module %s: %d function%s, %d event%s)" % (
                path, d.name, len(d.functions), "" if len(d.functions) == 1 else "s", len(d.events),
                "" if len(d.events) == 1 else "s"))
            continue
        try:
            tree = load_tree(path, defs)
        except TreeErrors as exc:
            problems += len(exc.errors)
            err(str(exc))
            continue
        for w in tree.warnings:
            err(str(w))
        warned += len(tree.warnings)
        n = len(tree.warnings)
        counted = "%d warning%s" % (n, "s" if n > 1 else "")
        if n and args.strict:
            print("%s: refused: %s (--strict makes warnings errors)" % (path, counted))
        else:
            print("%s: ok%s" % (path, " (%s)" % counted if n else ""))
    return EXIT_INVALID if problems or (args.strict and warned) else EXIT_OK


def _is_definition(path: str) -> bool:
    """A ``.json`` file whose top level has ``"Basic Module"``: a module definition, not a tree."""
    import json

    if not path.endswith(".json"):
        return False
    try:
        text = read_text(path)
    except (OSError, ValueError):
        return False   # the tree loader says what is wrong with it
    try:
        data = json.loads(text)
    except (ValueError, RecursionError):
        return '"Basic Module"' in text   # a definition with a JSON mistake: said as JSON, not as YAML
    return isinstance(data, dict) and "Basic Module" in data


# (an XML file is read as a tree: the loader names BehaviorTree.CPP's)
_NOT_TREES = {".py": "a Python module's class", ".pyc": "compiled Python", ".cpp": "C++ source", ".cc": "C++ source",
              ".cxx": "C++ source", ".c": "C source", ".h": "a C/C++ header", ".hpp": "a C++ header",
              ".launch": "a roslaunch file", ".msg": "a ROS message",
              ".srv": "a ROS service", ".action": "a ROS action", ".so": "a compiled library"}


def _not_checked_here(path: str) -> str:
    """Why ``bmtree check`` does not read ``path`` (its extension says it is neither a tree nor a module's
    definition), with what does check it; '' for any other file."""
    ext = os.path.splitext(path)[1].lower()
    what = _NOT_TREES.get(ext)
    if what is None:
        return ""
    cpp = ": the C++ module is checked against its definition when it runs: bmtree-bridge --definition DEF.json " \
          "compares the topics and types its node declares (BM_info) with the definition's, and says what differs"
    how = {".py": ": bmtree-module --definition DEF.json --class %s:CLASS checks the class against the definition "
                  "before it connects to a master" % path, ".cpp": cpp, ".cc": cpp, ".cxx": cpp, ".h": cpp,
           ".hpp": cpp}.get(ext, "")
    return "%s: not a tree or a module definition but %s; bmtree check reads trees (.yaml) and module definitions " \
           "(.json)%s" % (path, what, how)
