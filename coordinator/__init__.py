"""The coordinator: YAML task trees, validated, ticked by py_trees against basic modules."""
from __future__ import annotations

from coordinator.errors import TreeError, TreeErrors
from coordinator.language import load_tree

__all__ = ["TreeError", "TreeErrors", "load_tree"]
