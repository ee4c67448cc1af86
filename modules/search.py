"""Where module definitions are found, in order (a later place overrides an earlier one by module name):

1. the simulated robot's definitions (``modules/sim``), so trees check out of the box;
2. definitions exported by ROS packages on ``ROS_PACKAGE_PATH``: a package.xml with
   ``<export><bmtree definitions="defs"/></export>`` (paths relative to the package directory,
   ``${prefix}`` allowed, several separated by spaces);
3. ``$BMTREE_MODULE_PATH`` (os.pathsep-separated files or directories);
4. paths given on the command line (``--modules``).

A robot's own ``navigation.json`` therefore replaces the simulated one; two definitions of
one module in the same place are still an error. The package search is bounded (depth,
directories visited, package.xml size) and does not follow symbolic links, because
``ROS_PACKAGE_PATH`` often names large trees such as ``/usr/share``.
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence

from modules.definition import DefinitionError, ModuleDefinition, load_definitions

__all__ = ["PackageExport", "package_exports", "default_definitions", "MAX_DEPTH", "MAX_DIRS"]

MAX_DEPTH = 5              # directories below a ROS_PACKAGE_PATH entry
MAX_DIRS = 20000           # directories visited in all
MAX_MANIFEST_BYTES = 256 * 1024
SIM_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sim")


@dataclass(frozen=True)
class PackageExport:
    package: str
    manifest: str
    paths: List[str]


def _read_manifest(path: str, problems: List[str]) -> Optional[ET.Element]:
    """A package.xml's root element, or None if it is not a sane manifest (a problem when it
    mentions bmtree: its definitions would disappear without a word).

    No DTDs (so no entity expansion of any kind) and a size bound: ElementTree is then safe.
    """
    try:
        if os.path.getsize(path) > MAX_MANIFEST_BYTES:
            return None
        with open(path, "rb") as fh:
            data = fh.read(MAX_MANIFEST_BYTES + 1)
    except OSError:
        return None
    why = ""
    if b"<!DOCTYPE" in data or b"<!ENTITY" in data:
        why = "it declares a DTD or entities, which bmtree does not read"
    else:
        try:
            return ET.fromstring(data)
        except ET.ParseError as exc:
            why = "not well-formed XML: %s" % exc
    if b"bmtree" in data:
        problems.append("%s: %s; its bmtree export is not used" % (path, why))
    return None


def _export_of(manifest: str, problems: List[str]) -> Optional[PackageExport]:
    root = _read_manifest(manifest, problems)
    if root is None or root.tag != "package":
        return None
    name = (root.findtext("name") or "").strip() or os.path.basename(os.path.dirname(manifest))
    prefix = os.path.dirname(manifest)
    paths: List[str] = []
    for export in root.findall("export"):
        for entry in export.findall("bmtree"):
            value = entry.get("definitions")
            if not value:
                problems.append("%s: <bmtree> export without a 'definitions' attribute" % manifest)
                continue
            for item in value.replace("${prefix}", prefix).split():
                path = item if os.path.isabs(item) else os.path.join(prefix, item)
                if not os.path.exists(path):
                    problems.append("%s: package %s exports definitions %s, which does not exist" % (
                        manifest, name, path))
                    continue
                paths.append(path)
    return PackageExport(name, manifest, paths) if paths else None


def package_exports(ros_package_path: Optional[str] = None, problems: Optional[List[str]] = None) -> List[PackageExport]:
    """Packages on ``ROS_PACKAGE_PATH`` that export bmtree definitions (first of a name wins, as in rospack)."""
    rpp = os.environ.get("ROS_PACKAGE_PATH", "") if ros_package_path is None else ros_package_path
    problems = problems if problems is not None else []
    found: List[PackageExport] = []
    seen_names = set()
    budget = MAX_DIRS
    for root in [p for p in rpp.split(os.pathsep) if p]:
        root = os.path.abspath(root)
        stack = [(root, 0)]
        while stack and budget > 0:
            here, depth = stack.pop()
            budget -= 1
            try:
                entries = sorted(os.scandir(here), key=lambda e: e.name)
            except OSError:
                continue
            names = {e.name for e in entries}
            if "CATKIN_IGNORE" in names or "COLCON_IGNORE" in names:
                continue
            if "package.xml" in names:  # a package: never look inside it for more
                export = _export_of(os.path.join(here, "package.xml"), problems)
                if export is not None and export.package not in seen_names:
                    seen_names.add(export.package)
                    found.append(export)
                continue
            if depth >= MAX_DEPTH:
                continue
            for e in reversed(entries):
                if not e.name.startswith(".") and e.is_dir(follow_symlinks=False):
                    stack.append((e.path, depth + 1))
    return found


def _layer(paths: Sequence[str], into: Dict[str, ModuleDefinition], problems: List[str]) -> None:
    if not paths:
        return
    try:
        into.update(load_definitions(paths))
    except DefinitionError as exc:
        problems.extend(exc.problems)


def default_definitions(extra: Sequence[str] = (), ros_package_path: Optional[str] = None) -> Dict[str, ModuleDefinition]:
    """Every definition bmtree finds by default, plus ``extra`` (see the module docstring for the order)."""
    problems: List[str] = []
    found: Dict[str, ModuleDefinition] = {}
    _layer([SIM_DIR], found, problems)
    exports = package_exports(ros_package_path, problems)
    _layer([p for e in exports for p in e.paths], found, problems)
    env = os.environ.get("BMTREE_MODULE_PATH", "")
    _layer([p for p in env.split(os.pathsep) if p], found, problems)
    _layer(list(extra or ()), found, problems)
    if problems:
        raise DefinitionError(problems)
    return found
