"""bmtree-bridge without ROS: topic naming, output matching, binding, command-line errors."""
from __future__ import annotations

import json
import os

import pytest
from std_msgs.msg import Bool, Float64

from modules.bridge import CppBridge, _Call, data_topic, data_topics, main, make_bridge
from modules.definition import DefinitionError, load_definition
from modules.runtime import BindingError, Failure, ModuleServer, Rejected
from tests.conftest import REFERENCE, ROOT

GRIPPER = os.path.join(ROOT, "modules", "cpp", "example", "gripper.json")


def test_data_topics_follow_the_original_naming():
    assert data_topic("DEMO_BM", "std_msgs/String") == "/DEMO_BM/string"
    assert data_topic("gripper", "geometry_msgs/Point") == "/gripper/point"
    ins, outs = data_topics(load_definition(os.path.join(REFERENCE, "DEMO_BM.json")))
    assert ins == {"/DEMO_BM/string": "std_msgs/String", "/DEMO_BM/bool": "std_msgs/Bool"}
    assert outs == ins


def test_two_types_sharing_a_data_topic_are_a_definition_error():
    # no two message packages installed here share a type name: build the model directly
    from modules.definition import FunctionDefinition, ModuleDefinition, Param

    fns = {"f": FunctionDefinition(name="f", inputs=(Param("a", "std_msgs/Header"),), outputs=(), module="m"),
           "g": FunctionDefinition(name="g", inputs=(), outputs=(Param("b", "other_msgs/Header"),), module="m")}
    with pytest.raises(DefinitionError, match="types std_msgs/Header and other_msgs/Header would share the data "
                                              "topic /m/header"):
        data_topics(ModuleDefinition(name="m", functions=fns, source="m.json"))


def test_the_runtime_binds_one_method_per_function():
    d = load_definition(GRIPPER)
    bridge = make_bridge(d)
    ModuleServer(d, bridge, lambda t: None, lambda t: None)   # raises BindingError on a mismatch
    assert isinstance(bridge, CppBridge) and callable(bridge.set_fingers)


def _answered(fn, output, fresh):
    call = _Call(fn, sorted(fresh))
    call.fresh.update(fresh)
    call.output = output
    return call


def test_outputs_are_matched_by_occurrence_and_checked():
    d = load_definition(GRIPPER)
    bridge = make_bridge(d)
    ModuleServer(d, bridge, lambda t: None, lambda t: None)
    fn = d.function("set_fingers")
    call = _answered(fn, {"outparam_names": ["opening", "success"],
                          "outparam_topics": ["/gripper/float64", "/gripper/bool"]},
                     {"/gripper/float64": [Float64(0.05)], "/gripper/bool": [Bool(True)]})
    assert bridge._lacking(call) == []
    out = bridge._outputs(call)
    assert out["opening"].data == 0.05 and out["success"].data is True
    squeeze = d.function("squeeze")
    call = _answered(squeeze, {"outparam_names": ["closed_for", "label"],
                               "outparam_topics": ["/gripper/float64", "/gripper/float64"]},
                     {"/gripper/float64": [Float64(1.0)], "/gripper/string": []})
    assert bridge._lacking(call) == ["1 of 2 values arrived on /gripper/float64"]
    with pytest.raises(Failure, match="output 'label' came on /gripper/float64, its type's topic is /gripper/string"):
        bridge._outputs(call)
    with pytest.raises(Failure, match="missing output 'success'"):
        bridge._outputs(_answered(fn, {"outparam_names": ["opening"], "outparam_topics": ["/gripper/float64"]},
                                  {"/gripper/float64": [Float64(0.05)], "/gripper/bool": []}))
    with pytest.raises(Failure, match="malformed BM_output"):
        bridge._outputs(_answered(fn, {"outparam_names": "opening"}, {}))
    with pytest.raises(Rejected, match="out of reach"):
        bridge._outputs(_answered(fn, {"status": "rejected", "error": "out of reach"}, {}))
    with pytest.raises(Failure, match="not calibrated"):
        bridge._outputs(_answered(fn, {"status": "failed", "error": "not calibrated"}, {}))


def test_command_line_errors_exit_2_without_a_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"Basic Module": "m"}))
    assert main(["bmtree-bridge", "--definition", str(bad)]) == 2
    assert "Functions" in capsys.readouterr().err
    assert main(["bmtree-bridge", "--definition", GRIPPER, "--call-timeout", "-1"]) == 2
    assert "argument --call-timeout: expected a finite number of seconds of 0 or more (0: no limit), got '-1'" in \
        capsys.readouterr().err


def _gripper_info():
    """BM_info as the example C++ node publishes it (see basic_module_calls.h publishInfo)."""
    return {"library": "bmtree", "protocol": 2, "functions": ["ping", "reach", "set_fingers", "squeeze"],
            "signatures": {
                "ping": {"inparam_topics": [], "outparam_names": ["success"], "outparam_topics": ["/gripper/bool"]},
                "reach": {"inparam_topics": ["/gripper/point"], "outparam_names": ["final_pos", "distance"],
                          "outparam_topics": ["/gripper/point", "/gripper/float64"]},
                "set_fingers": {"inparam_topics": ["/gripper/float64", "/gripper/float64"],
                                "outparam_names": ["opening", "success"],
                                "outparam_topics": ["/gripper/float64", "/gripper/bool"]},
                "squeeze": {"inparam_topics": ["/gripper/float64", "/gripper/string"],
                            "outparam_names": ["closed_for", "label"],
                            "outparam_topics": ["/gripper/float64", "/gripper/string"]}}}


