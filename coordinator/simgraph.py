"""The simulated robot as a private ROS graph: master, Blackboard node, sim modules."""
from __future__ import annotations

import json
import os
import time
from typing import Dict, NamedTuple, Optional, Sequence

from coordinator.graph import GraphError, RosGraph
from modules.definition import ModuleDefinition
from modules.discovery import live_modules
from modules.sim import DEFAULT_WORLD
from modules.sim.world import World

__all__ = ["SIM_MODULES", "start_sim", "UserModule", "ModuleStartError"]

SIM_MODULES = ("navigation", "vision", "speech", "battery")


class UserModule(NamedTuple):
    """A user's module started beside the simulated ones (``bmtree run --sim --module``)."""

    definition_path: str
    class_spec: str
    definition: ModuleDefinition


class ModuleStartError(GraphError):
    """A user's module exited at start-up; ``code`` is its exit code (2: its class or definition is wrong)."""

    def __init__(self, message: str, code: Optional[int]):
        super().__init__(message)
        self.code = code


def _tail(path: str, lines: int = 5) -> str:
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            return "".join(fh.readlines()[-lines:]).rstrip()
    except OSError:
        return ""


def start_sim(world: Optional[str] = None, ros_home: Optional[str] = None, blackboard: bool = True,
              modules: Sequence[str] = SIM_MODULES, params: Optional[Dict[str, Sequence[str]]] = None,
              timeout: float = 30.0, user_modules: Sequence[UserModule] = (), address: str = "") -> RosGraph:
    """Bring the graph up and wait until every module has announced itself.

    Args:
        params: extra command-line arguments per module (ROS ``_param:=value`` private parameters).
        user_modules: the user's own modules, each run by ``bmtree-module`` as its own node.
        address: ROS_IP of the graph (default loopback, see :class:`RosGraph`).

    Raises:
        ModuleStartError: a user's module exited before it announced itself (its last output lines).
    """
    graph = RosGraph(ros_home, address=address)
    try:
        graph.start_master()
        names = []
        if blackboard:
            db = os.path.join(graph.ros_home, "blackboard.sqlite")
            graph.start_node(["-m", "blackboard.node", "--db", db], "/blackboard", wait=False, stop_last=True)
            names.append("/blackboard")
        for m in modules:
            extra = list((params or {}).get(m, ()))
            graph.start_node(["-m", "modules.sim", m, "--world", world or DEFAULT_WORLD, *extra], "/bm_" + m,
                             wait=False)
            names.append("/bm_" + m)
        mine = {}
        the_world = World.load(world or DEFAULT_WORLD, others=[fn.qualified for um in user_modules
                                                               for fn in um.definition.functions.values()])
        for um in user_modules:
            node = "/bm_" + um.definition.name
            faults = the_world.faults_of(um.definition.name)  # the world's faults of the user's own module
            extra = ["_faults:=%s" % json.dumps(faults)] if faults else []
            mine[node] = graph.start_node(["-m", "modules.node", "--definition", um.definition_path,
                                           "--class", um.class_spec, "--node-name", node[1:], *extra], node,
                                          wait=False)
            names.append(node)
        for name, proc in zip(names, graph.nodes):
            try:
                graph.wait_node(name, timeout, proc)
            except GraphError as exc:
                if name in mine and proc.poll() is not None:
                    out = _tail(os.path.join(graph.ros_home, name.strip("/") + ".out"))
                    raise ModuleStartError("your module %s exited with code %s:\n%s" % (
                        name[4:], proc.returncode, out), proc.returncode) from exc
                raise
        wanted = set(modules) | {um.definition.name for um in user_modules}
        end = time.monotonic() + timeout
        while wanted - set(live_modules(graph.uri)):
            if time.monotonic() > end:
                raise GraphError("modules did not announce themselves: %s" % ", ".join(
                    sorted(wanted - set(live_modules(graph.uri)))))
            time.sleep(0.05)
    except BaseException:
        graph.close()
        raise
    return graph
