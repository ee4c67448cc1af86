"""The module definitions a scenario made from a run log needs, as its ``modules:`` key names them.

A run finds definitions in several places (the simulated robot's, the ROS packages' exports on
``ROS_PACKAGE_PATH``, ``$BMTREE_MODULE_PATH``, ``--modules``); a scenario file is run elsewhere (CI, a
laptop without the workspace sourced), where only the simulated robot's are found by default. So the
scenario names, relative to itself, the files of every other definition its run used:

- the paths the run was given (``--modules``, ``--module``: the ``tree`` record's ``modules``);
- for each module the run used (called, waited on, recalled, heard from) that those do not define,
  the file its definition came from (the ``tree`` record's ``definitions``, which ``bmtree run`` writes);
- for a log without ``definitions`` (bmtree before it), or whose file is not here any more, the file
  the same search finds here now, said in the scenario's header.

A module the run knew only from the live graph (its announcement) has no file: ``bmtree replay`` says
so, naming it, when it writes the scenario.
"""
from __future__ import annotations

import os
from typing import Any, Dict, List, Optional, Set, Tuple

from coordinator.runlog import RunLog, definition_files

__all__ = ["definition_paths", "definitions_of", "used_modules", "relative"]


def relative(path: str, folder: str) -> str:
    """``path`` relative to ``folder`` (absolute when it cannot be: another drive)."""
    try:
        return os.path.relpath(os.path.abspath(path), folder)
    except ValueError:
        return os.path.abspath(path)


def used_modules(log: RunLog) -> Set[str]:
    """The modules the run used: the tree's calls and wait_events, the events it received, the values
    its recalls read (whose names a scenario's ``stored:`` qualifies with their function)."""
    out: Set[str] = set()
    for n in log.tree.get("nodes") or []:
        if isinstance(n, dict) and isinstance(n.get("target"), str):
            out.add(n["target"].split(".", 1)[0])
    for r in log.records:
        if r.get("type") == "event" and isinstance(r.get("module"), str):
            out.add(r["module"])
        elif r.get("type") == "recall":
            out.update(v["basic_mod"] for v in r.get("values") or []
                       if isinstance(v, dict) and isinstance(v.get("basic_mod"), str) and v["basic_mod"])
    return out


def _defined_by(paths: List[str]) -> Set[str]:
    """The modules the definition files and folders ``paths`` define (those that load now)."""
    from modules.definition import DefinitionError, load_definitions

    out: Set[str] = set()
    for p in paths:
        try:
            out.update(load_definitions([p]))
        except (DefinitionError, OSError):
            continue
    return out


def _found_here(names: Set[str], given: List[str]) -> Dict[str, str]:
    """Module -> the file its definition is in, as the default search finds it here now (not the
    simulated robot's), for ``names``."""
    from modules.definition import DefinitionError
    from modules.search import default_definitions

    try:
        found = default_definitions(given)
    except (DefinitionError, OSError):
        return {}
    return {k: v for k, v in definition_files(found).items() if k in names}


def definition_paths(log: RunLog) -> Tuple[List[str], List[str]]:
    """The absolute paths of the definitions a scenario of ``log`` needs beyond the simulated robot's
    (module docstring), and what its header says of those the log does not name (one line each)."""
    given = [m for m in log.tree.get("modules") or [] if isinstance(m, str) and os.path.exists(m)]
    out = list(dict.fromkeys(os.path.abspath(m) for m in given))
    wanted = used_modules(log) - _defined_by(given)
    recorded = log.tree.get("definitions")
    recorded = {k: v for k, v in recorded.items() if isinstance(v, str)} if isinstance(recorded, dict) else None
    notes: List[str] = []
    missing: Dict[str, str] = {}   # module -> the file the run used, not here now
    for name in sorted(wanted):
        path = (recorded or {}).get(name)
        if path is not None and os.path.isfile(path):
            out.append(path)
        elif path is not None:
            missing[name] = path
    left = set(missing) if recorded is not None else wanted
    here = _found_here(left, given) if left else {}
    for name in sorted(here):
        out.append(here[name])
    if here and recorded is None:
        notes.append("modules: %s as found here now (ROS packages, $BMTREE_MODULE_PATH): the run log does not say "
                     "which definition files its run used" % ", ".join(sorted(here)))
    elif here:
        notes.append("modules: %s as found here now: the run's (%s) are not here" % (
            ", ".join(sorted(here)), ", ".join(missing[n] for n in sorted(here))))
    gone = sorted(set(missing) - set(here))
    if gone:
        notes.append("modules: the definition files of %s the run used are not here (%s), nor found otherwise" % (
            ", ".join(gone), ", ".join(missing[n] for n in gone)))
    return list(dict.fromkeys(out)), notes


def definitions_of(log: RunLog, paths: Optional[List[str]] = None) -> Dict[str, Any]:
    """The module definitions of ``log``'s scenario: the default ones and ``paths`` (those of
    :func:`definition_paths`); none when they cannot be read now."""
    from modules.definition import DefinitionError
    from modules.search import default_definitions

    try:
        return default_definitions(definition_paths(log)[0] if paths is None else paths)
    except (DefinitionError, OSError):
        return {}
