"""What a module's failures say, to the tree and in the module's log: the place of an exception in
the author's code, outputs that break the definition, injected faults, code that ignores its cancel."""
from __future__ import annotations

import json
import logging
import threading
import time

import pytest

from comm import CancelRequest, FunctionResult
from modules.definition import parse_definition
from modules.runtime import ModuleServer

ARM = '''import json

from modules import BasicModule


class Arm(BasicModule):
    def pick(self, object):
        weights = {"apple": 0.2}
        if object.data == "empty":
            assert weights == {}
        if object.data == "json":
            return {"weight": json.loads("{not json")}
        if object.data == "huge":
            raise ValueError("x" * 100000)
        if object.data == "event":
            self.emit("dropped")
        if object.data == "heavy":
            return {"weight": "heavy"}
        if object.data == "list":
            return [1.0]
        return {"weight": weights[object.data]}

    def hang(self):
        self._release.wait(10)
        return {"success": True}
'''


class _Records(logging.Handler):
    """The module's log (pytest's own capture is off here: ``-p no:logging``)."""

    def __init__(self):
        super().__init__(logging.DEBUG)
        self.records = []

    def emit(self, record):
        self.records.append(record)

    def clear(self):
        self.records = []


@pytest.fixture
def caplog():
    logger = logging.getLogger("bmtree.module")
    handler, level = _Records(), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    yield handler
    logger.removeHandler(handler)
    logger.setLevel(level)


def _param(name, rostype):
    return {"Name": name, "Data-type": rostype, "Description": ""}


def arm_definition():
    return parse_definition(json.loads(json.dumps({
        "Basic Module": "arm", "Brief Description": "", "Hardware Required": [],
        "Functions": [
            {"Name": "pick", "Exec-condition": "", "Description": "",
             "Input-params": [_param("object", "std_msgs/String")],
             "Output-params": [_param("weight", "std_msgs/Float64")]},
            {"Name": "hang", "Exec-condition": "", "Description": "", "Input-params": [],
             "Output-params": [_param("success", "std_msgs/Bool")]}]})))


class Served:
    """An arm module served on worker threads; its answers by call id."""

    def __init__(self, impl, grace=0.2):
        self.results = {}
        self.cond = threading.Condition()
        self.server = ModuleServer(arm_definition(), impl, self._res, lambda t: None, cancel_grace=grace)

    def _res(self, text):
        r = FunctionResult.decode(text)
        with self.cond:
            self.results[r.call_id] = r
            self.cond.notify_all()

    def send(self, function, **inputs):
        call = self.server.definition.function(function).build_call(inputs)
        self.server.handle_call(call.encode())
        return call.call_id

    def wait(self, call_id, timeout=5.0):
        with self.cond:
            assert self.cond.wait_for(lambda: call_id in self.results, timeout), "no answer to %s" % call_id
            return self.results[call_id]

    def call(self, function, **inputs):
        return self.wait(self.send(function, **inputs))


@pytest.fixture
def arm(tmp_path):
    from modules.classfile import load_class

    (tmp_path / "arm.py").write_text(ARM)
    impl = load_class(str(tmp_path / "arm.py") + ":Arm")()
    impl._release = threading.Event()
    yield Served(impl)
    impl._release.set()


def line_of(text):
    return next(i for i, line in enumerate(ARM.splitlines(), 1) if text in line)


def test_an_exception_names_the_line_of_the_authors_code(arm, caplog):
    call_id = arm.send("pick", object="banana")
    r = arm.wait(call_id)
    assert (r.status, r.error) == ("failed", "KeyError: 'banana' (arm.py:%d in pick)" % line_of("weights[object"))
    raised = [rec for rec in caplog.records if "arm.pick raised" in rec.getMessage()]
    assert [rec.getMessage() for rec in raised] == ["arm.pick raised (call %s)" % call_id]
    assert raised[0].exc_info is not None  # the full traceback stays in the module's log


def test_an_exception_without_a_message_names_its_type_and_place(arm):
    r = arm.call("pick", object="empty")
    assert r.error == "AssertionError at arm.py:%d in pick" % line_of("assert weights")


def test_the_place_is_the_authors_line_not_the_library_or_the_runtime(arm):
    r = arm.call("pick", object="json")   # raised deep in the standard library's json
    assert r.error.startswith("JSONDecodeError: ") and r.error.endswith(
        "(arm.py:%d in pick)" % line_of("json.loads")), r.error
    r = arm.call("pick", object="event")  # raised in the runtime's emit, called by the author
    assert "module 'arm' has no event 'dropped'" in r.error and r.error.endswith(
        "(arm.py:%d in pick)" % line_of("self.emit")), r.error


