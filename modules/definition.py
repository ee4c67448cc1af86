"""Module definitions: the seed's JSON format, validated, as an in-memory model.

Every other part (module runtime, mocks, tree validation, discovery) works from
these objects, so a module is described once, as data.
"""
from __future__ import annotations

import errno
import json
import os
import re
from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import jsonschema

from comm.errors import InvalidInput, ProtocolError, did_you_mean
from comm.limits import check_depth
from comm.messages import FunctionCall, FunctionResult, new_id
from comm.rostypes import resolve_type, rostype_of, to_message, type_hint
from comm.typewords import said_of

__all__ = [
    "DefinitionError",
    "EventDefinition",
    "FunctionDefinition",
    "ModuleDefinition",
    "Param",
    "SCHEMA",
    "default_module_paths",
    "load_definition",
    "load_definitions",
    "parse_definition",
]

_SCHEMA_PATH = os.path.join(os.path.dirname(__file__), "schema", "module.schema.json")
with open(_SCHEMA_PATH, encoding="utf-8") as _fh:
    SCHEMA: Dict[str, Any] = json.load(_fh)
_VALIDATOR = jsonschema.Draft7Validator(SCHEMA)
_NAME = re.compile(SCHEMA["properties"]["Basic Module"]["pattern"])
_KEYS = {k: (set(v["required"]), set(v["properties"])) for k, v in SCHEMA["definitions"].items()}
_KEYS["module"] = (set(SCHEMA["required"]), set(SCHEMA["properties"]))


def _surely_valid(data: Any) -> bool:
    """True only for data the schema accepts, checked about 100x faster than jsonschema does
    (announcements of 50 modules are parsed before a run's first tick); anything else is
    left to jsonschema, which also words the errors."""
    def obj(d: Any, kind: str) -> bool:
        required, allowed = _KEYS[kind]
        return isinstance(d, dict) and required <= d.keys() and d.keys() <= allowed and all(
            isinstance(d[k], str) for k in ("Name", "Description", "Data-type", "Exec-condition", "Basic Module",
                                            "Brief Description") if k in d) and (
            "Name" not in d or _NAME.search(d["Name"]) is not None)

    def items(d: Dict[str, Any], key: str, kind: str) -> bool:
        return key not in d or (isinstance(d[key], list) and all(obj(x, kind) for x in d[key]))

    return (obj(data, "module") and _NAME.search(data["Basic Module"]) is not None
            and isinstance(data["Hardware Required"], list) and all(isinstance(h, str) for h in data["Hardware Required"])
            and items(data, "Functions", "function") and items(data, "Events", "event")
            and all(items(f, "Input-params", "param") and items(f, "Output-params", "param")
                    and isinstance(f.get("Concurrent", False), bool) for f in data["Functions"])
            and all(items(e, "Event-params", "param") for e in data.get("Events", ())))


class DefinitionError(InvalidInput):
    """One or more problems with definition files; ``problems`` holds one line each."""

    def __init__(self, problems: Sequence[str]):
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


@dataclass(frozen=True)
class Param:
    name: str
    rostype: str
    description: str = ""

    @property
    def msg_class(self) -> type:
        cls = resolve_type(self.rostype)
        assert cls is not None, self.rostype
        return cls

    def convert(self, value: Any) -> Any:
        """A type-checked ROS message from a YAML-friendly value (scalar allowed)."""
        return to_message(self.rostype, value, allow_scalar=True)

    def to_dict(self) -> Dict[str, str]:
        return {"Name": self.name, "Data-type": self.rostype, "Description": self.description}


def _params_dict(params: Sequence[Param]) -> List[Dict[str, str]]:
    return [p.to_dict() for p in params]


def _convert_values(kind: str, params: Sequence[Param], values: Mapping[str, Any], where: str) -> List[Any]:
    """Messages in definition order; every missing, unknown or ill-typed value is an error."""
    by_name = {p.name: p for p in params}
    unknown = [k for k in values if k not in by_name]
    problems = []
    for k in unknown:
        problems.append("unknown %s %r%s" % (kind, k, did_you_mean(k, by_name)))
    missing = [p.name for p in params if p.name not in values]
    if missing:
        problems.append("missing %s %s" % (kind, ", ".join(repr(m) for m in missing)))
    msgs = []
    for p in params:
        if p.name in values:
            try:
                msgs.append(p.convert(values[p.name]))
            except ProtocolError as exc:
                problems.append(said_of("%s %r" % (kind, p.name), exc))
    if problems:
        raise ProtocolError("%s: %s" % (where, "; ".join(problems)))
    return msgs


