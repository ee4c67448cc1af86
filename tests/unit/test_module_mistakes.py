"""What a module author's mistakes do to the running module: every call still gets a clear ``failed``
answer that decodes, the module is not left busy, and its threads (workers, the clock's) go on serving."""
from __future__ import annotations

import logging
import sys
import threading
import time

import pytest

from comm import CancelRequest, FunctionResult
from modules import node as module_node
from modules.basicmodule import Failure
from modules.definition import parse_definition
from modules.execution import TimerThread, WorkerThreads
from modules.outcome import Outcome, fail, succeed
from modules.runtime import BasicModule, BindingError, ModuleServer

DEFINITION = {
    "Basic Module": "probe",
    "Brief Description": "mistakes",
    "Hardware Required": [],
    "Functions": [
        {"Name": "f", "Exec-condition": "", "Description": "d",
         "Input-params": [{"Name": "mode", "Data-type": "std_msgs/String", "Description": "what to do"}],
         "Output-params": [{"Name": "x", "Data-type": "std_msgs/Float64", "Description": "x"},
                           {"Name": "s", "Data-type": "std_msgs/String", "Description": "s"}]},
        {"Name": "wait", "Exec-condition": "", "Description": "d", "Input-params": [], "Output-params": []},
    ],
}


class Unprintable(Exception):
    def __str__(self):
        raise SystemExit("not even this")


class NoFailure(Failure):
    def __str__(self):
        raise ValueError("no text")


class Mine(BaseException):
    pass


class BadValue:
    def __repr__(self):
        raise RuntimeError("no repr")

    def __eq__(self, other):
        raise RuntimeError("no eq")

    __hash__ = None


def _mode(mode):
    if mode == "exit":
        sys.exit(3)
    if mode == "interrupt":
        raise KeyboardInterrupt
    if mode == "generator":
        raise GeneratorExit
    if mode == "mine":
        raise Mine("base")
    if mode == "unprintable":
        raise Unprintable()
    if mode == "nofailure":
        raise NoFailure()
    if mode == "surrogate":
        raise RuntimeError("bad \udc80 name")
    if mode == "long":
        raise RuntimeError("\u00e9" * 1900)
    if mode == "none":
        return None
    if mode == "badvalue":
        return {"x": BadValue(), "s": "a"}
    if mode == "o_badvalue":
        return succeed(x=BadValue(), s="a")
    if mode == "o_reason":
        return fail(reason=3)
    if mode == "o_outputs":
        return Outcome("succeed", outputs=None)
    if mode in ("o_inf", "o_nan", "o_big"):
        return succeed(delay={"o_inf": float("inf"), "o_nan": float("nan"), "o_big": 1e300}[mode], x=1.0, s="a")
    return {"x": 1.0, "s": "ok"}


class Probe(BasicModule):
    def f(self, mode):
        return _mode(mode.data)

    def wait(self):
        self.context.sleep(30)  # stops when cancelled
        return {}


class NoSuperInit(Probe):
    def __init__(self):  # forgets super().__init__()
        self.ready = True


class Served:
    def __init__(self, impl=None, max_bytes=1 << 20):
        self.definition = parse_definition(DEFINITION, "probe.json")
        self.results = []
        self.cond = threading.Condition()
        self.server = ModuleServer(self.definition, impl or Probe(), self._res, lambda t: None,
                                   max_bytes=max_bytes, cancel_grace=0.2)

    def _res(self, text):
        with self.cond:
            self.results.append(FunctionResult.decode(text))  # an answer that does not decode fails here
            self.cond.notify_all()

    def call(self, function="f", **inputs):
        call = self.definition.function(function).build_call(inputs)
        self.server.handle_call(call.encode())
        return call.call_id

    def result(self, call_id, timeout=5.0):
        with self.cond:
            assert self.cond.wait_for(lambda: any(r.call_id == call_id for r in self.results), timeout), \
                "no answer to %s" % call_id
            return next(r for r in self.results if r.call_id == call_id)

    def answer(self, mode):
        return self.result(self.call(mode=mode))


@pytest.fixture
def module_log():
    lines = []

    class Keep(logging.Handler):
        def emit(self, record):
            lines.append(record.getMessage())

    handler = Keep()
    logger = logging.getLogger("bmtree.module")
    logger.addHandler(handler)
    yield lines
    logger.removeHandler(handler)


