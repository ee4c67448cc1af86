"""bmtree run's warning of a Blackboard node registered but not answering from here: one whose process is
gone stores nothing; one that cannot be reached from this machine (its ROS_IP) may well store the results,
since it connects to the modules itself (a several-machines audit found every result stored after a
warning that said none would be). No ROS: the node lookup is stood in for."""
from __future__ import annotations

import blackboard.client as client
from comm.address import REFUSED
from coordinator import runcmd


def _warned(monkeypatch, capsys, silent):
    monkeypatch.setattr(client, "blackboard_nodes", lambda *a, **k: ([], silent))
    monkeypatch.setattr(client, "silent_blackboards", lambda s, master_uri=None: "the Blackboard node /blackboard …")
    runcmd._warn_without_blackboard()
    return capsys.readouterr().err


def test_a_blackboard_whose_process_is_gone_stores_nothing(monkeypatch, capsys):
    said = _warned(monkeypatch, capsys, {"/blackboard": ("http://127.0.0.1:9/", REFUSED)})
    assert said.strip().endswith(": the results of this run's calls are not stored"), said


def test_a_blackboard_out_of_reach_here_may_still_store(monkeypatch, capsys):
    said = _warned(monkeypatch, capsys, {"/blackboard": ("http://192.0.2.1:40000/", "timed out")})
    assert "it may still store the results of this run's calls (it connects to the modules itself), but a recall " \
           "could not get its answers here" in said and "are not stored" not in said, said
