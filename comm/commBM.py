"""Python 3 drop-in for the original ``commBM.py`` of the basic-module architecture.

Same names, signatures and return conventions as the original: writers return the
JSON text or ``''`` on bad input, readers return a tuple or ``[]`` on bad input.
The JSON parses to exactly the original keys and values (``writeFunCallFromRos``
indents by 2 as the original did). New code should use the typed API in
:mod:`comm.messages`; this module exists so that unmodified modules keep working.
"""
from __future__ import annotations

import json
from typing import Any, List, Tuple, Union

import genpy
from rospy_message_converter import json_message_converter

from comm.messages import DEFAULT_MAX_BYTES
from comm.rostypes import check_message, resolve_type

__all__ = [
    "getRosType",
    "writeVarRequest",
    "readVarRequest",
    "writeMsgFromRos",
    "writeMsgFromJson",
    "readMsg2Ros",
    "readMsg2Json",
    "writeFunCallFromRos",
    "writeFunCallFromJson",
    "readFunCall",
    "writeEventFromRos",
    "readEvent2Ros",
    "json_loads_byteified",
    "json_load_byteified",
]


def json_loads_byteified(json_text: str) -> Any:
    """``json.loads``; Python 3 strings are already text, so nothing to byteify."""
    return json.loads(json_text)


def json_load_byteified(file_handle: Any) -> Any:
    return json.load(file_handle)


def getRosType(msg: Any) -> str:
    """``pkg/Type`` of a ROS message instance, ``''`` if it is not one."""
    if isinstance(msg, genpy.Message):
        return msg._type
    return ""


def _all_str(items: Any) -> bool:
    return isinstance(items, list) and all(isinstance(i, str) for i in items)


def _to_json_list(values: List[Any]) -> Union[Tuple[List[str], List[str]], None]:
    types, texts = [], []
    for v in values:
        t = getRosType(v)
        if not t:
            return None
        types.append(t)
        texts.append(json_message_converter.convert_ros_message_to_json(v))
    return types, texts


def _from_json_list(rostypes: Any, texts: Any) -> Union[List[Any], None]:
    if not _all_str(rostypes) or not _all_str(texts) or len(rostypes) != len(texts):
        return None
    out = []
    for t, text in zip(rostypes, texts):
        if resolve_type(t) is None:
            return None
        try:
            msg = json_message_converter.convert_json_to_ros_message(t, text)
            check_message(msg, t)
        except Exception:
            return None
        out.append(msg)
    return out


def _load_obj(text: Any) -> Union[dict, None]:
    if not isinstance(text, str) or len(text) > DEFAULT_MAX_BYTES:
        return None
    try:
        obj = json.loads(text)
    except ValueError:
        return None
    return obj if isinstance(obj, dict) else None


def writeVarRequest(vars: List[str]) -> str:  # noqa: A002 - the original's name
    """Request for the latest values of the named variables (Blackboard node)."""
    if not _all_str(vars):
        return ""
    return json.dumps({"var_names": list(vars)})


def readVarRequest(req: str) -> List[str]:
    obj = _load_obj(req)
    if obj is None or not _all_str(obj.get("var_names")):
        return []
    return obj["var_names"]


def writeMsgFromRos(values: List[Any], names: List[str]) -> str:
    """A result (``names``, ``rostypes``, ``msgs``) from ROS message instances."""
    if not isinstance(values, list) or not _all_str(names) or len(values) != len(names):
        return ""
    conv = _to_json_list(values)
    if conv is None:
        return ""
    return json.dumps({"names": names, "rostypes": conv[0], "msgs": conv[1]})


def writeMsgFromJson(values: List[str], names: List[str], msgtypes: List[str]) -> str:
    """A result from values already encoded as JSON strings."""
    if not (_all_str(values) and _all_str(names) and _all_str(msgtypes)):
        return ""
    if not len(values) == len(names) == len(msgtypes):
        return ""
    return json.dumps({"names": names, "rostypes": msgtypes, "msgs": values})


def readMsg2Ros(msg: str) -> Union[Tuple[List[str], List[Any]], List[Any]]:
    """``(names, ros_msgs)`` of a result, ``[]`` if it is not one."""
    obj = _load_obj(msg)
    if obj is None or not _all_str(obj.get("names")):
        return []
    ros = _from_json_list(obj.get("rostypes"), obj.get("msgs"))
    if ros is None or len(ros) != len(obj["names"]):
        return []
    return obj["names"], ros


def readMsg2Json(msg: str) -> Union[Tuple[List[str], List[str], List[str]], List[Any]]:
    """``(names, msgs, rostypes)`` of a result with values left as JSON strings."""
    obj = _load_obj(msg)
    if obj is None:
        return []
    names, msgs, rostypes = obj.get("names"), obj.get("msgs"), obj.get("rostypes")
    if not (_all_str(names) and _all_str(msgs) and _all_str(rostypes)):
        return []
    return names, msgs, rostypes


def writeFunCallFromRos(basicmod: str, fun: str, msgs: List[Any]) -> str:
    """A call of ``basicmod.fun`` with ROS message instances as positional inputs."""
    if not isinstance(basicmod, str) or not isinstance(fun, str) or not isinstance(msgs, list):
        return ""
    conv = _to_json_list(msgs)
    if conv is None:
        return ""
    return json.dumps({"basic_mod": basicmod, "function": fun, "msgs": conv[1], "rostypes": conv[0]}, indent=2)


def writeFunCallFromJson(basicmod: str, fun: str, msgs: List[str], msgtypes: List[str]) -> str:
    if not isinstance(basicmod, str) or not isinstance(fun, str):
        return ""
    if not (_all_str(msgs) and _all_str(msgtypes)) or len(msgs) != len(msgtypes):
        return ""
    return json.dumps({"basic_mod": basicmod, "function": fun, "msgs": msgs, "rostypes": msgtypes})


def readFunCall(funcall: str) -> Union[Tuple[str, str, List[Any]], List[Any]]:
    """``(basic_mod, function, ros_msgs)`` of a call, ``[]`` if it is not one."""
    obj = _load_obj(funcall)
    if obj is None or not isinstance(obj.get("basic_mod"), str) or not isinstance(obj.get("function"), str):
        return []
    ros = _from_json_list(obj.get("rostypes"), obj.get("msgs"))
    if ros is None:
        return []
    return obj["basic_mod"], obj["function"], ros


def writeEventFromRos(mod: str, event: str, values: List[Any], names: List[str]) -> str:
    """An event of module ``mod`` with ROS message instances as its parameters."""
    if not isinstance(mod, str) or not isinstance(event, str):
        return ""
    if not isinstance(values, list) or not _all_str(names) or len(values) != len(names):
        return ""
    conv = _to_json_list(values)
    if conv is None:
        return ""
    return json.dumps({"basic_mod": mod, "event": event, "names": names, "rostypes": conv[0], "msgs": conv[1]})


def readEvent2Ros(text: str) -> Union[Tuple[str, str, List[str], List[Any]], List[Any]]:
    """``(module, event, names, ros_msgs)`` of an event, ``[]`` if it is not one."""
    obj = _load_obj(text)
    if obj is None or not isinstance(obj.get("basic_mod"), str) or not isinstance(obj.get("event"), str):
        return []
    names = obj.get("names")
    ros = _from_json_list(obj.get("rostypes"), obj.get("msgs"))
    if ros is None or not _all_str(names) or len(names) != len(ros):
        return []
    return obj["basic_mod"], obj["event"], names, ros