@pytest.mark.parametrize("mode, error", [
    ("exit", "SystemExit: 3 (test_module_mistakes.py:"),
    ("interrupt", "KeyboardInterrupt at test_module_mistakes.py:"),
    ("generator", "GeneratorExit at test_module_mistakes.py:"),
    ("mine", "Mine: base (test_module_mistakes.py:"),
    ("unprintable", "Unprintable: (its message cannot be shown) (test_module_mistakes.py:"),
])
def test_a_base_exception_or_an_unprintable_one_fails_the_call_and_frees_the_module(mode, error, module_log):
    s = Served()
    r = s.answer(mode)
    assert r.status == "failed" and r.error.startswith(error) and " in _mode" in r.error, r.error
    assert s.answer("ok").status == "succeeded"  # f is not concurrent: the module was freed
    assert any(line.startswith("probe.f raised (call %s)" % r.call_id) for line in module_log), module_log


def test_a_failure_whose_message_cannot_be_shown_still_fails_the_call():
    s = Served()
    r = s.answer("nofailure")
    assert r.status == "failed" and r.error == "(its message cannot be shown)"
    assert s.answer("ok").status == "succeeded"


def test_an_error_text_with_a_lone_surrogate_is_answered_in_valid_unicode():
    r = Served().answer("surrogate")
    assert r.status == "failed" and r.error.startswith("RuntimeError: bad \\udc80 name (test_module_mistakes.py:")


def test_a_long_error_is_cut_to_the_limit_keeping_where_it_came_from():
    s = Served(max_bytes=1024)
    r = s.answer("long")
    assert r.status == "failed" and r.error.startswith("RuntimeError: \u00e9") and "..." in r.error
    assert r.error.endswith(" in _mode)") and len(r.encode().encode("utf-8")) <= 1024


def test_none_for_a_function_with_outputs_says_so():
    r = Served().answer("none")
    assert r.error == "invalid outputs: returned None, expected a dict of outputs 'x', 's'"


@pytest.mark.parametrize("mode", ["badvalue", "o_badvalue"])
def test_an_output_value_that_raises_when_checked_is_an_invalid_output(mode):
    s = Served()
    r = s.answer(mode)
    assert r.status == "failed" and r.error.startswith(
        "invalid outputs: output 'x': checking its value raised RuntimeError: no repr (test_module_mistakes.py:"), r.error
    assert s.answer("ok").status == "succeeded"


@pytest.mark.parametrize("mode, error", [
    ("o_reason", "3"),
    ("o_outputs", "invalid outcome: its outputs are NoneType, expected a dict"),
    ("o_inf", "invalid outcome: its delay is inf, not a number of seconds up to 86400 (a day)"),
    ("o_nan", "invalid outcome: its delay is nan, not a number of seconds up to 86400 (a day)"),
    ("o_big", "invalid outcome: its delay is 1e+300, not a number of seconds up to 86400 (a day)"),
])
def test_a_malformed_outcome_fails_the_call_and_the_clock_goes_on(mode, error):
    s = Served()
    r = s.answer(mode)
    assert (r.status, r.error) == ("failed", error)
    call_id = s.call("wait")  # a cancel's grace runs on the module's clock
    time.sleep(0.05)
    s.server.cancel(call_id)
    assert s.result(call_id).status == "cancelled"
    assert s.answer("ok").status == "succeeded"


def test_a_class_that_does_not_call_the_base_init_serves_its_calls():
    assert Served(NoSuperInit()).answer("ok").status == "succeeded"


def test_emit_in_init_says_when_it_can_be_used():
    class Early(Probe):
        def __init__(self):
            super().__init__()
            self.emit("ready")

    with pytest.raises(RuntimeError) as info:
        Early()
    assert str(info.value) == ("emit('ready') of Early before its runtime is bound: use it in a function, in setup() "
                               "or later, not in __init__")


def test_a_cancel_callback_that_exits_does_not_lose_the_cancel():
    class Callback(Probe):
        def wait(self):
            self.context.on_cancel(lambda: sys.exit(1))
            self.context.cancelled.wait(30)
            return {}

    s = Served(Callback())
    call_id = s.call("wait")
    time.sleep(0.05)
    s.server.handle_cancel(CancelRequest(call_id, "probe", "wait").encode())
    assert s.result(call_id).status == "cancelled"


