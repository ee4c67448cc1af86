"""Real rosmaster, module nodes as processes, real topics (issues: foundation, module runtime)."""
from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import time

import pytest
from geometry_msgs.msg import Point
from std_msgs.msg import Float64, String

from comm import Event, FunctionCall, commBM
from modules.definition import load_definitions
from tests.conftest import REFERENCE
from tests.integration.conftest import NODES, bmtree_cmd, start_sim_module, wait_announced


def test_a_process_publishes_a_call_another_decodes_it(ros_graph):
    decoder = subprocess.Popen([sys.executable, os.path.join(NODES, "decode_call.py")], env=ros_graph.env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ros_graph.wait_node("/decode_call", proc=decoder)
        ros_graph.start_node([sys.executable, os.path.join(NODES, "publish_call.py"), "1"], "/publish_call")
        out, err = decoder.communicate(timeout=20)
    finally:
        if decoder.poll() is None:
            decoder.kill()
    assert decoder.returncode == 0, err
    got = json.loads(out.strip().splitlines()[-1])
    assert got == {"basic_mod": "PYTHON_BM", "function": "graspObject", "names": ["target_pos", "obj_radius"],
                   "call_id": "from-a-process", "values": [{"x": 0.4, "y": -0.1, "z": 0.8}, {"data": 0.05}]}


@pytest.fixture
def sim_nodes(ros_graph, slow_world):
    faults = {"speech": ['_faults:={say: {crash: "speaker on fire", times: 1}}']}
    return {m: start_sim_module(ros_graph, m, slow_world, *faults.get(m, []),
                                node="bm_%s_faulty" % m if m in faults else None)
            for m in ("navigation", "vision", "speech")}


def test_sim_modules_answer_reject_fail_busy_cancel_and_emit(sim_nodes, sim_defs, caller_factory, ros_probe):
    c = caller_factory(subscribers=3, publishers=3, nodes=["/bm_navigation", "/bm_vision", "/bm_speech_faulty"],
                       answering=["navigation", "vision", "speech"])
    events = ros_probe.collect("/event/output", publishers=2)
    said = ros_probe.collect("/sim/speech/said", publishers=1)
    # every function answers correctly
    r = c.call(sim_defs, "navigation.where_am_i")
    assert r.status == "succeeded" and r.values["room"].data == "entrance"
    r = c.call(sim_defs, "vision.find_person", name="")
    assert r.status == "succeeded" and r.values["success"].data is False        # nobody at the entrance
    r = c.call(sim_defs, "speech.listen", seconds=0.1)
    assert r.values["success"].data is False and r.values["text"].data == ""
    r = c.call(sim_defs, "navigation.go_to", place="bedroom")                    # ~3.2 s at 2 m/s
    assert (r.status, r.values["room"].data) == ("succeeded", "bedroom")
    assert r.basic_mod == "navigation" and r.function == "go_to"
    ev = Event.decode(events.wait_for(lambda t: '"arrived"' in t)[0])
    assert ev.values["place"].data == "bedroom"
    r = c.call(sim_defs, "vision.find_person", name="Ana")
    assert r.values["person"].data == "Ana" and r.values["position"].x == pytest.approx(2.3)
    assert Event.decode(events.wait_for(lambda t: '"personSeen"' in t)[0]).values["person"].data == "Ana"
    assert c.call(sim_defs, "vision.find_object", object="apple").values["success"].data is False
    assert c.call(sim_defs, "speech.listen", seconds=1.0).values["text"].data == "yes, I am coming"
    r = c.call(sim_defs, "navigation.approach", target={"x": 2.3, "y": 6.4})
    assert r.values["success"].data is True
    # exception in user code -> failed, and the node still serves
    r = c.call(sim_defs, "speech.say", text="hola")
    assert (r.status, r.error) == ("failed", "RuntimeError: speaker on fire (injected fault)")
    r = c.call(sim_defs, "speech.say", text="¿Quieres cenar?")
    assert r.status == "succeeded"
    said.wait_for(lambda t: t == "¿Quieres cenar?")
    # unknown function and bad inputs -> rejected with the reason
    c.send(FunctionCall("navigation", "fly", [], names=[], call_id="u1"))
    r = c.result("u1")
    assert r.status == "rejected" and "module 'navigation' has no function 'fly'" in r.error
    c.send(FunctionCall("navigation", "go_to", [Point()], names=["place"], call_id="u2"))
    r = c.result("u2")
    assert r.status == "rejected" and "input 'place' is geometry_msgs/Point, the definition says std_msgs/String" \
        in r.error
    c.send('{"basic_mod": "navigation", "function": "go_to", "call_id": "u3", "names": ["place"], '
           '"rostypes": ["std_msgs/String"], "msgs": ["{\\"data\\": 5}"]}')
    r = c.result("u3")
    assert r.status == "rejected" and "bad inputs" in r.error and "msgs[0]" in r.error
    # busy -> rejected; cancel -> cancelled and the robot stops
    # connected before it is needed, to all three modules (each listens), not just the first
    cancels = ros_probe.publisher("/master/cancel", 3)
    go = sim_defs["navigation"].function("go_to").build_call({"place": "kitchen"})
    x0 = c.call(sim_defs, "navigation.where_am_i").values["position"].x
    c.send(go)
    deadline = time.monotonic() + 20
    while c.call(sim_defs, "navigation.where_am_i").values["position"].x == x0:  # until the robot moves
        assert time.monotonic() < deadline, "go_to never started driving"
    r = c.call(sim_defs, "navigation.approach", target={"x": 1.0})
    assert r.status == "rejected" and r.error == "busy with call %s (go_to)" % go.call_id
    from std_msgs.msg import String

    from comm import CancelRequest

    cancels.publish(String(CancelRequest(go.call_id, "navigation", "go_to").encode()))
    r = c.result(go.call_id)
    assert r.status == "cancelled"
    where = c.call(sim_defs, "navigation.where_am_i")
    assert where.values["room"].data == "bedroom"                     # never arrived
    x1 = where.values["position"].x
    time.sleep(0.5)
    assert c.call(sim_defs, "navigation.where_am_i").values["position"].x == x1   # and does not move any more
    ros_probe.close_collector(events)
    ros_probe.close_collector(said)


def _garbage(rng, i):
    kinds = [
        lambda: "".join(chr(rng.randrange(1, 0x2FF)) for _ in range(rng.randrange(0, 60))),
        lambda: "{" * rng.randrange(1, 5),
        lambda: json.dumps({"basic_mod": "speech", "function": "say", "rostypes": ["std_msgs/String"],
                            "msgs": ['{"data": %d}' % i], "call_id": "bad-%d" % i}),
        lambda: json.dumps({"basic_mod": "speech", "function": 7, "rostypes": [], "msgs": []}),
        lambda: json.dumps({"basic_mod": "navigation", "function": "go_to", "rostypes": ["std_msgs/String"],
                            "msgs": ['{"data": "kitchen"}'], "call_id": "other-%d" % i}),
        lambda: json.dumps([1, 2, 3]),
        lambda: json.dumps({"basic_mod": "speech", "function": "say", "rostypes": ["std_msgs/Strin"],
                            "msgs": ["{}"], "call_id": "bad-%d" % i}),
        lambda: json.dumps({"basic_mod": "speech", "function": "say", "msgs": "x" * 5000}),
    ]
    return rng.choice(kinds)()


def test_a_thousand_malformed_calls_do_not_hurt_a_module(ros_graph, sim_defs, caller_factory):
    proc = start_sim_module(ros_graph, "speech")
    c = caller_factory(subscribers=1, publishers=1, nodes=["/bm_speech"], answering=["speech"])
    rng = random.Random(7)
    good = []
    for i in range(1000):
        c.send(_garbage(rng, i))
        if i % 20 == 0:
            call = sim_defs["speech"].function("say").build_call({"text": "good %d" % i})
            c.send(call)
            good.append(call.call_id)
    for call_id in good:
        r = c.result(call_id, timeout=30)
        assert r.status == "succeeded", r.error
    assert proc.poll() is None
    rejected = [json.loads(t) for t in c.results.items if json.loads(t).get("status") == "rejected"]
    assert rejected and all((r.get("call_id") or "bad-").startswith("bad-") for r in rejected)
    assert c.call(sim_defs, "speech.say", text="still alive").status == "succeeded"


def test_discovery_lists_live_modules_and_forgets_dead_ones(ros_graph):
    nav = start_sim_module(ros_graph, "navigation")
    speech = start_sim_module(ros_graph, "speech")
    env = dict(os.environ)
    out = subprocess.run(bmtree_cmd("modules", "--live"), env=env, capture_output=True, text=True, timeout=30)
    assert out.returncode == 0 and "navigation  (node /bm_navigation)" in out.stdout
    assert "go_to(place: std_msgs/String)" in out.stdout and "speech  (node /bm_speech)" in out.stdout
    ros_graph.kill_node(nav)                  # SIGKILL: no clean-up, its announcement stays behind
    assert ros_graph.stop_node(speech) == 0   # SIGINT: clean stop
    out = subprocess.run(bmtree_cmd("modules", "--live"), env=env, capture_output=True, text=True, timeout=30)
    assert "navigation" not in out.stdout and "speech" not in out.stdout
    import rosgraph

    assert "speech" not in (rosgraph.Master("/t").getParam("/bmtree/modules") or {})


def test_sigterm_stops_a_module_cleanly(ros_graph):
    import signal

    proc = start_sim_module(ros_graph, "vision")
    proc.send_signal(signal.SIGTERM)
    assert _stopped(ros_graph, proc, "bm_vision") == 0


def _stopped(ros_graph, proc, node):
    """The exit status; a node still running after 20 s fails the test with every thread's stack
    (SIGUSR1 makes it print them to its log)."""
    import signal

    try:
        return proc.wait(20)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGUSR1)
        time.sleep(1)
        with open(os.path.join(ros_graph.ros_home, "%s.out" % node), errors="replace") as fh:
            raise AssertionError("%s did not stop on SIGTERM:\n%s" % (node, fh.read()[-8000:]))


