"""The simulated robot as a private ROS graph: master, Blackboard node, sim modules."""
from __future__ import annotations

import json
import os
import subprocess
import time
from typing import Dict, List, NamedTuple, Optional, Sequence

from coordinator.graph import GraphError, RosGraph
from coordinator.simprocess import how_it_ended, log_tail, process_ends, where_stuck
from modules.definition import ModuleDefinition
from modules.discovery import live_modules, node_alive
from modules.sim import DEFAULT_WORLD
from modules.sim.world import World

__all__ = ["SIM_MODULES", "SIM_AT_LEAST", "start_sim", "UserModule", "ModuleStartError", "process_ends"]

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


#: seconds the simulated robot's own processes (Blackboard, navigation, vision, speech, battery) get to
#: announce themselves at the least, whatever ``--wait``: a slow or busy machine takes seconds to start them
SIM_AT_LEAST = 30.0


class _Starting:
    """A process of the graph until it is up: a module announced (its node answering), the Blackboard
    registered and answering."""

    def __init__(self, name: str, proc: subprocess.Popen, module: Optional[str], yours: bool):
        self.name, self.proc, self.module, self.yours = name, proc, module, yours
        self.registered: Optional[float] = None  # when its node was first seen registered with the master
        self.serving: Optional[float] = None  # when it was first seen taking calls: its setup() runs

    @property
    def what(self) -> str:
        if self.yours:
            return "your module %s" % self.module
        return "the simulated robot's %s" % ("module %s" % self.module if self.module else "Blackboard")

    def state(self, now: float) -> str:
        """Where a process still running is in its start-up."""
        if self.serving is not None and self.module is not None:
            return "its process is still running: its setup() has not returned after %.1f s" % (now - self.serving)
        if self.registered is not None:
            return "its process is still running: its node registered with the master %.1f s ago but %s" % (
                now - self.registered, "has not started serving (setup() not reached yet)" if self.module else
                "does not answer")
        return "its process is still running, but its node has not registered with the master (still loading: %s)" % (
            "its class file or its __init__" if self.yours else "rospy, its world")


def _log_lines(graph: RosGraph, name: str) -> str:
    lines = log_tail(graph.log_path(name), 5)
    return "; its log %s %s" % (graph.log_path(name), "ends:\n" + "\n".join("  " + line for line in lines)
                                if lines else "is empty")


def _not_announced(graph: RosGraph, s: _Starting, now: float, within: str) -> str:
    """Why your module ``s`` did not announce itself ``within`` the time it had, its log's last lines; a
    process stuck in its ``setup()`` is killed once it said where it is (a node takes a stop signal only
    once started: stopped as the others are, it would be killed after 3 s)."""
    text = "%s did not announce itself within %s: %s" % (s.what, within, s.state(now))
    lines = _log_lines(graph, s.name)  # before the stacks it prints
    if s.serving is not None:
        at = where_stuck(s.proc, graph.log_path(s.name))
        text += " (it is at %s)" % at if at else ""
        s.proc.kill()
    return text + lines


