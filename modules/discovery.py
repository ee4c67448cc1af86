"""Which modules run now: each module node announces itself on the parameter server.

A module writes ``/bmtree/modules/<name>`` = ``{"node": ..., "definition": <JSON>}``
when it starts and removes it when it stops cleanly. A module killed hard leaves
its parameter behind, so a listing also pings the node's XML-RPC API: a module
whose node does not answer is not listed.
"""
from __future__ import annotations

import json
import socket
import xmlrpc.client
from dataclasses import dataclass
from typing import Dict, Optional

import rosgraph

from modules.definition import DefinitionError, ModuleDefinition, parse_definition

__all__ = ["PARAM_ROOT", "LiveModule", "live_modules", "announcement", "node_alive"]

PARAM_ROOT = "/bmtree/modules"


@dataclass
class LiveModule:
    name: str
    node: str
    uri: str
    definition: ModuleDefinition


def announcement(node: str, definition: ModuleDefinition) -> Dict[str, str]:
    return {"node": node, "definition": json.dumps(definition.to_dict())}


class _TimeoutTransport(xmlrpc.client.Transport):
    def __init__(self, timeout: float):
        super().__init__()
        self._timeout = timeout

    def make_connection(self, host):  # type: ignore[no-untyped-def]
        conn = super().make_connection(host)
        conn.timeout = self._timeout
        return conn


def node_alive(uri: str, timeout: float = 1.0) -> bool:
    """True if the node at ``uri`` answers ``getPid``."""
    try:
        code, _, _ = xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(timeout)).getPid("/bmtree")
        return code == 1
    except (OSError, socket.timeout, xmlrpc.client.Error):
        return False


def live_modules(master_uri: Optional[str] = None, timeout: float = 1.0) -> Dict[str, LiveModule]:
    """Modules running now on the master (raises OSError-like errors if there is no master)."""
    master = rosgraph.Master("/bmtree_discovery", master_uri=master_uri)
    try:
        params = master.getParam(PARAM_ROOT)
    except rosgraph.masterapi.MasterError:
        return {}
    found: Dict[str, LiveModule] = {}
    if not isinstance(params, dict):
        return found
    for name, entry in sorted(params.items()):
        if not isinstance(entry, dict) or not isinstance(entry.get("node"), str):
            continue
        try:
            uri = master.lookupNode(entry["node"])
        except rosgraph.masterapi.MasterError:
            continue
        if not node_alive(uri, timeout):
            continue
        try:
            definition = parse_definition(json.loads(entry.get("definition", "")), "live:%s" % entry["node"])
        except (ValueError, DefinitionError):
            continue
        found[name] = LiveModule(name=name, node=entry["node"], uri=uri, definition=definition)
    return found
