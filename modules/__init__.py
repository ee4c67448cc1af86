"""Basic modules: definitions, the Python module runtime and node, discovery, the sim robot."""
from __future__ import annotations

from modules.definition import (
    DefinitionError,
    EventDefinition,
    FunctionDefinition,
    ModuleDefinition,
    Param,
    default_module_paths,
    load_definition,
    load_definitions,
    parse_definition,
)
from modules.runtime import BasicModule, BindingError, CallContext, Failure, ModuleServer, Rejected

__all__ = [
    "BasicModule",
    "BindingError",
    "CallContext",
    "DefinitionError",
    "EventDefinition",
    "Failure",
    "FunctionDefinition",
    "ModuleDefinition",
    "ModuleServer",
    "Param",
    "Rejected",
    "default_module_paths",
    "load_definition",
    "load_definitions",
    "parse_definition",
]
