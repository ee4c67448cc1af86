"""bmtree-bridge without ROS, a second audit's findings: a BM_output's status decides (an empty error is
still a failure), ``--max-bytes``, and pings left unanswered while the C++ node is down."""
from __future__ import annotations

import json
import os

import pytest
from std_msgs.msg import Bool

from comm import FunctionCall
from comm.addressing import PING_FUNCTION
from modules.bridge import _Call, main, make_bridge, make_parser
from modules.definition import FunctionDefinition, load_definition
from modules.node import CallInbox
from modules.runtime import Failure, ModuleServer, Rejected
from tests.conftest import ROOT

GRIPPER = os.path.join(ROOT, "modules", "cpp", "example", "gripper.json")


def _bridge():
    d = load_definition(GRIPPER)
    bridge = make_bridge(d)
    ModuleServer(d, bridge, lambda t: None, lambda t: None)
    bridge.cpp_node = "/gripper"
    return bridge


def _answered(fn, output, fresh=None):
    call = _Call(fn, sorted(fresh or {}))
    call.fresh.update(fresh or {})
    call.output = output
    return call


NO_OUTPUTS = {"outparam_names": [], "outparam_topics": []}


def test_an_empty_error_with_status_failed_is_a_failure_not_a_success():
    """bmtree::Failure("") in a C++ function without outputs: its BM_output says "failed" with an empty
    error, which was taken for a success (the error's text decided, not the status)."""
    bridge = _bridge()
    stop = FunctionDefinition(name="stop", inputs=(), outputs=(), module="gripper")
    with pytest.raises(Failure) as exc:
        bridge._outputs(_answered(stop, dict(NO_OUTPUTS, status="failed", error="")))
    assert str(exc.value) == "the C++ node /gripper gave no message (its BM_output says failed with an empty error)"
    with pytest.raises(Failure, match="says cancelled with an empty error"):
        bridge._outputs(_answered(stop, dict(NO_OUTPUTS, status="cancelled")))
    assert bridge._outputs(_answered(stop, dict(NO_OUTPUTS))) == {}  # the original protocol: no status
    assert bridge._outputs(_answered(stop, dict(NO_OUTPUTS, status="succeeded", error=""))) == {}


def test_an_empty_error_with_status_rejected_is_a_rejection_not_a_missing_output():
    """bmtree::Rejected("") in a function with outputs was answered failed, blaming the definition:
    "the C++ node's BM_output does not match the definition: missing output 'success'"."""
    ping = _bridge().definition.function("ping")
    with pytest.raises(Rejected) as exc:
        _bridge()._outputs(_answered(ping, dict(NO_OUTPUTS, status="rejected", error=""), {"/gripper/bool": []}))
    assert str(exc.value) == "the C++ node /gripper gave no message (its BM_output says rejected with an empty " \
                             "error)"
    with pytest.raises(Failure, match="gave no message"):
        _bridge()._outputs(_answered(ping, dict(NO_OUTPUTS, status="failed"), {"/gripper/bool": []}))
    out = _bridge()._outputs(_answered(ping, {"outparam_names": ["success"], "outparam_topics": ["/gripper/bool"]},
                                       {"/gripper/bool": [Bool(True)]}))
    assert out["success"].data is True


def test_an_unknown_status_is_a_malformed_answer():
    ping = _bridge().definition.function("ping")
    with pytest.raises(Failure, match=r'malformed BM_output from /gripper: unknown status "done"'):
        _bridge()._outputs(_answered(ping, {"outparam_names": ["success"], "outparam_topics": ["/gripper/bool"],
                                            "status": "done"}, {"/gripper/bool": [Bool(True)]}))


def test_max_bytes_is_an_option_of_the_bridge_and_reaches_its_node(monkeypatch, capsys):
    """``bmtree-bridge --max-bytes N`` was refused (unrecognized arguments), though the README says every
    module node takes it; ``_max_bytes:=N`` alone worked."""
    assert "--max-bytes" in make_parser().format_help()
    assert make_parser().parse_args(["--definition", GRIPPER, "--max-bytes", "3000000"]).max_bytes == 3000000
    assert make_parser().parse_args(["--definition", GRIPPER]).max_bytes is None  # then ~max_bytes, else 1 MiB
    assert main(["bmtree-bridge", "--definition", GRIPPER, "--max-bytes", "10"]) == 2
    assert "argument --max-bytes: expected a whole number of at least" in capsys.readouterr().err

    import modules.node

    seen = {}

    def run_module(definition, impl, node_name=None, failures=None, **kwargs):
        seen.update(kwargs, impl=impl)
        return 0

    monkeypatch.setattr(modules.node, "run_module", run_module)
    assert main(["bmtree-bridge", "--definition", GRIPPER, "--max-bytes", "3000000"]) == 0
    assert seen["max_bytes"] == 3000000 and seen["impl"].max_bytes == 3000000
    assert main(["bmtree-bridge", "--definition", GRIPPER]) == 0
    assert seen["max_bytes"] is None  # the module node reads ~max_bytes, and the bridge takes its value in setup()


class _Node:
    """The module node's call inbox, as its node makes it (asking the module's not_ready at each ping)."""

    def __init__(self, module, impl):
        self.answers = []
        self.calls = []
        self.inbox = CallInbox(module, self.calls.append, lambda text: None, self.answers.append,
                               not_ready=impl.not_ready)


def test_a_ping_is_not_answered_while_the_cpp_node_is_down():
    """The module node answers bmtree run's ping itself: for a dead C++ node the run started and its first
    call was refused. The bridge now lets the ping go unanswered (the run waits, as for a module not
    started) while its C++ node is not running, and says why in its log."""
    bridge = _bridge()
    node = _Node("gripper", bridge)
    bridge._watcher = object()  # (started)
    bridge.cpp_uri = ""  # (no port to look at)

    def ping():
        node.inbox.handle_call(FunctionCall("gripper", PING_FUNCTION, [], names=[], call_id="p").encode(), "/run")

    ping()
    assert len(node.answers) == 1 and json.loads(node.answers[0])["status"] == "succeeded"  # the node is up

    bridge.cpp_uri = "http://127.0.0.1:1/"
    bridge._deaths[bridge.cpp_uri] = (0.0, "died (killed or crashed: nothing listens at http://127.0.0.1:1/)")
    ping()
    assert len(node.answers) == 1  # not answered
    assert bridge._not_ready().startswith("the C++ node /gripper of module 'gripper' is not running: it died at ")
    call = FunctionCall("gripper", "ping", [], names=[], call_id="c").encode()
    node.inbox.handle_call(call, "/run")
    assert node.calls == [call]  # a call goes its way (the bridge refuses it, saying why)

    del bridge._deaths[bridge.cpp_uri]
    bridge._absent = "/gripper does not receive /gripper/BM_input"  # started again, still connecting
    ping()
    assert len(node.answers) == 1
    assert bridge._not_ready(look=False) == "the C++ node of module 'gripper' is not connected: /gripper does not " \
                                            "receive /gripper/BM_input"
    bridge._absent = ""
    bridge.cpp_uri = ""
    ping()
    assert len(node.answers) == 2
