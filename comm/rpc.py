"""XML-RPC to ROS nodes and the master with a timeout: a hung peer must not hang the caller."""
from __future__ import annotations

import xmlrpc.client
from typing import Any

__all__ = ["proxy"]


class _TimeoutTransport(xmlrpc.client.Transport):
    def __init__(self, timeout: float):
        super().__init__()
        self._timeout = timeout

    def make_connection(self, host):  # type: ignore[no-untyped-def]
        conn = super().make_connection(host)
        conn.timeout = self._timeout
        return conn


def proxy(uri: str, timeout: float) -> Any:
    """An ``xmlrpc.client.ServerProxy`` whose every request gives up after ``timeout`` seconds."""
    return xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(timeout))
