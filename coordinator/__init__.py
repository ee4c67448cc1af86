"""The coordinator: YAML task trees, validated, ticked by py_trees against basic modules."""
from __future__ import annotations

from coordinator.ownpackages import take_own_packages

take_own_packages()  # before anything imports comm or modules: a project's folder "modules/" must not hide them

from coordinator.errors import TreeError, TreeErrors  # noqa: E402
from coordinator.language import load_tree  # noqa: E402

__all__ = ["TreeError", "TreeErrors", "load_tree", "__version__"]

__version__ = "0.1.0"  # also in setup.py and package.xml (a test keeps the three equal)