def test_sigterm_during_start_up_stops_a_module_cleanly(ros_graph):
    """rospy installs its handlers part-way through init_node; the node's own catch SIGTERM from
    before that, so a stop right after it registers (before it announced the module) is clean too."""
    import signal

    import rosgraph

    from modules.sim import DEFAULT_WORLD

    master = rosgraph.Master("/t")
    for n in range(3):
        name = "bm_early%d" % n
        proc = ros_graph.start_node(["-m", "modules.sim", "vision", "--world", DEFAULT_WORLD, "_basic_mod:=" + name,
                                     "__name:=" + name], "/" + name, wait=False)
        while True:  # registered: init_node is under way or done, the announcement not yet made
            try:
                master.lookupNode("/" + name)
                break
            except rosgraph.MasterError:
                assert proc.poll() is None, "the module ended before registering"
                time.sleep(0.01)
        time.sleep(0.05 * n)
        proc.send_signal(signal.SIGTERM)
        assert _stopped(ros_graph, proc, name) == 0


def test_module_name_overridable_by_ros_parameter(ros_graph, sim_defs, caller_factory):
    from modules.sim import DEFAULT_WORLD

    ros_graph.start_node(["-m", "modules.sim", "speech", "--world", DEFAULT_WORLD, "_basic_mod:=voice",
                          "__name:=bm_voice"], "/bm_voice")
    wait_announced("voice")
    c = caller_factory(nodes=["/bm_voice"], answering=["voice"])
    call = sim_defs["speech"].function("say").build_call({"text": "hi"})
    call.basic_mod = "voice"
    c.send(call)
    r = c.result(call.call_id)
    assert (r.status, r.basic_mod) == ("succeeded", "voice")