@dataclass(frozen=True)
class FunctionDefinition:
    name: str
    inputs: Tuple[Param, ...] = ()
    outputs: Tuple[Param, ...] = ()
    description: str = ""
    exec_condition: str = ""
    concurrent: bool = False
    module: str = ""

    @property
    def qualified(self) -> str:
        return "%s.%s" % (self.module, self.name)

    def input(self, name: str) -> Optional[Param]:
        return next((p for p in self.inputs if p.name == name), None)

    def output(self, name: str) -> Optional[Param]:
        return next((p for p in self.outputs if p.name == name), None)

    def convert_inputs(self, values: Mapping[str, Any]) -> List[Any]:
        return _convert_values("input", self.inputs, values, self.qualified)

    def build_call(self, values: Mapping[str, Any], call_id: Optional[str] = None) -> FunctionCall:
        """A FunctionCall with inputs checked against the definition (names in order)."""
        return FunctionCall(basic_mod=self.module, function=self.name, msgs=self.convert_inputs(values),
                            names=[p.name for p in self.inputs], call_id=call_id or new_id())

    def inputs_of(self, call: FunctionCall) -> Dict[str, Any]:
        """Inputs of a received call by name, checked; legacy calls are positional."""
        names = call.names if call.names is not None else [p.name for p in self.inputs][: len(call.msgs)]
        if len(names) != len(call.msgs):
            raise ProtocolError("%s: %d names for %d values" % (self.qualified, len(names), len(call.msgs)))
        values = dict(zip(names, call.msgs))
        self._check_types("input", self.inputs, values)
        return values

    def build_result(self, outputs: Mapping[str, Any], call_id: Optional[str] = None) -> FunctionResult:
        """A succeeded FunctionResult; raises ProtocolError if outputs break the definition."""
        msgs = _convert_values("output", self.outputs, outputs, self.qualified)
        return FunctionResult(names=[p.name for p in self.outputs], msgs=msgs, call_id=call_id,
                              basic_mod=self.module, function=self.name)

    def check_result(self, result: FunctionResult) -> None:
        """Raise ProtocolError if a succeeded result's outputs do not match the definition."""
        if result.status != "succeeded":
            return
        self._check_types("output", self.outputs, result.values)

    def _check_types(self, kind: str, params: Sequence[Param], values: Mapping[str, Any]) -> None:
        problems = []
        by_name = {p.name: p for p in params}
        for name, msg in values.items():
            p = by_name.get(name)
            if p is None:
                problems.append("unknown %s %r%s" % (kind, name, did_you_mean(name, by_name)))
            elif rostype_of(msg) != p.rostype:
                problems.append("%s %r is %s, the definition says %s" % (kind, name, rostype_of(msg), p.rostype))
        missing = [p.name for p in params if p.name not in values]
        if missing:
            problems.append("missing %s %s" % (kind, ", ".join(repr(m) for m in missing)))
        if problems:
            raise ProtocolError("%s: %s" % (self.qualified, "; ".join(problems)))

    def to_dict(self) -> Dict[str, Any]:
        d: Dict[str, Any] = {"Name": self.name, "Exec-condition": self.exec_condition,
                             "Description": self.description, "Input-params": _params_dict(self.inputs),
                             "Output-params": _params_dict(self.outputs)}
        if self.concurrent:
            d["Concurrent"] = True
        return d


@dataclass(frozen=True)
class EventDefinition:
    name: str
    params: Tuple[Param, ...] = ()
    description: str = ""
    module: str = ""

    def build_values(self, values: Mapping[str, Any]) -> List[Any]:
        return _convert_values("event param", self.params, values, "%s event %s" % (self.module, self.name))

    def to_dict(self) -> Dict[str, Any]:
        return {"Name": self.name, "Description": self.description, "Event-params": _params_dict(self.params)}


