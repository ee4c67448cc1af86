"""bmtree: behaviour-tree task coordinator for ROS 1 basic-module robots."""
from setuptools import setup

setup(
    name="bmtree",
    version="0.1.0",
    description="Behaviour-tree task coordinator for ROS 1 service robots built from basic modules",
    python_requires=">=3.8",
    packages=[
        "comm",
        "modules",
        "modules.sim",
        "blackboard",
        "coordinator",
        "coordinator.testing",
        "basicmodutil_pkg",
    ],
    package_data={
        "modules": ["schema/*.json"],
        "modules.sim": ["*.json", "*.yaml"],
        "coordinator": ["web/*"],
    },
    install_requires=[
        "py_trees>=2.2,<3",
        "rospy_message_converter>=0.5,<0.6",
        "pyyaml>=5.3",
        "jsonschema>=3.2",
        "pydot>=1.4",
        "rich>=10",
    ],
    extras_require={
        "test": ["pytest>=6", "pytest-xdist>=2.5", "ruff", "vermin", "selenium>=4.6"],
    },
    entry_points={
        "console_scripts": [
            "bmtree = coordinator.cli:main",
            "bmtree-module = modules.node:main",
            "bmtree-blackboard = blackboard.node:main",
            "bmtree-bridge = modules.bridge:main",
        ],
        "pytest11": ["bmtree = coordinator.testing.plugin"],
    },
)
