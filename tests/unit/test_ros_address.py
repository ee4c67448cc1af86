"""The advertised address of a ROS node, and why others cannot reach it (comm.address).

Only this machine's own addresses and the documentation ranges are used: 203.0.113.0/24
(TEST-NET-3) is never an address of a machine, ``.invalid`` names never resolve.
"""
from __future__ import annotations

import socket
import threading
from xmlrpc.server import SimpleXMLRPCServer

import pytest

from comm.address import (
    REFUSED,
    OwnAddress,
    advertised,
    is_loopback,
    is_own_address,
    master_is_remote,
    node_address_problem,
    own_address_problem,
    reach,
    suggested_address,
    warn_own_address,
)

REMOTE_MASTER = "http://10.77.0.1:11311/"
LOCAL_MASTER = "http://127.0.0.1:11311/"
NOT_MINE = "203.0.113.77"


def suggest(_master):
    return "10.77.0.2"


# what this process advertises ------------------------------------------------------------

def test_the_advertised_host_is_chosen_as_rosgraph_does():
    assert advertised({"ROS_IP": "10.0.0.5"}, []) == OwnAddress("10.0.0.5", "ROS_IP")
    # ROS_HOSTNAME wins over ROS_IP; an empty one counts as unset
    assert advertised({"ROS_IP": "10.0.0.5", "ROS_HOSTNAME": "robot"}, []) == OwnAddress("robot", "ROS_HOSTNAME")
    assert advertised({"ROS_IP": "10.0.0.5", "ROS_HOSTNAME": ""}, []) == OwnAddress("10.0.0.5", "ROS_IP")
    assert advertised({"ROS_IP": "10.0.0.5"}, ["__ip:=10.0.0.6"]) == OwnAddress("10.0.0.6", "__ip:=")
    assert advertised({}, [], hostname=lambda: "robot") == OwnAddress("robot", "")
    assert advertised({"ROS_IP": ""}, [], hostname=lambda: "robot") == OwnAddress("robot", "")
    local = advertised({}, [], hostname=lambda: "localhost")  # rosgraph takes an interface's address then
    assert local.variable == "" and local.host != "localhost"
    assert OwnAddress("127.0.0.1", "ROS_IP").said() == "ROS_IP=127.0.0.1"
    assert OwnAddress("robot", "").said() == "this machine's name 'robot'"


def test_loopback_and_own_addresses():
    assert is_loopback("127.0.0.1") and is_loopback("127.0.1.1") and is_loopback("::1")
    assert not is_loopback("10.77.0.1") and not is_loopback("robot")
    assert is_own_address("127.0.1.1")  # Ubuntu's hostname address: loopback, this machine's
    assert not is_own_address(NOT_MINE)


def test_a_master_is_remote_when_its_uri_is_not_loopback():
    assert master_is_remote(REMOTE_MASTER)
    assert not master_is_remote(LOCAL_MASTER) and not master_is_remote("http://localhost:11311/")
    assert not master_is_remote("http://robot.invalid:11311/")  # cannot tell: no warning


# this process's own address ----------------------------------------------------------------

def test_a_loopback_ros_ip_with_a_remote_master_names_the_variable_and_the_fix():
    problem = own_address_problem(REMOTE_MASTER, OwnAddress("127.0.0.1", "ROS_IP"), suggest)
    assert problem is not None and problem.kind == "loopback"
    assert problem.text == (
        "ROS_IP=127.0.0.1 is a loopback address while the ROS master http://10.77.0.1:11311/ is not: nodes on other "
        "machines cannot connect to this process (they would reach themselves): set ROS_IP=<an address of this "
        "machine on the robot's network, e.g. 10.77.0.2>")
    assert problem.where == "ROS_IP=127.0.0.1, a loopback address"


def test_the_hostname_on_loopback_with_a_remote_master_says_ros_ip_is_not_set():
    """Day one on Ubuntu: the machine's name maps to 127.0.1.1 (here: localhost)."""
    problem = own_address_problem(REMOTE_MASTER, OwnAddress("localhost", ""), suggest)
    assert problem is not None and problem.kind == "loopback"
    assert problem.text.startswith("this machine's name 'localhost' (127.0.0.1; ROS_IP is not set) is a loopback "
                                   "address while the ROS master http://10.77.0.1:11311/ is not")
    assert problem.text.endswith("set ROS_IP=<an address of this machine on the robot's network, e.g. 10.77.0.2>")


