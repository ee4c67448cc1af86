"""A malformed module announcement is said once per announcer, naming its node and what is wrong, and the
good ones are kept (an audit found them skipped without a word: the run then said the module was not
running, with no hint why)."""
from __future__ import annotations

import json
import logging

import pytest

from modules import discovery
from modules.discovery import announcement
from tests.conftest import log_records


class _Master:
    def __init__(self, params):
        self.params = params

    def getParam(self, key):
        return self.params

    def lookupNode(self, node):
        return "http://127.0.0.1:1%s/" % len(node)


@pytest.fixture
def said(monkeypatch):
    monkeypatch.setattr(discovery, "_WARNED", {}, raising=False)
    with log_records("bmtree.discovery", logging.WARNING) as records:
        yield records


def test_malformed_announcements_are_said_once_each_and_the_good_ones_kept(sim_defs, said):
    good = announcement("/bm_speech", sim_defs["speech"], uri="http://127.0.0.1:4000/",
                        topics={"call_topic": "/bmtree/call/speech", "cancel_topic": "/bmtree/cancel/speech"})
    broken = dict(announcement("/bm_vision", sim_defs["vision"], uri="http://127.0.0.1:4001/"))
    broken["definition"] = broken["definition"][:-5]
    invalid = json.loads(announcement("/bm_navigation", sim_defs["navigation"])["definition"])
    del invalid["Functions"][0]["Input-params"]
    params = {"speech": good, "vision": broken, "battery": {"node": 5}, "arm": "text",
              "navigation": dict(announcement("/bm_navigation", sim_defs["navigation"]), definition=json.dumps(invalid)),
              "deep": {"node": "/bm_deep", "definition": "[" * 5000 + "]" * 5000},
              "odd": dict(announcement("/bm_odd", sim_defs["battery"], uri="http://127.0.0.1:4002/"),
                          call_topic="/function/output")}
    for _ in range(3):   # a preflight reads them twice a second: said once
        found = discovery._announced(_Master(params))
    assert sorted(found) == ["odd", "speech"] and found["odd"].call_topic is None
    assert found["speech"].call_topic == "/bmtree/call/speech"
    lines = sorted(r.getMessage() for r in said)
    assert len(lines) == 6, lines
    assert lines[0] == "malformed module announcement /bmtree/modules/arm: the announcement is not a mapping (got str)"
    assert lines[1] == "malformed module announcement /bmtree/modules/battery: its key 'node' is not text (got int)"
    assert lines[2] == ("malformed module announcement /bmtree/modules/deep by node /bm_deep: its definition cannot be "
                        "read (ProtocolError: JSON nested deeper than 100 levels)")
    assert lines[3].startswith("malformed module announcement /bmtree/modules/navigation by node /bm_navigation: its "
                               "definition is invalid: live:/bm_navigation: Functions[0]") and "Input-params" in lines[3]
    assert lines[4] == ("malformed module announcement /bmtree/modules/odd by node /bm_odd: call_topic: not a topic it "
                        "may use ('/function/output'), so the shared one is used")
    assert lines[5].startswith("malformed module announcement /bmtree/modules/vision by node /bm_vision: its "
                               "definition cannot be read (JSONDecodeError: ")
    params["odd"] = dict(params["odd"], call_topic="/bmtree/call/odd")   # mended: said again if it breaks again
    discovery._announced(_Master(params))
    params["odd"] = dict(params["odd"], call_topic=7)
    discovery._announced(_Master(params))
    assert len(said) == 7 and "call_topic: not a topic it may use (7)" in said[-1].getMessage()


def test_a_parameter_that_is_no_mapping_is_said(said):
    assert discovery._announced(_Master(["x"])) == {}
    assert [r.getMessage() for r in said] == ["malformed module announcement /bmtree/modules/: not a mapping of module "
                                              "name to announcement (got list)"]
