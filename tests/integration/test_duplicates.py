"""Duplicate node names and two nodes for one module are reported, never silent."""
from __future__ import annotations

import os

from modules.discovery import live_modules
from tests.conftest import until
from tests.integration.faultkit import PROBE_CLASS, PROBE_JSON, start_probe


def _log(ros_graph, name):
    with open(os.path.join(ros_graph.ros_home, "%s.out" % name), errors="replace") as fh:
        return fh.read()


def test_a_node_kicked_out_by_its_name_says_so_and_keeps_the_new_announcement(ros_graph):
    first = start_probe(ros_graph, "bm_dup")
    before = live_modules()["probe"]
    # a second process under the same node name: the master stops the first
    start_probe(ros_graph, "bm_dup", wait=False)
    assert first.wait(30) == 3
    assert "another node registered with this node's name /bm_dup" in _log(ros_graph, "bm_dup")
    ros_graph.wait_node("/bm_dup")

    def announced() -> bool:   # (the new node registers, then announces: a moment apart under load)
        live = live_modules()
        return "probe" in live and live["probe"].node == "/bm_dup" and live["probe"].uri != before.uri

    until(announced, 20, lambda: _log(ros_graph, "bm_dup"))


def test_a_second_node_for_a_running_module_refuses_to_start(ros_graph):
    start_probe(ros_graph, "bm_one")
    second = ros_graph.start_node(["-m", "modules.node", "--definition", PROBE_JSON, "--class", PROBE_CLASS,
                                   "__name:=bm_two"], "/bm_two", wait=False)
    assert second.wait(30) == 3
    assert live_modules()["probe"].node == "/bm_one"
    text = _log(ros_graph, "bm_two")
    assert "module 'probe' is already served by the running node /bm_one" in text
    assert "Traceback" not in text