def test_a_module_renamed_by_basic_mod_gets_a_node_of_that_name(ros_graph, sim_defs, caller_factory):
    """Two copies of one module side by side, told apart only by _basic_mod:= (no __name:=)."""
    from modules.sim import DEFAULT_WORLD

    for name in ("left_voice", "right_voice"):
        ros_graph.start_node(["-m", "modules.sim", "speech", "--world", DEFAULT_WORLD, "_basic_mod:=" + name],
                             "/bm_" + name)
        wait_announced(name)
    c = caller_factory(nodes=["/bm_left_voice", "/bm_right_voice"], answering=["left_voice", "right_voice"])
    for name in ("left_voice", "right_voice"):
        call = sim_defs["speech"].function("say").build_call({"text": "hi"})
        call.basic_mod = name
        c.send(call)
        assert (c.result(call.call_id).status, c.result(call.call_id).basic_mod) == ("succeeded", name)


def test_module_node_cli_binds_and_reports_errors(tmp_path, ros_master):
    bad = tmp_path / "impl.py"
    bad.write_text("from modules import BasicModule\nclass Speech(BasicModule):\n    def say(self, text):\n"
                   "        return {'success': True}\n")
    out = subprocess.run([sys.executable, "-m", "modules.node", "--definition",
                          os.path.join(os.path.dirname(__file__), "..", "..", "modules", "sim", "speech.json"),
                          "--class", "%s:Speech" % bad], capture_output=True, text=True, timeout=30)
    assert out.returncode == 2
    assert "function 'listen' of definition" in out.stderr and "has no method in class Speech" in out.stderr


