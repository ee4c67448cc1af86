"""The engine with the in-process transport and a simulated clock (no ROS master)."""
from __future__ import annotations

import logging

import pytest
from geometry_msgs.msg import Point
from py_trees.common import Status
from std_msgs.msg import Bool, String

from comm import FunctionResult
from coordinator.builder import build_tree
from coordinator.clock import SimClock
from coordinator.context import RunContext
from coordinator.language import load_tree
from coordinator.runner import TreeRunner
from coordinator.testing import MockError, TreeTest, fail, hang, succeed
from coordinator.testing.inprocess import InProcessTransport
from coordinator.testing.mocks import Mocks


def tree(tmp_path, body, name="t.yaml"):
    path = tmp_path / name
    path.write_text("format: 1\n" + body)
    return str(path)


def test_call_statuses_outputs_and_success_convention(tmp_path):
    t = TreeTest(tree(tmp_path, """
root:
  sequence:
    - call: speech.listen
      inputs: {seconds: 2}
      outputs: {text: heard}
    - call: vision.find_object
      inputs: {object: $heard}
"""))
    t.mocks["speech.listen"].succeed(text="cup")
    t.mocks["vision.find_object"].succeed(success=False)
    run = t.run()
    assert run.failed and "answered success: false" in run.reason
    assert run.calls("vision.find_object")[0].inputs == {"object": "cup"}
    assert run.blackboard["heard"] == "cup"
    assert run.statuses("speech.listen") == ["RUNNING", "SUCCESS"]


def test_check_success_false_keeps_going(tmp_path):
    t = TreeTest(tree(tmp_path, """
root:
  call: vision.find_object
  inputs: {object: cup}
  outputs: {success: seen}
  check_success: false
"""))
    t.mocks["vision.find_object"].succeed(success=False)
    run = t.run()
    assert run.succeeded and run.blackboard["seen"] is False


def test_call_timeout_cancels_and_fails(tmp_path):
    t = TreeTest(tree(tmp_path, "root:\n  call: navigation.go_to\n  inputs: {place: kitchen}\n  timeout: 7\n"))
    t.mocks["navigation.go_to"].hang()
    run = t.run()
    assert run.failed and "no answer within 7s" in run.reason
    assert run.duration == pytest.approx(7.0)
    (call,) = run.calls()
    assert call.status == "timeout"
    cancels = [m for m in run.transport.sent if type(m).__name__ == "CancelRequest"]
    assert [c.call_id for c in cancels] == [call.call_id]


def test_timeout_decorator_halts_child_with_cancel(tmp_path):
    t = TreeTest(tree(tmp_path, """
root:
  selector:
    - timeout: 3
      child:
        call: navigation.go_to
        inputs: {place: kitchen}
    - call: speech.say
      inputs: {text: giving up}
"""))
    t.mocks["navigation.go_to"].succeed(delay=10.0, room="kitchen")
    run = t.run()
    assert run.succeeded and run.targets == ["navigation.go_to", "speech.say"]
    assert run.calls("navigation.go_to")[0].status == "halted"
    assert run.calls("speech.say")[0].started == pytest.approx(3.0)
    assert any(type(m).__name__ == "CancelRequest" for m in run.transport.sent)


def test_higher_priority_branch_halts_running_call(tmp_path):
    t = TreeTest(tree(tmp_path, """
inputs:
  alarm: {default: false}
root:
  parallel:
    policy: one
    children:
      - sequence: [{wait: 2}, {set: {alarm: true}}, {wait: 100}]
      - selector:
          memory: false
          children:
            - check: alarm
            - call: navigation.go_to
              inputs: {place: kitchen}
"""))
    t.mocks["navigation.go_to"].hang()
    run = t.run()
    assert run.succeeded and run.duration == pytest.approx(2.0)
    (call,) = run.calls("navigation.go_to")
    assert call.status == "halted"
    cancels = [m for m in run.transport.sent if type(m).__name__ == "CancelRequest"]
    assert [c.call_id for c in cancels] == [call.call_id]


