"""A module of events only (``"Functions": []``): a ROS topic turned into events, bmtree's form of
SMACH's MonitorState. Its definition loads and is checked without a word, its class (no public
method) binds and emits, and its node's start-up line says what it serves (it said ``serving ``)."""
from __future__ import annotations

import json

from comm.messages import Event
from coordinator.cli import main as bmtree
from modules import BasicModule
from modules.definition import load_definition, load_definitions, parse_definition
from modules.discovery import announcement
from modules.runtime import ModuleServer
from modules.sim import SIM_DIR

MONITOR = {
    "Basic Module": "door_monitor",
    "Brief Description": "The door sensor's topic as events.",
    "Hardware Required": [],
    "Functions": [],
    "Events": [{"Name": "heard", "Description": "The sensor said something.",
                "Event-params": [{"Name": "text", "Data-type": "std_msgs/String", "Description": "what it said"}]}],
}
TREE = """format: 1
root:
  sequence:
    - wait_event: door_monitor.heard
      where: 'text == "open"'
      outputs: {text: said}
      timeout: 10
    - call: speech.say
      inputs: {text: "the door is {said}"}
"""


class DoorMonitor(BasicModule):
    """No function: a topic's callback (private: a public method would have to be a function) emits."""

    def _on_message(self, text: str) -> None:
        self.emit("heard", text=text)


def _monitor(tmp_path) -> str:
    path = tmp_path / "door_monitor.json"
    path.write_text(json.dumps(MONITOR, indent=2))
    return str(path)


def test_the_start_up_line_of_an_events_only_module_says_it_serves_no_functions_and_its_events():
    from modules.node import serving_line

    assert serving_line(parse_definition(MONITOR)) == "serving no functions; events: heard"
    sim = load_definitions([SIM_DIR])
    assert serving_line(sim["speech"]) == "serving say, listen"
    assert serving_line(sim["navigation"]) == "serving go_to, approach, where_am_i; events: arrived"
    assert serving_line(parse_definition(dict(MONITOR, Events=[]))) == "serving no functions and no events"


def test_an_events_only_module_is_checked_without_errors_or_warnings(tmp_path, capsys):
    path = _monitor(tmp_path)
    definition = load_definition(path)
    assert not definition.functions and list(definition.events) == ["heard"]
    tree = tmp_path / "door.yaml"
    tree.write_text(TREE)
    assert bmtree(["check", "--strict", "--modules", path, str(tree)]) == 0
    out = capsys.readouterr()
    assert out.err == "" and out.out.strip() == "%s: ok" % tree, out
    assert bmtree(["modules", path]) == 0
    assert "event heard(text: std_msgs/String)" in capsys.readouterr().out


def test_an_events_only_module_binds_announces_and_emits(tmp_path):
    definition = load_definition(_monitor(tmp_path))
    events = []
    impl = DoorMonitor()
    ModuleServer(definition, impl, lambda text: None, events.append)
    impl._on_message("open")
    [sent] = [Event.decode(e) for e in events]
    assert (sent.basic_mod, sent.event, sent.names) == ("door_monitor", "heard", ["text"])
    assert sent.msgs[0].data == "open"
    said = announcement("/bm_door_monitor", definition)
    assert parse_definition(json.loads(said["definition"])).events["heard"].params[0].rostype == "std_msgs/String"


def test_a_call_to_an_events_only_module_says_it_has_events_to_wait_for(tmp_path, capsys):
    path = str(tmp_path / "door_monitor.json")
    with open(path, "w") as fh:
        json.dump(MONITOR, fh)
    tree = tmp_path / "t.yaml"
    tree.write_text("format: 1\nroot:\n  call: door_monitor.heard\n")
    assert bmtree(["check", "--modules", path, str(tree)]) == 2
    err = capsys.readouterr().err
    assert "t.yaml:3:9: module 'door_monitor' has no function 'heard' (it has no functions; its events: heard: wait " \
           "for one with wait_event: door_monitor.heard)" in err, err
