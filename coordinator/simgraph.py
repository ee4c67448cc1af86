"""The simulated robot as a private ROS graph: master, Blackboard node, sim modules, and the user's own
modules (``--module``: a Python class, or a C++ node with its bridge, :mod:`coordinator.simcpp`)."""
from __future__ import annotations

import json
import os
import subprocess
import threading
import time
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple

from coordinator.graph import GraphError, RosGraph
from coordinator.simcpp import pair_names, start_pair, watch_pair
from coordinator.simprocess import how_it_ended, log_tail, process_ends, where_stuck
from modules.definition import ModuleDefinition
from modules.discovery import live_modules, node_alive
from modules.sim import DEFAULT_WORLD
from modules.sim.world import World

__all__ = ["SIM_MODULES", "SIM_AT_LEAST", "start_sim", "SimGraph", "UserModule", "ModuleStartError", "process_ends"]

SIM_MODULES = ("navigation", "vision", "speech", "battery")


class UserModule(NamedTuple):
    """A user's module started beside the simulated ones (``bmtree run --sim --module``): a Python class
    (``class_spec``, ``FILE.py:CLASS``, run by ``bmtree-module``) or a C++ module's node (``executable``, its
    absolute path, checked before anything starts: :func:`coordinator.simcpp.check_executable`; run with a
    ``bmtree-bridge``), or a scripted stand-in (``script``, the absolute path of a mock node's script,
    checked before anything starts: :mod:`coordinator.testing.mocknode`) for a module not written yet."""

    definition_path: str
    class_spec: str
    definition: ModuleDefinition
    executable: Optional[str] = None
    script: Optional[str] = None