def test_parallel_success_on_one_halts_the_other_branch(tmp_path):
    t = TreeTest(tree(tmp_path, """
root:
  parallel:
    policy: one
    children:
      - wait_event: vision.lostPerson
        outputs: {person: lost}
      - call: navigation.go_to
        inputs: {place: kitchen}
"""))
    t.mocks["navigation.go_to"].hang()
    t.mocks.event(4.0, "vision.lostPerson", person="Ana")
    run = t.run()
    assert run.succeeded and run.blackboard["lost"] == "Ana" and run.duration == pytest.approx(4.0)
    assert run.calls("navigation.go_to")[0].status == "halted"


def test_retry_repeat_parallel_inverter_force(tmp_path):
    t = TreeTest(tree(tmp_path, """
root:
  sequence:
    - retry: 3
      child: {call: navigation.go_to, inputs: {place: kitchen}}
    - repeat: 2
      child: {call: speech.say, inputs: {text: hi}}
    - parallel:
        - call: speech.say
          inputs: {text: one}
        - wait: 1.5
      policy: all
    - inverter: {check: 'false'}
    - force_success: {call: vision.find_object, inputs: {object: pear}}
    - force_failure: {wait: 0}
"""))
    t.mocks["navigation.go_to"].fail_first(2, "blocked", room="kitchen")
    t.mocks["vision.find_object"].succeed(success=False)
    run = t.run()
    assert run.failed  # the last node forces failure
    assert [c.status for c in run.calls("navigation.go_to")] == ["failed", "failed", "succeeded"]
    assert len(run.calls("speech.say")) == 3
    assert run.duration == pytest.approx(1.5)


def test_retry_waits_its_delay_between_attempts_without_ticking_the_child(tmp_path):
    """``delay``: a module restarting or a door opening needs time; attempts back to back would
    all fail within it."""
    t = TreeTest(tree(tmp_path, """
inputs:
  pause: {default: 2.5}
root:
  retry: 3
  delay: $pause
  child: {call: navigation.go_to, inputs: {place: kitchen}}
"""))
    t.mocks["navigation.go_to"].fail_first(2, "blocked", room="kitchen")
    run = t.run()
    assert run.succeeded and run.duration == pytest.approx(5.0)
    assert [round(c.started - run.result.started, 3) for c in run.calls("navigation.go_to")] == [0.0, 2.5, 5.0]
    assert run.statuses("retry x3") == ["RUNNING", "SUCCESS"]


def test_wait_event_timeout_and_set(tmp_path):
    t = TreeTest(tree(tmp_path, """
root:
  selector:
    - wait_event: navigation.arrived
      timeout: 2
    - set: {gave_up: true}
"""))
    run = t.run()
    assert run.succeeded and run.blackboard == {"gave_up": True} and run.duration == pytest.approx(2.0)


def test_a_wait_event_in_a_loop_takes_each_of_the_events_that_came_together(tmp_path):
    """Two people seen at once: a loop over wait_event took Bob, and its next run started after Ana
    had come (with Bob), so it skipped her and waited out its timeout. Events that come together
    are one moment: the restarted leaf takes the others of that moment first, then new ones."""
    t = TreeTest(tree(tmp_path, """
root:
  repeat: 10
  until: 'who == "Ana"'
  child:
    wait_event: vision.personSeen
    outputs: {person: who}
    timeout: 5
"""))
    t.mocks.event(1.0, "vision.personSeen", person="Bob", position={"x": 1.0})
    t.mocks.event(1.0, "vision.personSeen", person="Ana", position={"x": 1.0})
    run = t.run()
    assert run.succeeded, run.reason
    assert run.blackboard["who"] == "Ana" and run.duration == pytest.approx(1.0)
    t = TreeTest(tree(tmp_path, """
root:
  sequence:
    - wait: 2
    - repeat: 2
      child:
        wait_event: vision.personSeen
        outputs: {person: who}
        timeout: 5
"""))
    t.mocks.event(1.0, "vision.personSeen", person="Bob", position={"x": 1.0})  # before the leaf started: not for it
    t.mocks.event(3.0, "vision.personSeen", person="Ana", position={"x": 1.0})
    t.mocks.event(4.0, "vision.personSeen", person="Eve", position={"x": 1.0})
    run = t.run()
    assert run.succeeded and run.blackboard["who"] == "Eve" and run.duration == pytest.approx(4.0)


