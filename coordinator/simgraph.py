"""The simulated robot as a private ROS graph: master, Blackboard node, sim modules."""
from __future__ import annotations

import os
import time
from typing import Dict, Optional, Sequence

from coordinator.graph import GraphError, RosGraph
from modules.discovery import live_modules
from modules.sim import DEFAULT_WORLD

__all__ = ["SIM_MODULES", "start_sim"]

SIM_MODULES = ("navigation", "vision", "speech")


def start_sim(world: Optional[str] = None, ros_home: Optional[str] = None, blackboard: bool = True,
              modules: Sequence[str] = SIM_MODULES, params: Optional[Dict[str, Sequence[str]]] = None,
              timeout: float = 30.0) -> RosGraph:
    """Bring the graph up and wait until every module has announced itself.

    Args:
        params: extra command-line arguments per module (ROS ``_param:=value`` private parameters).
    """
    graph = RosGraph(ros_home)
    try:
        graph.start_master()
        names = []
        if blackboard:
            db = os.path.join(graph.ros_home, "blackboard.sqlite")
            graph.start_node(["-m", "blackboard.node", "--db", db], "/blackboard", wait=False)
            names.append("/blackboard")
        for m in modules:
            extra = list((params or {}).get(m, ()))
            graph.start_node(["-m", "modules.sim", m, "--world", world or DEFAULT_WORLD, *extra], "/bm_" + m,
                             wait=False)
            names.append("/bm_" + m)
        for name, proc in zip(names, graph.nodes):
            graph.wait_node(name, timeout, proc)
        end = time.monotonic() + timeout
        while set(modules) - set(live_modules(graph.uri)):
            if time.monotonic() > end:
                raise GraphError("simulated modules did not announce themselves: %s" % ", ".join(
                    sorted(set(modules) - set(live_modules(graph.uri)))))
            time.sleep(0.05)
    except BaseException:
        graph.close()
        raise
    return graph
