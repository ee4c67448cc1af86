"""Whether the run a watch shows is still there: its process gone (killed outright: no end record) ends
the view with :func:`gone_record`; its node not answering (a dropped link, a stopped process) is said
while it lasts (:class:`RunLiveness`)."""
from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Dict, Optional, Tuple

from comm.liveness import NodeWatch
from comm.rpc import PidLine
from coordinator.watchstate import WatchState

if TYPE_CHECKING:
    from coordinator.watch import RosWatcher

__all__ = ["RunLiveness", "gone_record", "END_TICKS_GRACE", "ASK_EVERY"]

#: seconds ``watch --plain`` waits after the end for the run's last ticks (queued on another topic)
END_TICKS_GRACE = 1.0


def gone_record(state: WatchState, node: str, reason: str, alive: Optional[float] = None,
                unreached: Optional[float] = None) -> Dict[str, Any]:
    """The watch's own ``end`` of a run whose process is gone before its end (killed outright, crashed):
    status ``UNFINISHED``, ``gone`` true; never on the run stream, which that run can no longer write.
    ``alive``: the run's time when its process was found gone (:meth:`WatchState.now` then), its
    ``duration`` (else the time of its last record); the last tick is the run's last tick record's
    (a snapshot carries it as ``tick_t``), not the time the watch caught up. ``unreached``: the seconds the
    run's node had not answered this watch before it was found gone (a dropped link): the run may have ended
    well meanwhile, its end record lost to this watch, and nothing is claimed of its calls."""
    started = state.tree.get("started")
    wall = ""
    if isinstance(started, (int, float)):
        wall = " (%s)" % time.strftime("%H:%M:%S", time.localtime(started + state.tick_t))
    lived = max(state.t, alive if alive is not None else state.t)
    said = "%s; it did not stop its calls" % reason
    if unreached is not None:
        said = ("this watch could not reach it for %d s before, so the run may have ended meanwhile (well or not): its "
                "end never reached this watch; its result is in its run log, on the machine it ran on (bmtree runs, "
                "bmtree replay there)" % unreached)
    return {"v": 1, "type": "end", "run": state.run, "t": round(lived, 6), "status": "UNFINISHED", "gone": True,
            "reason": "the run (pid %s, node %s) is gone, its last tick (%d) at %.3fs%s, found gone at about %.1fs: "
                      "%s" % (state.tree.get("pid", "?"), node, state.tick, state.tick_t, wall, lived, said),
            "ticks": state.tick, "duration": round(lived, 6), "calls": state.calls_total}


#: seconds between the watch's questions to the run's node (``getPid``), and how long each waits for its answer
ASK_EVERY = 1.0


class RunLiveness:
    """Watches the run's node (the publisher of its tree record) in two ways.

    Its process gone: a run killed outright (``kill -9``) never publishes its end. The node is watched
    as the run watches modules (:class:`comm.liveness.NodeWatch`: its ``getPid`` over one kept
    connection, waited on, never polled); when it is gone and no end came within
    :data:`END_TICKS_GRACE`, the view gets :func:`gone_record`.

    Its answers: a dropped link or a stopped process sends no records, and neither does a run waiting
    on a long call; only a question tells them apart. A thread of its own asks the node about once a
    second (``getPid``, :class:`comm.rpc.PidLine`, :data:`ASK_EVERY` s to answer) and tells the state
    (:meth:`WatchState.heard`), so that every view says when it has not answered for
    :data:`coordinator.watchstate.SILENT_AFTER` s and when it answers again (``on_change``, with the
    state's lock held: ``--plain`` prints it)."""

    def __init__(self, watcher: RosWatcher, on_change: Optional[Callable[[], None]] = None):
        self.watcher = watcher
        self.state = watcher.state
        self.on_change = on_change
        self.node_watch = NodeWatch(self._node, self._uri_of, self._gone, period=0.5, dead_is_gone=True,
                                    caller="/bmtree_watch_liveness")
        self._asked: Tuple[str, Optional[PidLine]] = ("", None)  # the node asked, the connection to it
        self._stop = threading.Event()

    def start(self) -> RunLiveness:
        self.node_watch.start()
        threading.Thread(target=self._ask_loop, name="bmtree-watch-answers", daemon=True).start()
        return self

    def stop(self) -> None:
        self.node_watch.stop()
        self._stop.set()

    def _node(self) -> Optional[str]:
        """The node of the run shown, while it has not ended."""
        with self.state.lock:
            if not self.state.nodes or self.state.end is not None:
                return None
            return self.watcher.nodes.get(self.state.run)

    @staticmethod
    def _uri_of(node: str) -> Optional[str]:
        """The run node's URI; a master that does not answer raises OSError after a bounded wait (the
        watch tries again later) rather than holding the liveness thread, and the watch's exit, for ever."""
        import rosgraph

        from comm.rpc import master_api
        from coordinator.rosliveness import LIVENESS_QUESTION

        try:
            return master_api("/bmtree_watch_liveness", LIVENESS_QUESTION).lookupNode(node)
        except rosgraph.masterapi.MasterError:
            return None

    def _gone(self, node: str, reason: str) -> None:
        with self.state.lock:
            run = self.state.run
            if self.watcher.nodes.get(run) != node:
                return
            alive = self.state.now()  # its process is found gone now, not at its last record
            asked = self.state.asked
            # it had not answered this watch before (a dropped link): it may well have ended meanwhile
            unreached = time.monotonic() - asked[1] if self.state.silent and asked is not None else None
        # an ending run leaves right after its (latched) end: give it the time to arrive
        if self.state.wait(lambda s: s.end is not None or s.run != run, END_TICKS_GRACE):
            return
        with self.state.lock:
            if self.state.end is None and self.state.run == run:
                self.watcher.apply(gone_record(self.state, node, reason, alive, unreached))

    def _ask_loop(self) -> None:
        try:
            while not self._stop.is_set():
                began = time.monotonic()
                try:
                    self.ask()
                except Exception:  # the master away (the lookup), a node that answers oddly: ask again later
                    pass
                self._stop.wait(max(0.0, began + ASK_EVERY - time.monotonic()))
        finally:
            if self._asked[1] is not None:
                self._asked[1].close()

    def ask(self) -> None:
        """One question to the run's node, while its run has not ended (the asking thread's; callable in tests)."""
        node = self._node()
        if node is None:
            return
        line = self._asked[1]
        if self._asked[0] != node or line is None:
            uri = self._uri_of(node)  # once per node (OSError: the master does not answer; again next time)
            if not uri:
                return
            if line is not None:
                line.close()
            line = PidLine(uri, ASK_EVERY, "/bmtree_watch_answers")
            self._asked = (node, line)
        try:
            answered = line.ask() is not None
        except OSError:  # refused: its process is gone (NodeWatch ends the view)
            answered = False
        with self.state.lock:
            if self.state.heard(node, answered) and self.on_change is not None:
                self.on_change()
