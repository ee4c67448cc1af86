"""The coordinator: YAML task trees, validated, ticked by py_trees against basic modules."""
from __future__ import annotations

from coordinator.errors import TreeError, TreeErrors
from coordinator.language import load_tree

__all__ = ["TreeError", "TreeErrors", "load_tree", "__version__"]

__version__ = "0.1.0"  # also in setup.py and package.xml (a test keeps the three equal)