def test_original_python_bm_module_called_by_typed_and_legacy_api(ros_graph, caller_factory, ros_probe):
    ros_graph.start_node([sys.executable, os.path.join(NODES, "legacy_python_bm.py")], "/PYTHON_BM")
    defs = load_definitions([REFERENCE])
    c = caller_factory(subscribers=1, publishers=1, nodes=["/PYTHON_BM"])
    call = defs["PYTHON_BM"].function("graspObject").build_call({"target_pos": {"x": 0.3, "y": 0.1, "z": 0.9},
                                                                 "obj_radius": 0.0})
    # the original module answers no ping, so the first call is what proves it connected: sent
    # again (it is idempotent) while a first message is lost to a connection still being set up
    end = time.monotonic() + 20
    while True:
        c.send(call)
        try:
            text = c.results.wait_for(lambda t: "final_pos" in t, timeout=2.0)[0]
            break
        except AssertionError:
            assert time.monotonic() < end, "the original PYTHON_BM module never answered"
    assert set(json.loads(text)) == {"names", "rostypes", "msgs"}    # exactly the original keys, no call_id
    res = defs["PYTHON_BM"].function("graspObject")
    from comm import FunctionResult

    r = FunctionResult.decode(text)
    res.check_result(r)
    assert r.legacy and r.values["success"].data is True and r.values["final_pos"] == Point(0.3, 0.1, 0.9)
    c.results.clear()
    c.send(commBM.writeFunCallFromRos("PYTHON_BM", "putObject", [Point(1.0, 2.0, 3.0)]))
    text = c.results.wait_for(lambda t: "final_pos" in t)[0]
    names, msgs = commBM.readMsg2Ros(text)
    assert names == ["success", "final_pos"] and msgs[1] == Point(1.0, 2.0, 3.0)
    c.results.clear()
    c.send(commBM.writeFunCallFromRos("PYTHON_BM", "goSafePos", []))
    names, msgs = commBM.readMsg2Ros(c.results.wait_for(lambda t: "final_pos" in t)[0])
    assert msgs[1] == Point(0.0, 0.0, 0.5)
    assert String and Float64  # message classes used by the legacy node are importable here too