@dataclass
class ModuleDefinition:
    name: str
    functions: Dict[str, FunctionDefinition] = field(default_factory=dict)
    events: Dict[str, EventDefinition] = field(default_factory=dict)
    brief: str = ""
    hardware: List[str] = field(default_factory=list)
    source: str = ""

    def function(self, name: str) -> FunctionDefinition:
        """The named function; ProtocolError with a 'did you mean' if there is none."""
        fn = self.functions.get(name)
        if fn is None:
            raise ProtocolError("module %r has no function %r%s" % (
                self.name, name, did_you_mean(name, self.functions)))
        return fn

    def no_function(self, name: Any) -> str:
        """``module 'arm' has no function 'pik' (did you mean 'pick'?)``, or what it has instead: its
        functions, or for a module of events only (a topic turned into events) those events, which a
        ``wait_event`` waits for."""
        hint = did_you_mean(name, self.functions) if isinstance(name, str) else ""
        if not hint and self.functions:
            hint = " (functions: %s)" % ", ".join(self.functions)
        elif not hint:
            hint = " (it has no functions%s)" % (
                "; its events: %s: wait for one with wait_event: %s.%s" % (
                    ", ".join(self.events), self.name, next(iter(self.events))) if self.events else "")
        return "module %r has no function %r%s" % (self.name, name, hint)

    def renamed(self, name: str) -> ModuleDefinition:
        """The same definition under another module name (a ROS parameter may rename a module)."""
        return parse_definition(dict(self.to_dict(), **{"Basic Module": name}), self.source)

    def to_dict(self) -> Dict[str, Any]:
        d: Dict[str, Any] = {"Basic Module": self.name, "Brief Description": self.brief,
                             "Hardware Required": list(self.hardware),
                             "Functions": [f.to_dict() for f in self.functions.values()]}
        if self.events:
            d["Events"] = [e.to_dict() for e in self.events.values()]
        return d


def _json_path(parts: Iterable[Any]) -> str:
    out = ""
    for p in parts:
        out += "[%d]" % p if isinstance(p, int) else ("." if out else "") + str(p)
    return out or "(top level)"


def _schema_message(err: jsonschema.ValidationError) -> str:
    if err.validator == "additionalProperties":
        allowed = list(err.schema.get("properties", {}))
        extra = [k for k in err.instance if k not in allowed]
        msgs = []
        for k in extra:
            msgs.append("unknown key %r%s" % (k, did_you_mean(k, allowed)))
        return "; ".join(msgs)
    if err.validator == "required":
        return err.message.replace("is a required property", "is missing")
    if err.validator == "type":
        return "must be of type %s, got %s" % (err.validator_value, type(err.instance).__name__)
    if err.validator == "pattern":
        return "%r is not a valid name (letters, digits and '_', not starting with a digit)" % (err.instance,)
    return err.message


def _params(raw: List[Dict[str, Any]]) -> Tuple[Param, ...]:
    return tuple(Param(p["Name"], p["Data-type"], p.get("Description", "")) for p in raw)


