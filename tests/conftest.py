"""Shared paths for the test suite (the fixtures come from the bmtree pytest plugin)."""
from __future__ import annotations

import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED_REFERENCE = os.path.join(os.path.dirname(ROOT), "shared", "reference")
TREES = os.path.join(ROOT, "trees")
DATA = os.path.join(ROOT, "tests", "data")


@pytest.fixture(scope="session")
def sim_defs():
    from modules.definition import load_definitions
    from modules.sim import SIM_DIR

    return load_definitions([SIM_DIR])