@pytest.mark.parametrize("concurrent, problem", [
    ({"wiat"}, "Typo.concurrent names 'wiat', which is not a function of module 'probe' (did you mean 'wait'?)"),
    ("wait", "Typo.concurrent must be True, False or a set of function names, got 'wait'"),
])
def test_a_concurrent_that_names_no_function_is_a_binding_error(concurrent, problem):
    typo = type("Typo", (Probe,), {"concurrent": concurrent})
    with pytest.raises(BindingError) as info:
        Served(typo())
    assert problem in str(info.value)


def test_an_async_or_generator_method_is_a_binding_error():
    class Async(Probe):
        async def f(self, mode):
            return {"x": 1.0, "s": "a"}

    class Yields(Probe):
        def wait(self):
            yield {}

    with pytest.raises(BindingError) as info:
        Served(Async())
    assert "method Async.f is an async def: the runtime calls it in a worker thread" in str(info.value)
    with pytest.raises(BindingError) as info:
        Served(Yields())
    assert "method Yields.wait is a generator (it has a yield)" in str(info.value)


def test_a_repeated_mistake_is_logged_once_then_at_most_every_few_seconds(module_log):
    from comm.saylimit import SayLimit

    s = Served()
    now = [0.0]
    s.server.log_limit = SayLimit(every=10.0, clock=lambda: now[0])
    for _ in range(4):
        assert s.answer("exit").status == "failed"
        assert s.answer("none").status == "failed"
    assert [line.split(" (call")[0] for line in module_log] == ["probe.f raised", "probe.f: invalid outputs"]
    now[0] = 11.0
    s.answer("exit")
    assert module_log[-1].endswith(") (and 3 more like it in the last 10s)"), module_log
    s.answer("mine")  # another mistake is said at once
    assert module_log[-1].startswith("probe.f raised"), module_log


def test_the_worker_and_timer_threads_survive_what_they_run():
    ran = threading.Event()
    workers = WorkerThreads("mistakes", idle_seconds=5)
    workers.submit(sys.exit, 1)
    workers.submit(ran.set)
    assert ran.wait(2)
    timer = TimerThread("mistakes-timer")
    ticked = threading.Event()
    timer.call_later(float("inf"), ticked.set)
    timer.call_later(0.0, lambda: sys.exit(1))
    timer.call_later(0.01, ticked.set)
    assert ticked.wait(2)


class InitExits(BasicModule):
    def __init__(self):
        super().__init__()
        sys.exit(5)


def test_a_class_whose_init_exits_is_one_line_exit_2(tmp_path, capsys):
    import json

    definition = tmp_path / "probe.json"
    definition.write_text(json.dumps(DEFINITION))
    code = module_node.main(["bmtree-module", "--definition", str(definition), "--class",
                             "%s:InitExits" % __file__])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and err.endswith("test_module_mistakes.py:%d: SystemExit: 5\n" % (
        InitExits.__init__.__code__.co_firstlineno + 2)), err


def test_a_shutdown_hook_that_raises_is_one_log_line(module_log):
    class Stops(Probe):
        def shutdown(self):
            raise SystemExit("driver gone")

    module_node._shut_down(Stops())
    assert module_log == ["Stops.shutdown raised SystemExit: driver gone (test_module_mistakes.py:%d in shutdown)" % (
        Stops.shutdown.__code__.co_firstlineno + 1)]


def test_a_stopped_node_leaves_without_a_thread_of_its_code_that_goes_on(monkeypatch, capsys):
    exits = []
    monkeypatch.setattr(module_node.os, "_exit", exits.append)
    stop = threading.Event()
    t = threading.Thread(target=stop.wait, args=(10,), name="emitter")
    t.start()
    # the threads of this test alone: others that the test process may run are no module's
    monkeypatch.setattr(module_node.threading, "enumerate", lambda: [threading.current_thread(), t])
    try:
        module_node._leave_without_threads(0, grace=0.1)
    finally:
        stop.set()
        t.join()
    assert exits == [0]
    assert "the module's thread 'emitter' still ran 0.1s after the node stopped" in capsys.readouterr().err
    module_node._leave_without_threads(0, grace=0.1)  # none left: returns
    assert exits == [0]