def test_recall_from_the_blackboard(tmp_path):
    t = TreeTest(tree(tmp_path, """
root:
  sequence:
    - call: navigation.go_to
      inputs: {place: kitchen}
    - recall: {where: navigation/go_to/room, ok: success}
    - check: 'where == "kitchen" and ok'
    - selector:
        - recall: {nothing: never_stored}
        - set: {missing_was_reported: true}
"""))
    t.mocks["navigation.go_to"].succeed(room="kitchen")
    run = t.run()
    assert run.succeeded and run.blackboard["where"] == "kitchen" and run.blackboard["missing_was_reported"]


def test_mocks_refuse_what_the_module_would_refuse(tmp_path, sim_defs):
    mocks = Mocks(sim_defs)
    with pytest.raises(MockError, match="has no function 'fly'"):
        mocks["navigation.fly"]
    with pytest.raises(MockError, match="unknown output 'rooom'"):
        mocks["navigation.go_to"].succeed(rooom="kitchen")
    with pytest.raises(MockError) as info:
        mocks["navigation.approach"].succeed(position={"x": "near"})
    assert str(info.value).endswith("navigation.approach: output 'position' (geometry_msgs/Point): field x takes a "
                                    "number (float64), got 'near'")
    clock = SimClock()
    transport = InProcessTransport(mocks, clock)
    got = []
    transport.connect(got.append)
    from comm import FunctionCall

    transport.send_call(FunctionCall("speech", "sing", [], names=[], call_id="c1"))
    transport.send_call(FunctionCall("speech", "say", [Bool(True)], names=["text"], call_id="c2"))
    assert [(r.status, r.call_id) for r in got] == [("rejected", "c1"), ("rejected", "c2")]
    assert "has no function 'sing'" in got[0].error and "std_msgs/Bool" in got[1].error


def _ctx_with_tree(tmp_path, sim_defs, body):
    clock = SimClock()
    mocks = Mocks(sim_defs)
    ctx = RunContext(InProcessTransport(mocks, clock), clock, sim_defs)
    root = build_tree(load_tree(tree(tmp_path, body), sim_defs), ctx)
    return ctx, root, mocks


def test_legacy_result_correlation(tmp_path, sim_defs):
    """Results without call_id: within the module that published them (named, or mapped from the
    publishing node by the transport), by function when named, else by output names; else dropped."""
    ctx, root, _ = _ctx_with_tree(tmp_path, sim_defs, """
root:
  parallel:
    - call: speech.say
      inputs: {text: a}
    - call: navigation.where_am_i
    - call: vision.find_object
      inputs: {object: apple}
""")
    ctx.transport.send_call = lambda call: None      # nobody answers: we play the legacy modules
    root.setup_with_descendants()
    root.tick_once()
    say, where, find = ctx.calls
    ctx.dispatch(FunctionResult(["room", "position"], [String("hall"), Point()]))
    assert where.result is not None and say.result is None            # by output names (no publisher known)
    ctx.dispatch(FunctionResult(["success"], [Bool(True)], basic_mod="speech", function="say"))
    assert say.result is not None                                       # by module and function
    ctx.dispatch(FunctionResult(["something"], [String("x")]))
    assert find.result is None and len(ctx.dropped) == 1                # no oldest-call fallback
    vision_outputs = (["success", "position", "room"], [Bool(True), Point(), String("kitchen")])
    ctx.dispatch(FunctionResult(*vision_outputs, basic_mod="speech", publisher="/bm_speech"))
    assert find.result is None and len(ctx.dropped) == 2                # never another module's call
    ctx.dispatch(FunctionResult(*vision_outputs, publisher="/some_other_node"))
    assert find.result is None and len(ctx.dropped) == 3                # a node of no module of this run
    ctx.dispatch(FunctionResult(*vision_outputs, basic_mod="vision", publisher="/vision"))
    assert find.result is not None                                      # its own module's call
    ctx.dispatch(FunctionResult(["success"], [Bool(True)], call_id="not-pending"))
    assert len(ctx.dropped) == 4                                        # a late answer matches nothing


