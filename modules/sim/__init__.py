"""The simulated robot: navigation, vision and speech modules over a YAML world."""
from __future__ import annotations

import os

from modules.sim.robot import SIM_CLASSES, Navigation, Speech, Vision
from modules.sim.world import DEFAULT_WORLD, World, WorldError

__all__ = ["DEFAULT_WORLD", "SIM_CLASSES", "SIM_DIR", "Navigation", "Speech", "Vision", "World",
           "WorldError", "definition_path"]

SIM_DIR = os.path.dirname(__file__)


def definition_path(module: str) -> str:
    return os.path.join(SIM_DIR, module + ".json")
