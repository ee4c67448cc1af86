"""Why a process of the simulated robot's graph (``bmtree run --sim``) ended, or has not started:
bmtree started it (:class:`coordinator.graph.RosGraph`), so it knows its exit code or signal, and its
output goes to ``<node>.out`` in the run's ``.sim`` folder, whose last lines say more.

A ``die`` fault (README, "Faults") kills its module's process with SIGKILL, as a crash would, after
the node logged ``the node dies (an injected fault) with N call(s) in flight: REASON``
(``modules.node._die``): read back here, it is said as what it is, an injected fault.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from typing import Any, Callable, List, Optional, Set

__all__ = ["cut", "log_tail", "last_error", "where_stuck", "injected_death", "how_it_ended", "ended_text",
           "process_ends"]

LINE_WIDTH = 200  # characters of a log line quoted in a message
REAP_WAIT = 1.0  # s a process found gone (its port refuses) may take to be reaped by the kernel

#: what ``modules.node._die`` logs before a ``die`` fault kills the node (its wording is read here)
_DIED = re.compile(r"the node dies \(an injected fault\) with \d+ call\(s\) in flight: (.*)$")
_ROSPY = re.compile(r"^\[(DEBUG|INFO|WARN|ERROR|FATAL)\] \[[\d.]+\]: ")  # rospy's (and roscpp's) prefix of a log line
_DUMP = re.compile(r"^(  File |Current thread 0x|Thread 0x|Stack \(most recent|Extension modules: |  <no Python frame>)")
_FRAME = re.compile(r'^  File "(.*)", line (\d+) in (.*)$')
_ERROR = re.compile(r"^(\[(ERROR|FATAL)\] |Fatal Python error: |error: |terminate called |"
                    r"[A-Za-z_][\w.]*(Error|Exception|Exit)(: |$))")
_WHAT = "  what():"  # after a C++ program's "terminate called after throwing …": the exception's text


def cut(text: str, width: int = LINE_WIDTH) -> str:
    text = text.rstrip()
    return text if len(text) <= width else text[:width - 1] + "…"


def cut_middle(text: str, width: int = 2 * LINE_WIDTH) -> str:
    """``text`` cut in the middle: an error's what comes first and its fix last (``… must be the
    definition's (BasicModule(nh, "hand"))``), and both are kept."""
    text = text.rstrip()
    if len(text) <= width:
        return text
    head = width * 2 // 5
    return text[:head] + " … " + text[-(width - head - 3):]


def log_tail(path: str, lines: int = 5, width: int = LINE_WIDTH) -> List[str]:
    """The last ``lines`` non-empty lines of the log at ``path``, each cut to ``width`` characters
    (none when it cannot be read)."""
    try:
        with open(path, "rb") as fh:
            fh.seek(0, 2)
            fh.seek(max(0, fh.tell() - 64 * 1024))  # a module that printed megabytes: its end only
            text = fh.read().decode("utf-8", errors="replace")
    except OSError:
        return []
    found = [line for line in text.splitlines() if line.strip()]
    return [cut(line, width) for line in found[-lines:]] if lines > 0 else []


def last_error(path: str, within: int = 50) -> str:
    """The last error line among the last ``within`` lines of the log at ``path`` (rospy's and roscpp's
    ``[ERROR]`` and ``[FATAL]``, ``error: …``, an exception's last traceback line, ``Fatal Python error: …``,
    a C++ ``terminate called …`` with its ``what()``), without ROS's level and time, cut; "" for none.
    The threads' stacks that follow a ``Fatal Python error`` (``PYTHONFAULTHANDLER``) are not counted, and
    the innermost frame of its thread outside Python's own library is said with it (``… (at
    gripper.py:16 in grasp)``)."""
    lines = log_tail(path, 5000, 10 * LINE_WIDTH)
    counted = 0
    for i in range(len(lines) - 1, -1, -1):
        line = lines[i]
        if _DUMP.match(line):
            continue
        if _ERROR.match(line):
            if line.startswith("terminate called") and i + 1 < len(lines) and lines[i + 1].startswith(_WHAT):
                line += " (what(): %s)" % lines[i + 1][len(_WHAT):].strip()
            return cut_middle(_ROSPY.sub("", line) + (_where(lines[i + 1:]) if line.startswith("Fatal Python") else ""))
        counted += 1
        if counted >= within:
            break
    return ""


def _where(dump: List[str]) -> str:
    """`` (at gripper.py:16 in grasp)``: the innermost frame of a fault's current thread outside Python's own
    library (``/lib/python``), from a faulthandler's dump; "" when there is none."""
    current = False
    for line in dump:
        if line.startswith("Current thread"):
            current = True
        elif current and not line.startswith("  File "):
            return ""
        elif current:
            if _own(line):
                return " (at %s)" % _frame_text(line)
    return ""