def test_a_loopback_ros_hostname_also_says_to_unset_it():
    problem = own_address_problem(REMOTE_MASTER, OwnAddress("localhost", "ROS_HOSTNAME"), suggest)
    assert problem is not None and problem.text.endswith("e.g. 10.77.0.2> and unset ROS_HOSTNAME (it wins over ROS_IP)")


def test_loopback_is_right_when_the_master_is_on_loopback_too():
    assert own_address_problem(LOCAL_MASTER, OwnAddress("127.0.0.1", "ROS_IP"), suggest) is None
    assert own_address_problem("http://localhost:11311/", OwnAddress("localhost", ""), suggest) is None
    assert own_address_problem("http://robot.invalid:11311/", OwnAddress("127.0.0.1", "ROS_IP"), suggest) is None


def test_an_address_not_of_this_machine_is_named():
    problem = own_address_problem(REMOTE_MASTER, OwnAddress(NOT_MINE, "ROS_IP"), suggest)
    assert problem is not None and problem.kind == "foreign"
    assert problem.text == ("ROS_IP=203.0.113.77 is not an address of this machine, so other nodes cannot connect to "
                            "this process: set ROS_IP=<an address of this machine on the robot's network, e.g. "
                            "10.77.0.2>")
    # with a master on loopback too: the master cannot call it back either
    assert own_address_problem(LOCAL_MASTER, OwnAddress(NOT_MINE, "ROS_IP"), suggest) is not None
    # this machine's own, non-loopback address is right
    assert own_address_problem(REMOTE_MASTER, OwnAddress("10.77.0.2", "ROS_IP"), suggest, mine=lambda a: True) is None


def test_a_name_that_does_not_resolve_keeps_its_message():
    problem = own_address_problem(REMOTE_MASTER, OwnAddress("robot.invalid", ""), suggest)
    assert problem is not None and problem.kind == "unresolved"
    assert "this machine's name 'robot.invalid' does not resolve" in problem.text
    assert "ROS_IP" in problem.text and "ROS_HOSTNAME" in problem.text
    # the master on another machine: this machine's own address, not loopback (it suggested 127.0.0.1 there)
    assert "(export ROS_IP=10.77.0.2, this machine's address towards the master %s)" % REMOTE_MASTER in problem.text
    assert "127.0.0.1" not in problem.text
    here = own_address_problem(LOCAL_MASTER, OwnAddress("robot.invalid", ""), suggest)
    assert here is not None and "(export ROS_IP=127.0.0.1 when every node runs here)" in here.text


def test_without_an_example_the_fix_is_still_said():
    problem = own_address_problem(REMOTE_MASTER, OwnAddress("127.0.0.1", "ROS_IP"), lambda m: "")
    assert problem is not None and problem.text.endswith("set ROS_IP=<an address of this machine on the robot's network>")


def test_the_example_address_is_never_loopback():
    assert not is_loopback(suggested_address(LOCAL_MASTER) or "10.0.0.1")
    assert not is_loopback(suggested_address(REMOTE_MASTER) or "10.0.0.1")


def test_each_process_warns_once(monkeypatch):
    import comm.address

    monkeypatch.setattr(comm.address, "_warned", [False])
    monkeypatch.setenv("ROS_IP", "127.0.0.1")
    monkeypatch.delenv("ROS_HOSTNAME", raising=False)
    monkeypatch.setenv("ROS_MASTER_URI", REMOTE_MASTER)
    said = []
    assert warn_own_address(said.append) is not None
    assert warn_own_address(said.append) is not None
    assert len(said) == 1 and said[0].startswith("warning: ROS_IP=127.0.0.1 is a loopback address") and "set ROS_IP=<" in said[0]
    monkeypatch.setattr(comm.address, "_warned", [False])
    monkeypatch.setenv("ROS_MASTER_URI", LOCAL_MASTER)
    assert warn_own_address(said.append) is None and len(said) == 1


# another node's registered address ----------------------------------------------------------