class _Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.DEBUG)
        self.records = []

    def emit(self, record):
        self.records.append(record)


def test_late_result_of_timed_out_call_is_not_taken(tmp_path, sim_defs):
    ctx, root, mocks = _ctx_with_tree(tmp_path, sim_defs, """
root:
  sequence:
    - force_success: {call: navigation.go_to, inputs: {place: kitchen}, timeout: 1}
    - call: navigation.go_to
      inputs: {place: bedroom}
      outputs: {room: room}
""")
    first_id = []
    mocks["navigation.go_to"].script(hang(), succeed(delay=5.0, room="bedroom"))
    root_runner = TreeRunner(root, ctx)
    orig = ctx.transport.send_call

    def spy(call):
        first_id.append(call.call_id)
        orig(call)
        if len(first_id) == 2:  # the first call's late answer arrives while the second is pending
            ctx.inbox.put(FunctionResult(["success", "room", "position"], [Bool(True), String("kitchen"),
                                         Point()], call_id=first_id[0],
                                         basic_mod="navigation", function="go_to"))

    ctx.transport.send_call = spy
    caplog = _Records()
    logging.getLogger("bmtree").addHandler(caplog)
    try:
        result = root_runner.run()
        ctx.dispatch(FunctionResult(["success"], [Bool(True)], call_id="never-sent"))
    finally:
        logging.getLogger("bmtree").removeHandler(caplog)
    assert result.status == Status.SUCCESS
    assert result.blackboard["room"].data == "bedroom"
    # the cancelled answer and the late success of the first call both match nothing
    assert [r.call_id for r in ctx.dropped] == [first_id[0]] * 2 + ["never-sent"]
    assert [r.status for r in ctx.dropped] == ["cancelled", "succeeded", "succeeded"]
    # expected after a timeout, so no warning; an answer that matches no call of the run gets one
    assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == [
        "dropped a result that matches no pending call (call_id never-sent, module None, function None, outputs "
        "success, from node unknown)"]


def test_event_driven_chain_needs_no_tick_periods(tmp_path):
    calls = "\n".join("    - call: speech.say\n      inputs: {text: '%d'}" % i for i in range(10))
    t = TreeTest(tree(tmp_path, "root:\n  sequence:\n" + calls + "\n"))
    run = t.run()
    assert run.succeeded and len(run.calls()) == 10
    assert run.duration == 0.0 and run.result.ticks <= 11


def test_scripted_failures_and_rejections(tmp_path):
    t = TreeTest(tree(tmp_path, """
root:
  selector:
    - call: speech.say
      inputs: {text: a}
    - call: speech.say
      inputs: {text: b}
    - call: speech.say
      inputs: {text: c}
"""))
    from coordinator.testing import reject

    t.mocks["speech.say"].script(fail("hoarse"), reject("busy"), succeed())
    run = t.run()
    assert run.succeeded
    assert [(c.status, c.error) for c in run.calls()] == [("failed", "hoarse"), ("rejected", "busy"),
                                                          ("succeeded", "")]


