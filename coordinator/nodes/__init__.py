"""The registry of node kinds: one object per kind, one module per family.

Adding a kind means adding its object to its family module's ``KINDS``; the parser,
the data-flow and type checks, the builder, the reference tables and the JSON Schema
all walk this registry.
"""
from __future__ import annotations

from typing import Dict

from coordinator.nodes import call, composites, decorators, ending, include, leaves, loops, switch
from coordinator.nodes.base import NodeKind

__all__ = ["REGISTRY", "NodeKind"]

REGISTRY: Dict[str, NodeKind] = {k.name: k for family in (composites, switch, decorators, loops, call, leaves,
                                                           ending, include)
                                 for k in family.KINDS}