def test_error_text_is_bounded_and_keeps_its_place(arm):
    r = arm.call("pick", object="huge")
    assert len(r.error) <= 2100 and r.error.startswith("ValueError: xxx")
    assert r.error.endswith("(arm.py:%d in pick)" % line_of("100000")), r.error[-100:]


def test_invalid_outputs_do_not_repeat_the_target_and_are_logged_with_the_call(arm, caplog):
    call_id = arm.send("pick", object="heavy")
    r = arm.wait(call_id)
    assert r.status == "failed" and r.error.startswith("invalid outputs: output 'weight'"), r.error
    assert "arm.pick" not in r.error  # the coordinator says "arm.pick failed: …" already
    warned = [rec for rec in caplog.records if rec.levelno == logging.WARNING and call_id in rec.getMessage()]
    assert len(warned) == 1 and warned[0].getMessage().startswith("arm.pick: invalid outputs (call %s): output "
                                                                  "'weight'" % call_id), warned
    call_id = arm.send("pick", object="list")
    assert arm.wait(call_id).error == "invalid outputs: returned list, expected a dict of outputs"
    assert any(call_id in rec.getMessage() and rec.levelno == logging.WARNING and rec.exc_info is None
               for rec in caplog.records)


# -- injected faults -----------------------------------------------------------------------------
def world_with(faults):
    from modules.sim import World

    return World.from_dict({"rooms": {"a": {"x": 0, "y": 0}, "b": {"x": 1, "y": 0}}, "start": "a", "speed": 100,
                            "faults": faults})


def test_a_worlds_faults_say_they_are_injected(sim_defs, caplog):
    from modules.sim import Navigation, Vision

    world = world_with({"navigation.go_to": {"fail": "wheel motor overheated", "times": 1},
                        "navigation.approach": {"reject": "map not loaded"},
                        "vision.find_object": {"crash": True}, "vision.find_person": {"crash": "lens cracked"}})
    nav = ServedSim(sim_defs["navigation"], Navigation(world))
    call_id = nav.send("go_to", place="b")
    assert nav.wait(call_id).error == "wheel motor overheated (injected fault)"
    assert any("call %s of navigation.go_to: an injected fault answers (fail 'wheel motor overheated')" % call_id
               in rec.getMessage() for rec in caplog.records)
    assert nav.call("go_to", place="b").status == "succeeded"  # times: 1
    r = nav.call("approach", target={"x": 1.0})
    assert (r.status, r.error) == ("rejected", "map not loaded (injected fault)")
    caplog.clear()
    vis = ServedSim(sim_defs["vision"], Vision(world))
    assert vis.call("find_object", object="apple").error == "RuntimeError: injected crash (injected fault)"
    assert vis.call("find_person", name="").error == "RuntimeError: lens cracked (injected fault)"
    # a crash is no bug of the module's: no traceback through the runtime and world.py
    assert not [rec for rec in caplog.records if rec.exc_info], [rec.getMessage() for rec in caplog.records]


def test_faults_of_a_users_own_module_say_they_are_injected_and_are_logged_at_start(arm):
    from modules.node import _faults, _injected

    faults = _faults(arm.server.definition, '{pick: {fail: "gripper jammed", times: 5}, hang: {crash: true}}')
    arm.server.faults = faults
    assert arm.call("pick", object="apple").error == "gripper jammed (injected fault)"
    assert arm.call("hang").error == "RuntimeError: injected crash (injected fault)"
    assert _injected("arm", arm.server.impl, _faults(arm.server.definition, '{pick: {fail: "gripper jammed", '
                                                     'times: 5}, hang: {crash: true, delay: 2}}')) == (
        "faults injected: arm.hang: crash after 2 s; arm.pick: fail 'gripper jammed' ×5")


def test_a_simulated_modules_node_logs_its_worlds_faults_at_start():
    from modules.definition import load_definition
    from modules.node import _faults, _injected
    from modules.sim import Navigation, definition_path

    nav = Navigation(world_with({"navigation.go_to": {"fail": "wheel motor overheated", "times": 5},
                                 "vision.find_object": {"hang": True}}))
    assert _injected("navigation", nav, {}) == "faults injected: navigation.go_to: fail 'wheel motor overheated' ×5"
    own = _faults(load_definition(definition_path("navigation")), "{approach: {delay: 1.5}}")
    assert _injected("navigation", nav, own) == ("faults injected: navigation.approach: delay 1.5 s; "
                                                 "navigation.go_to: fail 'wheel motor overheated' ×5")
    assert _injected("navigation", Navigation(world_with({})), {}) == ""
    # a death says why, as the world wrote it (it said only "die")
    dying = Navigation(world_with({"navigation.go_to": {"die": "camera USB disconnected", "times": 1}}))
    assert _injected("navigation", dying, {}) == "faults injected: navigation.go_to: die 'camera USB disconnected' ×1"