def test_live_definition_mismatch_is_described(sim_defs):
    from coordinator.ros_transport import diff_definitions
    from modules.definition import parse_definition

    live = sim_defs["navigation"].to_dict()
    live["Functions"][0]["Input-params"][0]["Data-type"] = "geometry_msgs/Point"
    live["Functions"] = [f for f in live["Functions"] if f["Name"] != "approach"]
    diff = diff_definitions(sim_defs["navigation"], parse_definition(live))
    assert "go_to inputs differ: here place:std_msgs/String, running place:geometry_msgs/Point" in diff
    assert "function 'approach' is not served by the running module" in diff
    assert diff_definitions(sim_defs["navigation"], sim_defs["navigation"]) == []
    live = sim_defs["navigation"].to_dict()
    where = next(f for f in live["Functions"] if f["Name"] == "where_am_i")
    where["Concurrent"] = not sim_defs["navigation"].function("where_am_i").concurrent
    assert any("'where_am_i' is" in d and "concurrent in the running module" in d
               for d in diff_definitions(sim_defs["navigation"], parse_definition(live)))


def test_display_on_a_terminal_and_as_lines(tmp_path):
    import io

    from coordinator.runner import Display

    t = TreeTest(tree(tmp_path, "root:\n  sequence:\n    - call: speech.say\n      inputs: {text: hi}\n"
                                "    - check: 'false'\n      name: impossible\n"))
    clock = SimClock()
    ctx = RunContext(InProcessTransport(t.mocks, clock), clock, t.definitions)
    for tty in (True, False):
        out = io.StringIO()
        ctx = RunContext(InProcessTransport(t.mocks, clock), clock, t.definitions)
        TreeRunner(build_tree(t.tree, ctx), ctx, display=Display(out, tty=tty, min_interval=0.0)).run()
        text = out.getvalue()
        if tty:
            assert "\x1b[" in text and "speech.say" in text   # redrawn in place with py_trees' unicode tree
        else:
            assert "\x1b[" not in text
            assert "SUCCESS   speech.say" in text and "FAILURE   impossible (false is false)" in text


def test_control_set_takes_a_value_for_a_key_a_call_output_wrote(tmp_path):
    """A call's output is a ROS message: `set` converts the value as a call input would."""
    import types

    from std_msgs.msg import Float64

    from coordinator.control import Controller

    replies = []
    control = Controller(True, replies.append)
    ctx = types.SimpleNamespace(blackboard={"weight": Float64(1.5), "label": "apple"}, observers=[],
                                write=lambda k, v: ctx.blackboard.__setitem__(k, v))
    control.ctx, control.root = ctx, object()
    assert control._apply({"command": "set", "key": "weight", "value": "2"}) == (True, 'weight = {"data": 2}')
    assert ctx.blackboard["weight"] == Float64(2.0)
    assert control._apply({"command": "set", "key": "weight", "value": "{data: 2.5}"})[0]
    assert ctx.blackboard["weight"] == Float64(2.5)
    ok, answer = control._apply({"command": "set", "key": "weight", "value": "heavy"})
    assert (ok, answer) == (False, "weight takes a number (std_msgs/Float64), got 'heavy'")
    assert ctx.blackboard["weight"] == Float64(2.5)
    assert control._apply({"command": "set", "key": "label", "value": "5"}) == (False, "label holds str; 5 is int")


def test_a_time_given_as_now_is_the_time_of_each_call_on_the_run_clock(tmp_path):
    """``now`` in a literal input was converted once, when the tree loaded: every call got that
    time. In a tree test it is the simulated time, so the same on every run."""
    from modules.definition import parse_definition

    clock = parse_definition({"Basic Module": "stamper", "Brief Description": "", "Hardware Required": [],
                              "Functions": [{"Name": "mark", "Exec-condition": "", "Description": "",
                                             "Input-params": [{"Name": "at", "Data-type": "std_msgs/Time",
                                                               "Description": ""}],
                                             "Output-params": []}]})
    t = TreeTest(tree(tmp_path, """
root:
  sequence:
    - call: stamper.mark
      inputs: {at: now}
    - wait: 2.5
    - call: stamper.mark
      inputs: {at: now}
"""), definitions={"stamper": clock})
    run = t.run()
    assert run.succeeded, run.reason
    assert [c.inputs["at"] for c in run.calls("stamper.mark")] == [{"secs": 0, "nsecs": 0},
                                                                  {"secs": 2, "nsecs": 500000000}]
