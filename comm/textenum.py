"""Enums whose members are their wire text: statuses and outcome kinds stay strings on the wire.

A member is a ``str``: it equals, hashes, prints, and serialises (JSON, YAML) as its text,
so ``result.status == "failed"`` holds and payloads, reports and scenario files are unchanged.
"""
from __future__ import annotations

from enum import Enum
from typing import Any

import yaml

__all__ = ["TextEnum"]


class TextEnum(str, Enum):
    def __str__(self) -> str:
        return str(self.value)

    def __repr__(self) -> str:
        return repr(self.value)


def _represent(dumper: Any, member: TextEnum) -> Any:
    return dumper.represent_str(str(member.value))


yaml.SafeDumper.add_multi_representer(TextEnum, _represent)
yaml.Dumper.add_multi_representer(TextEnum, _represent)
