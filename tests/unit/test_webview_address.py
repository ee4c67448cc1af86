"""The page's address as printed: loopback by default; with --bind 0.0.0.0 also the one other machines use."""
from __future__ import annotations

import urllib.request

from coordinator.webview import WebServer


def test_a_loopback_page_names_only_its_loopback_address():
    server = WebServer(None, "127.0.0.1", 0)
    try:
        assert server.url.startswith("http://127.0.0.1:") and server.remote_url == ""
        assert server.where() == server.url
    finally:
        server.close()


def test_a_page_on_every_address_names_the_one_other_machines_use(monkeypatch):
    monkeypatch.setenv("ROS_IP", "127.0.0.2")  # the machine's address for ROS: reachable by the others
    server = WebServer(None, "0.0.0.0", 0)
    try:
        port = server.url.rsplit(":", 1)[1].strip("/")
        assert server.url == "http://127.0.0.1:%s/" % port
        assert server.remote_url == "http://127.0.0.2:%s/" % port
        assert server.where() == "%s (from other machines: %s)" % (server.url, server.remote_url)
        with urllib.request.urlopen(server.remote_url, timeout=10) as page:  # it does listen there
            assert page.status == 200
    finally:
        server.close()


def test_without_ros_ip_the_host_name_is_given(monkeypatch):
    monkeypatch.delenv("ROS_IP", raising=False)
    monkeypatch.setenv("ROS_HOSTNAME", "robot.local")
    server = WebServer(None, "0.0.0.0", 0)
    try:
        assert server.remote_url.startswith("http://robot.local:")
    finally:
        server.close()