def where_stuck(proc: subprocess.Popen, log: str, wait: float = 1.0) -> str:
    """``c11_setupblock.py:9 in setup``: where the main thread of a module node still starting is (the
    innermost frame outside Python's own library), from the stacks the node prints to its log on SIGUSR1
    (:class:`comm.nodelife.StopSignals`, installed before its node registers); "" when none came in
    ``wait`` seconds. Only for a process whose node registered (before, SIGUSR1 would end it)."""
    try:
        start = os.path.getsize(log)
        proc.send_signal(signal.SIGUSR1)
    except OSError:
        return ""
    end = time.monotonic() + wait
    while time.monotonic() < end and proc.poll() is None:
        time.sleep(0.05)
        try:
            with open(log, "rb") as fh:
                fh.seek(start)
                lines = fh.read(256 * 1024).decode("utf-8", errors="replace").splitlines()
        except OSError:
            return ""
        stack: List[str] = []
        for line in lines:  # each thread: its header, then its frames innermost first
            if line.startswith(("Thread 0x", "Current thread 0x")):
                stack = []
            frame = _FRAME.match(line)
            if frame is not None:
                stack.append(line)
                if frame.group(3) == "<module>" and frame.group(1) == "<string>":  # the main thread's outermost
                    return next((_frame_text(f) for f in stack if _own(f)), "")
    return ""


def _own(line: str) -> bool:
    frame = _FRAME.match(line)
    return frame is not None and "/lib/python" not in frame.group(1) and not frame.group(1).startswith("<")


def _frame_text(line: str) -> str:
    frame = _FRAME.match(line)
    return "%s:%s in %s" % (os.path.basename(frame.group(1)), frame.group(2), frame.group(3)) if frame else ""


def injected_death(path: str, within: int = 20) -> str:
    """The reason of the ``die`` fault that killed the node logging to ``path`` ("" if none did)."""
    for line in reversed(log_tail(path, within, 10 * LINE_WIDTH)):
        found = _DIED.search(line)
        if found:
            return found.group(1).strip()
    return ""


def how_it_ended(code: int) -> str:
    """``exited with code 7``, ``was killed by SIGSEGV`` (a negative ``Popen.returncode``)."""
    if code >= 0:
        return "exited with code %d" % code
    try:
        return "was killed by %s" % signal.Signals(-code).name
    except ValueError:
        return "was killed by signal %d" % -code


def ended_text(code: int, log: str) -> str:
    """Why a process that ended with ``code`` (``Popen.returncode``) and logged to ``log`` ended:
    ``its process exited with code 7``, ``its process was killed by SIGSEGV; its log's last error:
    Fatal Python error: Segmentation fault``, ``its process exited: motor driver fault (injected fault)``."""
    from modules.sim.world import INJECTED

    died = injected_death(log) if code == -signal.SIGKILL else ""
    if died:
        return "its process exited: %s%s" % (cut(died), INJECTED)
    error = last_error(log)
    return "its process %s%s" % (how_it_ended(code), "; its log's last error: %s" % error if error else "")


def process_ends(graph: Any, wait: float = REAP_WAIT) -> Callable[[str], str]:
    """For :attr:`coordinator.rosliveness.Whereabouts.ended`: ``node`` -> :func:`ended_text` of its process
    in ``graph`` (a :class:`~coordinator.graph.RosGraph`), once it has ended (waited for up to ``wait``
    seconds, once per process: one whose port refuses may not be reaped yet); "" for a node the graph did
    not start, or whose process still runs. A bridge that bmtree ended because its C++ node ended
    (``graph.ended_with``, :func:`coordinator.simcpp.watch_pair`) is said by that node's end: ``its C++ node
    /gripper stopped: its process was killed by SIGSEGV``."""
    waited: Set[int] = set()  # pids waited for once already: asked again, they are only looked at

    def code_of(node: str) -> Optional[int]:
        proc: Optional[subprocess.Popen] = graph.procs.get(node)
        if proc is None:
            return None
        try:
            return proc.wait(0 if proc.pid in waited else wait)
        except subprocess.TimeoutExpired:
            return None
        finally:
            waited.add(proc.pid)

    def ended(node: str) -> str:
        code = code_of(node)
        if code is None:
            return ""
        what, first = getattr(graph, "ended_with", {}).get(node, ("", ""))
        first_code = code_of(first) if first else None
        if first_code is not None:
            return "%s %s stopped: %s" % (what, first, ended_text(first_code, graph.log_path(first)))
        return ended_text(code, graph.log_path(node))
    return ended