def _wait_up(graph: RosGraph, starting: List[_Starting], wait: float, started: float) -> None:
    """Until every process in ``starting`` is up. A process that exits is said at once; your modules get
    ``wait`` seconds from ``started`` (and never less than the simulated robot's own took), those of the
    simulated robot :data:`SIM_AT_LEAST` at least.

    Raises:
        ModuleStartError: one of your modules exited, or did not announce itself in time.
        GraphError: a process of the simulated robot did.
    """
    import rosgraph

    from comm.addressing import call_topic
    from comm.rpc import master_api

    master = master_api("/bmtree_sim", 2.0, graph.uri)
    sims_up: Optional[float] = None
    pending = list(starting)
    while True:
        for s in pending:
            if s.proc.poll() is not None:
                text = "%s %s during start-up%s" % (s.what, how_it_ended(s.proc.returncode), _log_lines(graph, s.name))
                if s.yours:
                    raise ModuleStartError(text, s.proc.returncode)
                raise GraphError(text)
        try:
            announced = set(live_modules(graph.uri)) if any(s.module for s in pending) else set()
            subscribed = {n for t, nodes in master.getSystemState()[1] for n in nodes
                          if t in {call_topic(s.module) for s in pending if s.module}}
        except (OSError, rosgraph.masterapi.Error):  # the master is busy: asked again
            announced, subscribed = set(), set()
        now = time.monotonic()
        for s in list(pending):
            if s.module in announced:
                pending.remove(s)
                continue
            try:
                uri = master.lookupNode(s.name)
            except (OSError, rosgraph.masterapi.Error):  # not registered yet, or the master busy
                continue
            if s.registered is None:
                s.registered = now
            if s.module is None and node_alive(uri, 0.5):
                pending.remove(s)
            elif s.serving is None and s.name in subscribed:
                s.serving = now
        if sims_up is None and not any(not s.yours for s in pending):
            sims_up = now
        if not pending:
            return
        late = [s for s in pending if not s.yours] if now > started + max(wait, SIM_AT_LEAST) else []
        if late:
            raise GraphError("the simulated robot did not start within %g s (its own modules get at least %g s, "
                             "whatever --wait): %s" % (max(wait, SIM_AT_LEAST), SIM_AT_LEAST, "; ".join(
                                 "%s did not announce itself: %s%s" % (s.what, s.state(now), _log_lines(graph, s.name))
                                 for s in late)))
        if sims_up is not None and now > started + wait:
            within = "%g s (--wait)" % wait if now - started < wait + 1.0 else \
                "%.1f s (--wait %g s, and until the simulated robot's own modules were up)" % (now - started, wait)
            raise ModuleStartError("\n".join(_not_announced(graph, s, now, within) for s in pending if s.yours), None)
        time.sleep(0.1)


def start_sim(world: Optional[str] = None, ros_home: Optional[str] = None, blackboard: bool = True,
              modules: Sequence[str] = SIM_MODULES, params: Optional[Dict[str, Sequence[str]]] = None,
              timeout: float = SIM_AT_LEAST, user_modules: Sequence[UserModule] = (), address: str = "") -> RosGraph:
    """Bring the graph up and wait until every module has announced itself.

    Args:
        params: extra command-line arguments per module (ROS ``_param:=value`` private parameters).
        timeout: seconds the user's modules get to announce themselves (``--wait``), counted from their
            start (and never less than the simulated robot's own modules took); the simulated robot's
            own get at least :data:`SIM_AT_LEAST`.
        user_modules: the user's own modules, each run by ``bmtree-module`` as its own node.
        address: ROS_IP of the graph (default loopback, see :class:`RosGraph`).

    Raises:
        ModuleStartError: a user's module exited before it announced itself, or did not announce itself
            within ``timeout`` (why, and its log's last lines); at once when it exits.
        GraphError: a process of the simulated robot did.
    """
    graph = RosGraph(ros_home, address=address)
    try:
        graph.start_master()
        starting = []
        if blackboard:
            db = os.path.join(graph.ros_home, "blackboard.sqlite")
            proc = graph.start_node(["-m", "blackboard.node", "--db", db], "/blackboard", wait=False, stop_last=True)
            starting.append(_Starting("/blackboard", proc, None, False))
        started = time.monotonic()
        for m in modules:
            extra = list((params or {}).get(m, ()))
            proc = graph.start_node(["-m", "modules.sim", m, "--world", world or DEFAULT_WORLD, *extra], "/bm_" + m,
                                    wait=False)
            starting.append(_Starting("/bm_" + m, proc, m, False))
        the_world = World.load(world or DEFAULT_WORLD, others=[fn.qualified for um in user_modules
                                                               for fn in um.definition.functions.values()])
        for um in user_modules:
            node = "/bm_" + um.definition.name
            faults = the_world.faults_of(um.definition.name)  # the world's faults of the user's own module
            extra = ["_faults:=%s" % json.dumps(faults)] if faults else []
            # a crash in C code (a driver's library) says where in the log (Fatal Python error: …)
            proc = graph.start_node(["-m", "modules.node", "--definition", um.definition_path,
                                     "--class", um.class_spec, "--node-name", node[1:], *extra], node,
                                    wait=False, env={"PYTHONFAULTHANDLER": "1"})
            starting.append(_Starting(node, proc, um.definition.name, True))
        _wait_up(graph, starting, timeout, started)
    except BaseException:
        graph.close()
        raise
    return graph
