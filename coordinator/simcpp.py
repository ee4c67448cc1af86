"""A C++ (or any compiled) module under ``bmtree run --sim --module DEF.json=EXECUTABLE``.

The right-hand side of ``--module`` names a Python class when it holds a ``:`` (``FILE.py:CLASS``,
``package.module:CLASS``) and an executable otherwise (``./build/gripper_node``; a bare name is looked up
on ``PATH``, as a shell does). The executable is started as the module's node, named by bmtree
(``__name:=``, ``/<module>`` as ``bmtree::run`` names it, so that the bridge can tell a node that serves
another module), with a ``bmtree-bridge`` for it (``/<module>_bridge``, which gets the world's faults):
the two are one module of the run. Once the run is up, the end of either process ends the other at once
(SIGKILL: as a crash, so the run finds the module gone and says why, :func:`watch_pair`).

``coordinator.runcmd`` reads ``--module`` and checks the executable here (:func:`check_executable`) before
anything starts.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import threading
from typing import Any, Dict, List, Sequence, Set, Tuple

from coordinator.errors import UsageError
from modules.definition import ModuleDefinition

__all__ = ["CPP_ENV", "check_executable", "pair_names", "start_pair", "watch_pair"]

#: the C++ node's environment beside the graph's: its log without colour codes, each line as written
CPP_ENV = {"NO_COLOR": "1", "ROSCONSOLE_STDOUT_LINE_BUFFERED": "1"}
_SOURCES = (".cpp", ".cc", ".cxx", ".c", ".h", ".hpp", ".hh")


def check_executable(path: str, definition: ModuleDefinition) -> str:
    """The absolute path of the executable ``path`` of ``definition``'s module, before anything starts.

    Raises:
        UsageError: no such file (or none of that name on PATH), a folder, a source file, a Python file
            given without its class, a file that is not executable, or a definition the C++ protocol cannot
            serve (a Concurrent function).
        DefinitionError: two types of the module would share a data topic of the C++ protocol.
    """
    shown = "--module %s=%s" % (definition.source or definition.name, path)
    if path.endswith(".py"):
        raise UsageError("%s: a Python file: name its class (%s=%s:CLASS); an executable, given without "
                         ":CLASS, runs as a C++ module's node" % (shown, definition.source or definition.name, path))
    if path.endswith(_SOURCES):
        raise UsageError("%s: a source file: build it and give the executable (README, C++ modules)" % shown)
    if os.sep not in path:  # as a shell: a bare name is a command on PATH
        found = shutil.which(path)
        if found is None:
            here = "; for the one in this folder write ./%s" % path if os.path.isfile(path) else ""
            raise UsageError("%s: no executable %s on PATH%s" % (shown, path, here))
        path = found
    full = os.path.abspath(os.path.expanduser(path))
    if not os.path.exists(full):
        words = " (bmtree starts it with no arguments but __name:=; for more, give a script that runs it with " \
                "them)" if len(path.split()) > 1 else ""
        raise UsageError("%s: no such file%s" % (shown, words))
    if os.path.isdir(full):
        raise UsageError("%s: a folder, not an executable" % shown)
    if not os.access(full, os.X_OK):
        raise UsageError("%s: not executable (chmod +x it, or give FILE.py:CLASS for a Python module)" % shown)
    from modules.basicmodule import BindingError
    from modules.bridge import make_bridge

    try:  # the bridge's own checks of the definition (shared data topics, Concurrent functions)
        make_bridge(definition)
    except BindingError as exc:
        raise UsageError("%s: %s" % (shown, exc))
    return full


def pair_names(module: str, taken: Set[str]) -> Tuple[str, str]:
    """The C++ node's and its bridge's names: ``/<module>`` (``bmtree::run``'s, which the bridge needs to
    tell a node that serves another module) and ``/<module>_bridge``, unless the graph has one already
    (a module named ``blackboard``): then ``_cpp`` is added. Both are added to ``taken``."""
    node = "/" + module
    while node in taken or node + "_bridge" in taken:
        node += "_cpp"
    taken.update((node, node + "_bridge"))
    return node, node + "_bridge"


def start_pair(graph: Any, definition_path: str, executable: str, node: str, bridge: str, bridge_wait: float,
               extra: Sequence[str] = ()) -> List[subprocess.Popen]:
    """Start the C++ node ``node`` and its bridge ``bridge`` on ``graph`` (a
    :class:`~coordinator.graph.RosGraph`: its environment, its logs ``<node>.out``); ``bridge_wait``: the
    bridge's ``--wait`` for the node's connections (bmtree's own ``--wait`` ends the start-up first);
    ``extra``: the bridge's ``_param:=`` arguments (the world's faults)."""
    cpp = graph.start_node([executable, "__name:=" + node.lstrip("/")], node, wait=False, env=CPP_ENV)
    proxy = graph.start_node(["-m", "modules.bridge", "--definition", definition_path, "--node-name",
                              bridge.lstrip("/"), "--wait", "%g" % bridge_wait, *extra], bridge, wait=False)
    return [cpp, proxy]


def watch_pair(graph: Any, node: str, bridge: str) -> None:
    """From now on, when the C++ node ``node`` or its bridge ``bridge`` ends, end the other at once with
    SIGKILL, and note in ``graph.ended_with`` why (:func:`coordinator.simprocess.process_ends` says it): a
    bridge without its node would refuse the calls instead of the module being found gone, and a node
    without its bridge would run on. Nothing is done once ``graph.closing`` is set (the run's end).

    Each process is waited for with ``waitid(WNOWAIT)`` in a thread of its own: told at once of its end,
    which it leaves to be reaped by its ``Popen``."""
    lock = threading.Lock()
    done: List[str] = []
    labels: Dict[str, str] = {node: "its C++ node", bridge: "its bridge"}

    def watch(me: str, other: str) -> None:
        proc = graph.procs.get(me)
        if proc is None:
            return
        try:
            os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOWAIT)
        except ChildProcessError:  # reaped already: it ended
            pass
        except OSError:
            return
        with lock:
            if done or graph.closing.is_set():
                return
            done.append(me)
            graph.ended_with[other] = (labels[me], me)
            partner = graph.procs.get(other)
            if partner is not None:
                try:
                    partner.kill()  # by its pid, unless its Popen reaped it already
                except OSError:
                    pass

    for me, other in ((node, bridge), (bridge, node)):
        threading.Thread(target=watch, args=(me, other), name="bmtree-pair-%s" % me, daemon=True).start()