def test_a_loopback_uri_that_does_not_answer_with_a_remote_master_is_an_address_problem():
    why = node_address_problem("/bm_vision", "http://127.0.0.1:4000/", REFUSED, REMOTE_MASTER)
    assert why == ("node /bm_vision registered http://127.0.0.1:4000/, a loopback address, which does not answer "
                   "from here (connection refused): a wrong ROS_IP on the machine that runs it?")
    # one that answers here (it runs on this machine) still cannot be reached by the master
    why = node_address_problem("/bm_vision", "http://127.0.0.1:4000/", "", REMOTE_MASTER)
    assert "a loopback address, which the master and the nodes on other machines cannot reach" in why
    why = node_address_problem("/bm_vision", "http://localhost:4000/", REFUSED, REMOTE_MASTER)
    assert "a name of a loopback address here (127.0.0.1)" in why and "a wrong ROS_IP or ROS_HOSTNAME" in why


def test_a_refused_connection_is_a_dead_process_not_an_address_problem():
    assert node_address_problem("/bm_vision", "http://10.77.0.2:4000/", REFUSED, REMOTE_MASTER) == ""
    assert node_address_problem("/bm_vision", "http://127.0.0.1:4000/", REFUSED, LOCAL_MASTER) == ""
    assert node_address_problem("/bm_vision", "http://127.0.0.1:4000/", "", LOCAL_MASTER) == ""


def test_a_timeout_or_no_route_to_another_machine_is_an_address_problem():
    for failure in ("timed out", "no route to host"):
        why = node_address_problem("/bm_vision", "http://%s:4000/" % NOT_MINE, failure, REMOTE_MASTER)
        assert why.startswith("node /bm_vision registered http://203.0.113.77:4000/, which does not answer from here "
                              "(%s): a wrong ROS_IP on the machine that runs it" % failure), why
    # on this machine a timeout is a stuck process
    assert node_address_problem("/bm_vision", "http://127.0.0.1:4000/", "timed out", LOCAL_MASTER) == ""


def _closed_port():
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_reach_tells_refused_from_timed_out_from_answered():
    assert reach("http://127.0.0.1:%d/" % _closed_port(), 2.0) == REFUSED
    with socket.socket() as silent:  # accepts (the kernel does), never answers
        silent.bind(("127.0.0.1", 0))
        silent.listen(4)
        assert reach("http://127.0.0.1:%d/" % silent.getsockname()[1], 0.3) == "timed out"
    server = SimpleXMLRPCServer(("127.0.0.1", 0), logRequests=False)
    server.register_function(lambda caller: [1, "", 42], "getPid")
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        assert reach("http://127.0.0.1:%d/" % server.server_address[1], 2.0) == ""
    finally:
        server.shutdown()
        server.server_close()
    assert reach("http://nowhere.invalid:4000/", 2.0) == "its name does not resolve here"


# where the messages are said ----------------------------------------------------------------

@pytest.fixture
def speech_at_a_closed_loopback_port():
    from modules.definition import load_definition
    from modules.discovery import LiveModule
    from modules.sim import definition_path

    return LiveModule("speech", "/bm_speech", "http://127.0.0.1:%d/" % _closed_port(),
                      load_definition(definition_path("speech")))


def test_the_preflight_tells_an_unreachable_node_from_a_dead_one(monkeypatch, speech_at_a_closed_loopback_port):
    from coordinator.preflight import _dead

    monkeypatch.setenv("ROS_MASTER_URI", REMOTE_MASTER)
    found = _dead([speech_at_a_closed_loopback_port])["speech"]
    assert found == ["module 'speech' cannot be reached: node /bm_speech registered %s, a loopback address, which "
                     "does not answer from here (connection refused): a wrong ROS_IP on the machine that runs it?"
                     % speech_at_a_closed_loopback_port.uri]
    monkeypatch.setenv("ROS_MASTER_URI", LOCAL_MASTER)
    assert _dead([speech_at_a_closed_loopback_port])["speech"] == [
        "module 'speech' is not running (node /bm_speech announced it but does not answer)"]


def test_the_watch_without_a_run_names_its_own_address():
    from coordinator.watch import no_run_message

    problem = own_address_problem(REMOTE_MASTER, OwnAddress("127.0.0.1", "ROS_IP"), suggest)
    message = no_run_message("/bmtree/run", 20.0, address=str(problem))
    assert message.startswith("error: no run on /bmtree/run/tree after 20s (is 'bmtree run' running on this master? "
                              "If it is, it cannot reach this watch: ROS_IP=127.0.0.1 is a loopback address")
    assert "set ROS_IP=<an address of this machine on the robot's network, e.g. 10.77.0.2>)" in message
    assert "ROS_IP" not in no_run_message("/bmtree/run", 20.0)