def _bridge_with_info(info, definition=GRIPPER):
    d = load_definition(definition) if isinstance(definition, str) else definition
    bridge = make_bridge(d)
    ModuleServer(d, bridge, lambda t: None, lambda t: None)
    bridge.library, bridge.cpp_node = True, "/gripper"
    if info is not None:
        bridge._infos["/gripper"] = info
    return bridge


def test_the_definition_is_checked_against_what_the_cpp_node_provides():
    bridge = _bridge_with_info(_gripper_info())
    bridge._check_signatures(wait=0)   # the example matches its definition
    assert all(bridge._signature_problem(fn, _gripper_info()) == "" for fn in bridge.definition.functions.values())

    info = _gripper_info()
    info["functions"].remove("ping")
    del info["signatures"]["ping"]
    info["signatures"]["set_fingers"]["inparam_topics"] = ["/gripper/float64"]
    info["signatures"]["reach"]["outparam_names"] = ["final_pos", "dist"]
    with pytest.raises(BindingError) as exc:
        _bridge_with_info(info)._check_signatures(wait=0)
    text = str(exc.value)
    assert text.startswith(GRIPPER + " does not match the C++ node: ")
    assert ("function 'ping' is not provided by the C++ node /gripper (it provides reach, set_fingers, squeeze): "
            "add provide(\"ping\", ...)") in text
    assert ("function 'set_fingers' takes its inputs on [\"/gripper/float64\"] in the C++ node /gripper, but the "
            "definition's Input-params (left: std_msgs/Float64, right: std_msgs/Float64) are sent on "
            "[\"/gripper/float64\", \"/gripper/float64\"]") in text
    assert ("function 'reach' returns dist on /gripper/float64, final_pos on /gripper/point in the C++ node "
            "/gripper, but the definition's Output-params are distance on /gripper/float64, final_pos on "
            "/gripper/point") in text
    assert "function 'squeeze'" not in text


def test_a_call_to_a_function_the_restarted_cpp_node_lost_is_rejected_with_the_reason():
    info = _gripper_info()
    info["functions"].remove("squeeze")
    bridge = _bridge_with_info(info)
    bridge._ready = True
    bridge._out_sub = type("Sub", (), {"impl": type("Impl", (), {"has_connection": lambda self, uri: True})()})()
    with pytest.raises(Rejected, match="function 'squeeze' is not provided by the C.. node /gripper"):
        bridge._execute("squeeze", {})


def test_a_node_of_an_older_library_is_only_checked_for_its_function_names():
    info = {"library": "bmtree", "protocol": 1, "functions": ["ping", "reach", "set_fingers", "squeeze"]}
    _bridge_with_info(info)._check_signatures(wait=0)
    info["functions"] = ["ping"]
    with pytest.raises(BindingError, match="function 'reach' is not provided"):
        _bridge_with_info(info)._check_signatures(wait=0)


def test_an_original_node_is_not_checked():
    bridge = _bridge_with_info(None)
    bridge.library = False
    bridge._check_signatures(wait=0)


def test_a_malformed_bm_info_is_a_difference_not_a_crash():
    info = _gripper_info()
    info["signatures"]["reach"]["outparam_names"] = [["final_pos"], {"x": 1}]
    info["signatures"]["ping"] = "nonsense"
    with pytest.raises(BindingError, match="function 'reach' returns nothing in the C.. node"):
        _bridge_with_info(info)._check_signatures(wait=0)


def test_an_answer_to_a_call_this_bridge_did_not_send_is_thrown_away_with_its_values():
    """The previous bridge was killed during a squeeze; the C++ node finishes it and answers while
    this bridge's first call runs: its BM_output and values must not become this call's."""
    from std_msgs.msg import String

    d = load_definition(GRIPPER)
    bridge = make_bridge(d)
    ModuleServer(d, bridge, lambda t: None, lambda t: None)
    bridge.cpp_node = "/gripper"
    call = _Call(d.function("squeeze"), ["/gripper/float64", "/gripper/string"])
    call.call_id = "mine"
    bridge._call = call

    def msg(cls, value):
        m = cls(value)
        m._connection_header = {"callerid": "/gripper"}
        return m

    def output(call_id, label):
        return msg(String, json.dumps({"outparam_names": ["closed_for", "label"], "call_id": call_id,
                                       "outparam_topics": ["/gripper/float64", "/gripper/string"]}))

    bridge._on_data(msg(Float64, 6.0), "/gripper/float64")   # the old call's values: one came before its answer,
    bridge._on_output(output("old", "long"))                  # the other comes after it (another connection)
    bridge._on_data(msg(String, "long"), "/gripper/string")
    assert call.output is None
    bridge._on_data(msg(Float64, 0.5), "/gripper/float64")    # this call's own
    bridge._on_data(msg(String, "short"), "/gripper/string")
    bridge._on_output(output("mine", "short"))
    out = bridge._outputs(call)
    assert out["closed_for"].data == 0.5 and out["label"].data == "short"