class ServedSim(Served):
    def __init__(self, definition, impl):
        self.results = {}
        self.cond = threading.Condition()
        self.server = ModuleServer(definition, impl, self._res, lambda t: None, cancel_grace=0.2)


# -- code that ignores its cancel ----------------------------------------------------------------
def test_code_still_running_after_the_cancel_grace_is_logged(arm, caplog):
    call_id = arm.send("hang")
    time.sleep(0.05)
    arm.server.handle_cancel(CancelRequest(call_id, "arm", "hang").encode())
    assert arm.wait(call_id).status == "cancelled"
    warned = [rec.getMessage() for rec in caplog.records if rec.levelno == logging.WARNING]
    assert "call %s of arm.hang was cancelled but its code has not returned after 0.2 s; arm stays busy until " \
           "it does" % call_id in warned, warned
    arm.server.impl._release.set()
    deadline = time.monotonic() + 5
    while not any("has returned; arm is free again" in rec.getMessage() for rec in caplog.records):
        assert time.monotonic() < deadline, [rec.getMessage() for rec in caplog.records]
        time.sleep(0.01)


def test_code_that_returns_within_the_grace_is_not_reported(arm, caplog):
    call_id = arm.send("hang")
    time.sleep(0.05)
    arm.server.handle_cancel(CancelRequest(call_id, "arm", "hang").encode())
    arm.server.impl._release.set()
    assert arm.wait(call_id).status == "cancelled"
    time.sleep(0.3)
    assert not [rec for rec in caplog.records if rec.levelno >= logging.WARNING]


def test_a_call_cancelled_already_is_not_reported_cancelled_when_its_caller_goes(arm, caplog):
    """The coordinator cancelled the call and exited (Ctrl-C): the module said "cancelled call …: its
    caller … is gone", as if it had cancelled it, and would run the grace a second time."""
    from comm.liveness import ModuleLost
    from modules.callers import CallerWatch

    node = CallerWatch(arm.server, "arm")
    call_id = arm.send("hang")
    time.sleep(0.05)
    arm.server.handle_cancel(CancelRequest(call_id, "arm", "hang").encode())
    node.orphaned(ModuleLost(module="/bmtree_run", node="/bmtree_run", reason="its process is gone",
                              call_ids=[call_id]))
    assert not [rec.getMessage() for rec in caplog.records if "its caller" in rec.getMessage()]
    assert arm.server.cancel(call_id) is False
    # a call nobody cancelled is cancelled and reported as before
    arm.server.impl._release.set()
    arm.wait(call_id)
    time.sleep(0.05)
    arm.server.impl._release.clear()
    other = arm.send("hang")
    time.sleep(0.05)
    node.orphaned(ModuleLost(module="/bmtree_run", node="/bmtree_run", reason="its process is gone",
                              call_ids=[other]))
    assert any("cancelled call %s of module arm: its caller /bmtree_run is gone" % other in rec.getMessage()
               for rec in caplog.records)
    arm.server.impl._release.set()
    assert arm.wait(other).status == "cancelled"


def test_where_an_init_raised_names_the_line_of_a_class_in_a_folder_below_bmtrees_modules(tmp_path, monkeypatch):
    """Frames of bmtree's own modules/ are skipped to find the author's line; those of modules/example/ (a
    shipped example a team copies and edits there) were skipped too, and the error named the class spec."""
    import importlib.util

    from modules import classfile

    (tmp_path / "modules" / "example").mkdir(parents=True)
    driver = tmp_path / "modules" / "example" / "drv.py"
    driver.write_text("def start():\n    raise RuntimeError('no driver')\n")
    spec = importlib.util.spec_from_file_location("bmtree_test_drv", str(driver))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setattr(classfile, "__file__", str(tmp_path / "modules" / "classfile.py"))
    with pytest.raises(RuntimeError) as info:
        module.start()
    assert classfile.where_raised(info.value, "drv.py:Drv") == "%s:2" % driver
