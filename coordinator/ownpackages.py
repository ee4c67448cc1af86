"""bmtree's own ``comm``, ``modules`` and ``blackboard``, whatever folders the working directory has.

Python imports from the working directory first (``python -m pytest``, ``python -c``), before the
finder of an editable install. A robot project often has a folder called ``modules/`` (its
definitions, as bmtree's own examples name it): without an ``__init__.py`` it is a namespace
package that hid bmtree's ``modules``, and the pytest plugin failed with ``cannot import name
'default_module_paths' from 'modules' (unknown location)``. Such a folder holds no Python
package, so bmtree's own is taken instead. A regular package of that name elsewhere is left
alone: it may be bmtree's own under another path (catkin's devel space relays each package
through an ``__init__.py`` of its own).
"""
from __future__ import annotations

import importlib.util
import os
import sys

__all__ = ["PACKAGES", "take_own_packages"]

PACKAGES = ("comm", "modules", "blackboard")
_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _hidden_by_namespace(name: str) -> bool:
    """True when ``name`` would be imported as a namespace package (folders without ``__init__.py``)."""
    loaded = sys.modules.get(name)
    if loaded is not None:
        return getattr(loaded, "__file__", None) is None
    spec = importlib.util.find_spec(name)
    return spec is not None and spec.origin in (None, "namespace")


def take_own_packages() -> None:
    """Import bmtree's packages from bmtree's folder where a namespace package (a folder of the working
    directory, or of ``sys.path``, without ``__init__.py``) would hide them."""
    for name in PACKAGES:
        if not _hidden_by_namespace(name):
            continue
        own = os.path.join(_ROOT, name)
        spec = importlib.util.spec_from_file_location(name, os.path.join(own, "__init__.py"),
                                                      submodule_search_locations=[own])
        if spec is None or spec.loader is None:
            raise ImportError("bmtree's own package %r is missing from %s" % (name, own))
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[name]
            raise