class SimGraph(RosGraph):
    """The simulated robot's graph: ``ended_with`` (a process bmtree ended because the other of its C++
    module's pair ended: ``(what that one is, its node)``) and ``closing`` (set once the graph stops, when
    an end is no longer a module's death) for :func:`coordinator.simcpp.watch_pair`."""

    def __init__(self, ros_home: Optional[str] = None, master_uri: str = "", address: str = ""):
        super().__init__(ros_home, master_uri, address)
        self.ended_with: Dict[str, Tuple[str, str]] = {}
        self.closing = threading.Event()

    def close(self) -> None:
        self.closing.set()
        super().close()


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
    registered and answering. ``role``: "" (a Python module's node, the Blackboard), ``cpp`` (a C++
    module's node) or ``bridge`` (its bridge): the pair is up once the bridge announced the module."""

    def __init__(self, name: str, proc: subprocess.Popen, module: Optional[str], yours: bool, role: str = ""):
        self.name, self.proc, self.module, self.yours, self.role = name, proc, module, yours, role
        self.registered: Optional[float] = None  # when its node was first seen registered with the master
        self.serving: Optional[float] = None  # when it was first seen taking calls: its setup() runs

    @property
    def topic(self) -> str:
        """The topic its node subscribes once it takes calls ("" for the Blackboard)."""
        from comm.addressing import call_topic

        if self.module is None:
            return ""
        return "/%s/BM_input" % self.module if self.role == "cpp" else call_topic(self.module)

    @property
    def what(self) -> str:
        if self.role:
            return "your module %s's %s %s" % (self.module, "C++ node" if self.role == "cpp" else "bridge", self.name)
        if self.yours:
            return "your module %s" % self.module
        return "the simulated robot's %s" % ("module %s" % self.module if self.module else "Blackboard")

    def state(self, now: float) -> str:
        """Where a process still running is in its start-up."""
        if self.role == "cpp":
            if self.registered is None:
                return "its C++ node's process is still running, but its node %s has not registered with the " \
                       "master (its main() has not made a ros::NodeHandle)" % self.name
            return "its C++ node %s registered with the master %.1f s ago %s" % (
                self.name, now - self.registered, "and subscribes %s, but its bridge has not connected to it (is "
                "its constructor still running?)" % self.topic if self.serving is not None else
                "but does not subscribe %s (its module not constructed yet)" % self.topic)
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
    text = "your module %s did not announce itself within %s: %s" % (s.module, within, s.state(now))
    lines = _log_lines(graph, s.name)  # before the stacks it prints
    if s.serving is not None and not s.role:  # a Python node prints its stacks on SIGUSR1
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
            subscribed = {(t, n) for t, nodes in master.getSystemState()[1] for n in nodes
                          if t in {s.topic for s in pending if s.module}}
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
            elif s.serving is None and (s.topic, s.name) in subscribed:
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
            raise ModuleStartError("\n".join(_not_announced(graph, s, now, within) for s in pending
                                             if s.yours and s.role != "bridge"), None)  # a pair: said of its node
        time.sleep(0.1)


def start_sim(world: Optional[str] = None, ros_home: Optional[str] = None, blackboard: bool = True,
              modules: Sequence[str] = SIM_MODULES, params: Optional[Dict[str, Sequence[str]]] = None,
              timeout: float = SIM_AT_LEAST, user_modules: Sequence[UserModule] = (), address: str = "",
              port: int = 0) -> RosGraph:
    """Bring the graph up and wait until every module has announced itself.

    Args:
        params: extra command-line arguments per module (ROS ``_param:=value`` private parameters).
        timeout: seconds the user's modules get to announce themselves (``--wait``), counted from their
            start (and never less than the simulated robot's own modules took); the simulated robot's
            own get at least :data:`SIM_AT_LEAST`.
        user_modules: the user's own modules, each run by ``bmtree-module`` as its own node, or an executable's
            as its node (named ``/<module>``) and a ``bmtree-bridge`` (``/<module>_bridge``), which end together
            once the graph is up (:mod:`coordinator.simcpp`).
        address: ROS_IP of the graph (default loopback, see :class:`RosGraph`).
        port: the master's port (0: a free one).

    Raises:
        ModuleStartError: a user's module exited before it announced itself, or did not announce itself
            within ``timeout`` (why, and its log's last lines); at once when it exits.
        GraphError: a process of the simulated robot did.
    """
    graph = SimGraph(ros_home, address=address)
    try:
        graph.start_master(port=port)
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
        taken = {"/blackboard"} | {"/bm_" + m for m in modules} | {"/bm_" + um.definition.name for um in user_modules
                                                                    if um.executable is None}
        pairs = []
        for um in user_modules:
            node = "/bm_" + um.definition.name
            faults = the_world.faults_of(um.definition.name)  # the world's faults of the user's own module
            extra = ["_faults:=%s" % json.dumps(faults)] if faults else []
            if um.executable is not None:  # its bridge takes the faults; bmtree's --wait ends the start-up first
                node, bridge = pair_names(um.definition.name, taken)
                procs = start_pair(graph, um.definition_path, um.executable, node, bridge,
                                   max(timeout, SIM_AT_LEAST) + 30.0, extra)
                starting.extend(_Starting(n, p, um.definition.name, True, role)
                                for n, p, role in zip((node, bridge), procs, ("cpp", "bridge")))
                pairs.append((node, bridge))
                continue
            if um.script is not None:   # the node is bm_<module>, as the simulated robot's
                argv = ["-m", "coordinator.testing.mocknode", um.script, "--modules", um.definition_path, *extra]
            else:
                argv = ["-m", "modules.node", "--definition", um.definition_path, "--class", um.class_spec,
                        "--node-name", node[1:], *extra]
            # a crash in C code (a driver's library) says where in the log (Fatal Python error: …)
            proc = graph.start_node(argv, node, wait=False, env={"PYTHONFAULTHANDLER": "1"})
            starting.append(_Starting(node, proc, um.definition.name, True))
        _wait_up(graph, starting, timeout, started)
        for node, bridge in pairs:
            watch_pair(graph, node, bridge)
    except BaseException:
        graph.close()
        raise
    return graph
