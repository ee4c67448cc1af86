"""The bridge's C++ node on the ROS graph: found through the master, connections checked, death noticed.

The C++ node's name is not fixed: it is whoever subscribes ``/<BM>/BM_input``. These are the
bridge's questions to the master and to the node's XML-RPC port (each bounded: a master that does
not answer must not hold a call), kept apart from the C++ protocol itself (:mod:`modules.bridge`).
"""
from __future__ import annotations

import logging
import socket
import time
from typing import Any, Callable, List, Optional, Tuple
from urllib.parse import urlsplit

from comm.masterwatch import watch_master
from comm.nodelife import stop_requested
from comm.rpc import MASTER_TIMEOUT, master_api
from modules.basicmodule import BindingError
from modules.discovery import PARAM_ROOT

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


def _clock(at: float) -> str:
    """A moment of this day, as the bridge's reader compares it with the logs (local time)."""
    return time.strftime("%H:%M:%S", time.localtime(at))


class CppNodeGraph:
    """The graph side of :class:`modules.bridge.CppBridge` (a base class of it, on its state): which
    node is the C++ node (``cpp_node``, ``cpp_uri``, ``library``, ``cancellable``, ``emits``), what is
    not connected yet, and whether its process is gone.

    A C++ node that this bridge served and whose process is gone is *down* (``_deaths``: when and
    how, by URI): a call is refused at once, saying so, until a node subscribes ``BM_input`` again;
    only a live node whose connections are still being made is waited for."""

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
        live = [n for n in uris if not _refuses(uris[n])]
        served = [n for n in uris if uris[n] == self._served and n not in live]
        if not any(n in talkers for n in live) and (served or self._served in self._deaths):
            # the node this bridge served is gone and none took its place (a tool may listen), unless it is
            # being started again under its name (subscribed already, BM_output not yet advertised)
            nodes = [n for n in live if n == self.cpp_node] or served
        else:
            nodes = live or list(uris)
            nodes = [n for n in nodes if n in talkers] or nodes  # a tool may listen to BM_input too
        self._misnamed = "" if nodes else self._serves_another(master, pubs, subs)
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

    def _serves_another(self, master: Any, pubs: List[Any], subs: List[Any]) -> str:
        """Nobody subscribes ``/<BM>/BM_input``, but a live node named as the module (the C++ node's
        name, ``bmtree::run``'s) serves another module: the module name in its code is not the
        definition's. What is there, in words ("" if no such node)."""
        import rosgraph

        name = self.definition.name
        for topic, nodes in subs:
            if not topic.endswith("/BM_input") or topic == "/%s/BM_input" % name:
                continue
            for n in nodes:
                if n == self._self_name or n.rsplit("/", 1)[-1] != name:
                    continue
                try:
                    if _refuses(master.lookupNode(n)):
                        continue
                except rosgraph.masterapi.Error:
                    continue
                other = topic[:-len("/BM_input")]
                if n in next((x for t, x in pubs if t == other + "/BM_info"), []):  # built with bmtree's library
                    what, fix = "publishes %s/BM_info and subscribes %s" % (other, topic), \
                        "the name given to BasicModule in the C++ code must be the definition's (BasicModule(nh, " \
                        "\"%s\"))" % name
                else:
                    what, fix = "subscribes %s" % topic, "the module name in the C++ code must be the definition's"
                # the advice before the details (a path can be long): whoever quotes the line cut short (bmtree
                # run --sim quotes 200 characters of a bridge's last error) still gives the fix
                return "node %s serves module %r, but the definition is module %r: %s (node %s %s; the definition " \
                       "is %s)" % (n, other.lstrip("/"), name, fix, n, what, self.definition.source or name)
        return ""

    def _down(self) -> str:
        """Why calls are refused at once: the C++ node this bridge served is gone and no other has
        taken its place ("" if not known to be so)."""
        death = self._deaths.get(self.cpp_uri)
        if death is None:
            return ""
        return "the C++ node %s of module %r is not running: %s; start it again" % (
            self.cpp_node, self.definition.name, self._death_note(death))

    @staticmethod
    def _death_note(death: Tuple[float, str]) -> str:
        at, how = death
        verb, _, why = how.partition(" ")
        return "it %s at %s %s" % (verb, _clock(at), why)

    def _missing(self) -> List[str]:
        """What is not connected yet between this bridge and the C++ node, in words."""
        name = self.definition.name
        served = self._served
        self._live = False
        node = self._find_node()
        if node is None:
            if served and served == self.cpp_uri:  # the node served stopped and unregistered (Ctrl-C, rosnode kill)
                self._say_gone()
            return [self._misnamed or self._down() or "no node subscribes /%s/BM_input (is the C++ node running?)"
                    % name]
        if self._gone():  # killed outright: the master still lists it, but nothing listens at its port
            if served and served == self.cpp_uri:
                self._say_gone()
            return [self._down() or "the C++ node %s is registered with the master but not running (its process is "
                    "gone: start it again)" % node]
        self._live = True  # its connections may still be on their way: worth a wait
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

    def _not_ready(self, look: bool = True) -> str:
        """Why the module cannot take a call now, in words ("" when it can, as far as is known): its C++ node
        is not running (it died or exited and no node took its place), or is not connected to this bridge
        yet (one started again), or the bridge is still starting. Cheap: what the watch found, and one look
        at the node's XML-RPC port (a node killed less than a second ago, before the watch noticed), unless
        not to ``look``."""
        if self._watcher is None:
            return "its bridge %s is still waiting for the C++ node" % (self._self_name or "")
        down = self._down()
        if not down and self._absent:
            return "the C++ node of module %r is not connected: %s" % (self.definition.name, self._absent)
        if look and not down and self.cpp_uri and self.cpp_uri != self._gone_said and self._gone():
            self._say_gone()
            down = self._down()
        return down

    def _look_again(self) -> None:
        """The watch's thread, while the C++ node is down or not connected: one look for a node serving
        the module (started again, under its name or another), unless a call is looking for it now."""
        if not self._finding.acquire(blocking=False):
            return
        try:
            self._wait_connected(0)
        finally:
            self._finding.release()

    def _announce_readiness(self) -> None:
        """Keep the key ``not_ready`` of the module's announcement the reason of :meth:`_not_ready` (no key
        while it can take calls), so that a coordinator or ``bmtree modules --live`` can say why without
        calling it. The master is asked only when the reason changes (and again until it is set)."""
        node = self._module_node
        reason = self._not_ready(look=False)  # (the watch has just looked)
        if node is None or reason == self._announced_not_ready or getattr(node, "kicked_out", ""):
            return
        key = getattr(node, "_param", "") or "%s/%s" % (PARAM_ROOT, self.definition.name)
        try:
            master = master_api(self._self_name or "/bmtree_bridge", MASTER_TIMEOUT)
            entry = master.getParam(key)
            if not isinstance(entry, dict) or entry.get("instance") != getattr(node, "instance", None):
                return  # not announced yet (start-up), or not this process's announcement: try again later
            entry = dict(entry)
            if reason:
                entry["not_ready"] = reason
            else:
                entry.pop("not_ready", None)
            if self._watch_stop.is_set() or stop_requested():  # the node is leaving: its announcement goes
                return
            master.setParam(key, entry)
        except Exception as exc:  # the master does not answer, or the key is gone: next time
            log.debug("could not set the announcement's not_ready: %s", exc)
            return
        self._announced_not_ready = reason
        watch_master().keep_param(key, lambda: None if getattr(node, "kicked_out", "") else entry)

    def _wait_connected(self, timeout: float, check: bool = False,
                        cancelled: Optional[Callable[[], bool]] = None) -> List[str]:
        """What is still missing after ``timeout`` ([] once connected). With ``check`` (at start),
        a library node's BM_info is compared with the definition as soon as it arrives: a
        definition that does not match it (an output of another type: a data topic the node never
        publishes), or a node named as the module that serves another, stops the bridge at once,
        every difference named, instead of after the wait. For a call (``cancelled`` given: True
        once the call is cancelled) only a live C++ node whose connections are being made is
        waited for: none running, a dead one or a master that does not answer is said at once."""
        end = time.monotonic() + timeout
        while True:
            try:
                missing = self._missing()  # sets _live
            except OSError as exc:
                missing = ["the ROS master does not answer: %s" % exc]
            if check and self._misnamed:
                raise BindingError(self._misnamed)  # exit 2: the C++ code and the definition disagree
            if check and self.library and self.cpp_node and self.cpp_node != self._checked:
                with self._cond:
                    informed = self.cpp_node in self._infos
                if informed:
                    self._check_signatures(wait=0)  # BindingError (exit 2) on a difference
            if not missing:
                self._ready = True
                self._served = self.cpp_uri
                self._absent = ""
                return []
            if time.monotonic() >= end or stop_requested() or (
                    cancelled is not None and (not self._live or cancelled())):
                self._absent = "; ".join(missing)
                return missing
            time.sleep(0.05)

    def _gone(self) -> bool:
        """True if the C++ node's process is gone: its XML-RPC port refuses connections.

        A node that is merely slow is not gone: only the call's deadline ends its call.
        """
        return _refuses(self.cpp_uri)

    def _said_gone(self) -> bool:
        """True once the log said that the C++ node's process is gone (the watch noticed it between calls)."""
        return bool(self._gone_said) and self._gone_said == self.cpp_uri

    def _say_gone(self) -> None:
        """One line in the bridge's log when its C++ node's process is gone (once per node): an error
        if it died (killed, crashed: it is still registered), a warning if it exited (Ctrl-C, rosnode
        kill: roscpp unregistered it)."""
        with self._say_lock:  # a call's thread, the watch's and a ping's may find it at once: said once
            self._say_gone_once()

    def _say_gone_once(self) -> None:
        import rosgraph

        uri, node = self.cpp_uri, self.cpp_node
        if not uri or uri == self._gone_said:
            return
        self._gone_said = uri
        at = time.time()
        now: Optional[str] = ""  # the node's URI on the master now ("": not known, None: unregistered)
        try:  # bounded: asked from a call's thread, whose answer a master that does not answer must not hold
            now = master_api(self._self_name or "/bmtree_bridge", MASTER_TIMEOUT).lookupNode(node)
        except rosgraph.masterapi.MasterError:  # "unknown node"
            now = None
        except (rosgraph.masterapi.MasterException, OSError):
            pass
        if now is None:
            self._deaths[uri] = (at, "exited (it unregistered from the master: Ctrl-C or rosnode kill)")
            log.warning("the C++ node %s of module %r has exited (it unregistered from the master); calls are "
                        "refused until it is started again", node, self.definition.name)
        elif now and now != uri:
            log.warning("the C++ node %s of module %r at %s is gone; a new node of that name runs at %s (the next "
                        "call is sent to it)", node, self.definition.name, uri, now)
        else:
            self._deaths[uri] = (at, "died (killed or crashed: nothing listens at %s)" % uri)
            log.error("the C++ node %s of module %r died (killed or crashed: nothing listens at %s%s); calls are "
                      "refused until it is started again", node, self.definition.name, uri,
                      ", and it is still registered with the master" if now else "")

    def _watch(self) -> None:
        """A thread: notices, between calls too, that the C++ node's process is gone (kill -9, a crash);
        while it is, looks every second for one started again; and keeps the announcement's
        ``not_ready`` up to date (:meth:`_announce_readiness`)."""
        while not self._watch_stop.wait(_WATCH):
            if stop_requested():
                continue
            try:
                uri = self.cpp_uri
                if uri and uri != self._gone_said and _refuses(uri):
                    self._say_gone()
                if (self._down() or self._absent) and self._call is None:  # (a call notices a death itself)
                    self._look_again()
                self._announce_readiness()
            except Exception:  # a bug here must not end the watch: the next second tries again
                log.exception("the bridge's watch of its C++ node failed")
