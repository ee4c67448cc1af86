"""The simulated robot: navigation, vision, speech and battery modules over a YAML world."""
from __future__ import annotations

import os

from modules.sim.battery import Battery
from modules.sim.robot import Navigation, Speech, Vision
from modules.sim.world import DEFAULT_WORLD, World, WorldError

__all__ = ["DEFAULT_WORLD", "SIM_CLASSES", "SIM_DIR", "Battery", "Navigation", "Speech", "Vision", "World",
           "WorldError", "definition_path"]

SIM_DIR = os.path.dirname(__file__)

SIM_CLASSES = {"navigation": Navigation, "vision": Vision, "speech": Speech, "battery": Battery}


def definition_path(module: str) -> str:
    return os.path.join(SIM_DIR, module + ".json")
