"""A module may say it cannot take a call now (``BasicModule.not_ready``): a ping, bmtree run's start-up
check, is then left unanswered and the run waits for it, as the C++ bridge does while its C++ node is
down. Any other call goes its way. No ROS: the node's own call inbox."""
from __future__ import annotations

import json

from comm.addressing import PING_FUNCTION
from comm.messages import FunctionCall
from modules.basicmodule import BasicModule
from modules.node import CallInbox


class Arm(BasicModule):
    def __init__(self):
        super().__init__()
        self.why = "the arm's driver has not started"
        self.asked_by = []

    def not_ready(self, caller=None):
        self.asked_by.append(caller)
        return self.why


def test_a_ping_waits_for_a_module_that_says_it_is_not_ready():
    arm, answers, calls = Arm(), [], []
    inbox = CallInbox("arm", calls.append, lambda text: None, answers.append, not_ready=arm.not_ready)
    ping = FunctionCall("arm", PING_FUNCTION, [], names=[], call_id="p").encode()
    inbox.handle_call(ping, "/bmtree_run")
    assert answers == [] and arm.asked_by == ["/bmtree_run"]
    call = FunctionCall("arm", "move", [], names=[], call_id="c").encode()
    inbox.handle_call(call, "/bmtree_run")
    assert calls == [call]   # a call is the module's to refuse, saying why
    arm.why = ""
    inbox.handle_call(ping, "/bmtree_run")
    assert [json.loads(a)["call_id"] for a in answers] == ["p"]


def test_a_module_is_ready_unless_it_says_otherwise():
    assert BasicModule().not_ready("/x") == ""