def parse_definition(data: Any, source: str = "<definition>") -> ModuleDefinition:
    """Validate a definition's JSON data and build the model; DefinitionError lists every problem."""
    problems = []
    errors = [] if _surely_valid(data) else _VALIDATOR.iter_errors(data)
    for err in sorted(errors, key=lambda e: list(map(str, e.absolute_path))):
        problems.append("%s: %s: %s" % (source, _json_path(err.absolute_path), _schema_message(err)))
    if problems:
        raise DefinitionError(problems)
    name = data["Basic Module"]

    def check_params(plist: List[Dict[str, Any]], path: str) -> None:
        seen = set()
        for j, p in enumerate(plist):
            where = "%s[%d]" % (path, j)
            if p["Name"] in seen:
                problems.append("%s: %s.Name: duplicate parameter name %r" % (source, where, p["Name"]))
            seen.add(p["Name"])
            if resolve_type(p["Data-type"]) is None:
                problems.append("%s: %s.Data-type: %r is not a ROS message type%s" % (
                    source, where, p["Data-type"], type_hint(p["Data-type"])))

    functions: Dict[str, FunctionDefinition] = {}
    for i, f in enumerate(data["Functions"]):
        if f["Name"] in functions:
            problems.append("%s: Functions[%d].Name: duplicate function name %r" % (source, i, f["Name"]))
        check_params(f["Input-params"], "Functions[%d].Input-params" % i)
        check_params(f["Output-params"], "Functions[%d].Output-params" % i)
        functions[f["Name"]] = FunctionDefinition(
            name=f["Name"], inputs=_params(f["Input-params"]), outputs=_params(f["Output-params"]),
            description=f["Description"], exec_condition=f["Exec-condition"],
            concurrent=bool(f.get("Concurrent", False)), module=name)
    events: Dict[str, EventDefinition] = {}
    for i, e in enumerate(data.get("Events", [])):
        if e["Name"] in events:
            problems.append("%s: Events[%d].Name: duplicate event name %r" % (source, i, e["Name"]))
        check_params(e["Event-params"], "Events[%d].Event-params" % i)
        events[e["Name"]] = EventDefinition(e["Name"], _params(e["Event-params"]), e["Description"], name)
    if problems:
        raise DefinitionError(problems)
    return ModuleDefinition(name=name, functions=functions, events=events, brief=data["Brief Description"],
                            hardware=list(data["Hardware Required"]), source=source)


_MAX_FILE = 4 << 20


def _no_duplicate_keys(pairs: List[Tuple[str, Any]]) -> Dict[str, Any]:
    """A JSON object; a key written twice is an error (JSON would silently keep the last)."""
    out: Dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError("key %r appears twice in one object" % key)
        out[key] = value
    return out


def load_definition(path: str) -> ModuleDefinition:
    """Load and validate one definition file."""
    from comm.textfile import read_text  # bounded; a device refused, a FIFO not waited on at open

    try:
        text = read_text(path, _MAX_FILE)
    except OSError as exc:
        raise DefinitionError(["%s: cannot read: %s%s" % (path, exc.strerror or exc, ": not a module definition"
                                                           if exc.errno == errno.EFBIG else "")])
    except UnicodeDecodeError as exc:
        raise DefinitionError(["%s: cannot read: not UTF-8 text (byte %d)" % (path, exc.start)])
    try:
        check_depth(text)
        data = json.loads(text, object_pairs_hook=_no_duplicate_keys)
    except json.JSONDecodeError as exc:
        raise DefinitionError(["%s:%d:%d: invalid JSON: %s" % (path, exc.lineno, exc.colno, exc.msg)])
    except (ProtocolError, ValueError, RecursionError) as exc:
        raise DefinitionError(["%s: invalid JSON: %s" % (path, exc)])
    return parse_definition(data, path)


def _expand(paths: Iterable[str]) -> List[str]:
    """The definition files of ``paths`` (folders: their ``.json`` files), each once (a folder and a
    file in it, or one file given twice, is not a duplicate module)."""
    files: Dict[str, str] = {}
    for p in paths:
        found = sorted(os.path.join(p, f) for f in os.listdir(p) if f.endswith(".json")) if os.path.isdir(p) else [p]
        for f in found:
            files.setdefault(os.path.realpath(f), f)
    return list(files.values())


def load_definitions(paths: Iterable[str]) -> Dict[str, ModuleDefinition]:
    """Load every definition in the given files and directories; all problems at once."""
    problems: List[str] = []
    found: Dict[str, ModuleDefinition] = {}
    for path in _expand(paths):
        try:
            d = load_definition(path)
        except DefinitionError as exc:
            problems.extend(exc.problems)
            continue
        if d.name in found:
            problems.append("%s: Basic Module: duplicate module name %r (also defined in %s)" % (
                path, d.name, found[d.name].source))
            continue
        found[d.name] = d
    if problems:
        raise DefinitionError(problems)
    return found


def default_module_paths() -> List[str]:
    """The simulated robot's definitions, then ``$BMTREE_MODULE_PATH`` (os.pathsep-separated)."""
    paths = [os.path.join(os.path.dirname(__file__), "sim")]
    extra = os.environ.get("BMTREE_MODULE_PATH", "")
    paths.extend(p for p in extra.split(os.pathsep) if p)
    return paths
