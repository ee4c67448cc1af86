"""The bridge's C++ node on the ROS graph: found through the master, connections checked, death noticed.

The C++ node's name is not fixed: it is whoever subscribes ``/<BM>/BM_input``. These are the
bridge's questions to the master and to the node's XML-RPC port (each bounded: a master that does
not answer must not hold a call), kept apart from the C++ protocol itself (:mod:`modules.bridge`).
"""
from __future__ import annotations

import logging
import socket
import time
from typing import List, Optional
from urllib.parse import urlsplit

from comm.nodelife import stop_requested
from comm.rpc import MASTER_TIMEOUT, master_api

__all__ = ["CppNodeGraph"]

log = logging.getLogger("bmtree.bridge")

_WATCH = 1.0  # how often the bridge checks, between calls, that the C++ node is still there (s)


def _refuses(uri: str) -> bool:
    """True if nothing listens at a node's XML-RPC port any more: its process is gone."""
    try:
        host, port = urlsplit(uri).hostname, urlsplit(uri).port
        with socket.create_connection((host, port), timeout=1.0):
            return False
    except ConnectionRefusedError:
        return True
    except (OSError, ValueError):
        return False


def _some(names: List[str], shown: int = 3) -> str:
    """A few names and how many more: a node connected to nothing is said in one line, not one per topic."""
    if len(names) <= shown + 1:
        return ", ".join(names)
    return "%s and %d more" % (", ".join(names[:shown]), len(names) - shown)


class CppNodeGraph:
    """The graph side of :class:`modules.bridge.CppBridge` (a base class of it, on its state): which
    node is the C++ node (``cpp_node``, ``cpp_uri``, ``library``, ``cancellable``, ``emits``), what is
    not connected yet, and whether its process is gone."""

    def _find_node(self) -> Optional[str]:
        """The C++ node: whoever subscribes ``/<BM>/BM_input`` (its name is not fixed)."""
        import rosgraph

        master = master_api(self._self_name or "/bmtree_bridge", MASTER_TIMEOUT)  # OSError: no answer in time
        name = self.definition.name
        pubs, subs, _ = master.getSystemState()
        listeners = next((n for t, n in subs if t == "/%s/BM_input" % name), [])
        talkers = next((n for t, n in pubs if t == "/%s/BM_output" % name), [])
        uris = {}
        for n in listeners:
            if n != self._self_name:
                try:
                    uris[n] = master.lookupNode(n)
                except rosgraph.masterapi.Error:
                    continue
        # one killed outright stays registered: live ones first (its restart under another name)
        nodes = [n for n in uris if not _refuses(uris[n])] or list(uris)
        nodes = [n for n in nodes if n in talkers] or nodes  # a tool may listen to BM_input too
        if not nodes:
            return None
        if len(nodes) > 1:
            log.warning("several nodes subscribe /%s/BM_input (%s); using %s", name, ", ".join(nodes), nodes[0])
        node = nodes[0]
        self.cpp_uri = uris[node]
        self.cpp_node = node
        self.library = node in next((n for t, n in pubs if t == "/%s/BM_info" % name), [])
        self.cancellable = node in next((n for t, n in subs if t == "/%s/BM_cancel" % name), [])
        self.emits = node in next((n for t, n in pubs if t == "/%s/BM_event" % name), [])
        return node

    def _missing(self) -> List[str]:
        """What is not connected yet between this bridge and the C++ node, in words."""
        name = self.definition.name
        node = self._find_node()
        if node is None:
            return ["no node subscribes /%s/BM_input (is the C++ node running?)" % name]
        if self._gone():  # killed outright: the master still lists it, but nothing listens at its port
            return ["the C++ node %s is registered with the master but not running (its process is gone: start it "
                    "again)" % node]
        sync = [("/%s/BM_input" % name, self._in_pub)]
        if self.cancellable:
            sync.append(("/%s/BM_cancel" % name, self._cancel_pub))
        deaf = [topic for topic, pub in sync + sorted(self._pubs.items()) if not pub.impl.has_connection(node)]
        subs = [self._out_sub] + self._subs
        if self.emits and self.definition.events and self._event_sub is not None:
            subs.append(self._event_sub)  # an event sent before would be lost
        mute = [sub.resolved_name for sub in subs if not sub.impl.has_connection(self.cpp_uri)]
        out = []
        if deaf:
            out.append("%s does not receive %s" % (node, _some(deaf)))
        if mute:
            out.append("%s does not publish %s to the bridge" % (node, _some(mute)))
        return out

    def _wait_connected(self, timeout: float, check: bool = False) -> List[str]:
        """What is still missing after ``timeout`` ([] once connected). With ``check`` (at start),
        a library node's BM_info is compared with the definition as soon as it arrives: a
        definition that does not match it (an output of another type: a data topic the node never
        publishes) stops the bridge at once, every difference named, instead of after the wait."""
        end = time.monotonic() + timeout
        while True:
            try:
                missing = self._missing()
            except OSError as exc:
                missing = ["the ROS master does not answer: %s" % exc]
            if check and self.library and self.cpp_node and self.cpp_node != self._checked:
                with self._cond:
                    informed = self.cpp_node in self._infos
                if informed:
                    self._check_signatures(wait=0)  # BindingError (exit 2) on a difference
            if not missing:
                self._ready = True
                return []
            if time.monotonic() >= end or stop_requested():
                return missing
            time.sleep(0.05)

    def _gone(self) -> bool:
        """True if the C++ node's process is gone: its XML-RPC port refuses connections.

        A node that is merely slow is not gone: only the call's deadline ends its call.
        """
        return _refuses(self.cpp_uri)

    def _say_gone(self) -> None:
        """One line in the bridge's log when its C++ node's process is gone (once per node): an error
        if it died (killed, crashed: it is still registered), a warning if it exited (Ctrl-C, rosnode
        kill: roscpp unregistered it)."""
        import rosgraph

        uri, node = self.cpp_uri, self.cpp_node
        if not uri or uri == self._gone_said:
            return
        self._gone_said = uri
        now: Optional[str] = ""  # the node's URI on the master now ("": not known, None: unregistered)
        try:  # bounded: asked from a call's thread, whose answer a master that does not answer must not hold
            now = master_api(self._self_name or "/bmtree_bridge", MASTER_TIMEOUT).lookupNode(node)
        except rosgraph.masterapi.MasterError:  # "unknown node"
            now = None
        except (rosgraph.masterapi.MasterException, OSError):
            pass
        if now is None:
            log.warning("the C++ node %s of module %r has exited (it unregistered from the master); calls are "
                        "refused until it is started again", node, self.definition.name)
        elif now and now != uri:
            log.warning("the C++ node %s of module %r at %s is gone; a new node of that name runs at %s (the next "
                        "call is sent to it)", node, self.definition.name, uri, now)
        else:
            log.error("the C++ node %s of module %r died (killed or crashed: nothing listens at %s%s); calls are "
                      "refused until it is started again", node, self.definition.name, uri,
                      ", and it is still registered with the master" if now else "")

    def _watch(self) -> None:
        """A thread: notices, between calls too, that the C++ node's process is gone (kill -9, a crash)."""
        while not self._watch_stop.wait(_WATCH):
            uri = self.cpp_uri
            if uri and uri != self._gone_said and not stop_requested() and _refuses(uri):
                self._say_gone()
