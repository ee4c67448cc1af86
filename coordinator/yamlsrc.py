"""YAML with positions: safe loading that remembers where every key and value came from."""
from __future__ import annotations

from typing import Any, Dict, List

import yaml

from coordinator.errors import Pos, TreeError, TreeErrors

__all__ = ["LMap", "LList", "load_yaml", "pos_of"]

_STR = "tag:yaml.org,2002:str"


class LMap(dict):
    """A mapping that knows the position of itself, of each key and of each value."""

    pos: Pos
    key_pos: Dict[Any, Pos]
    val_pos: Dict[Any, Pos]


class LList(list):
    pos: Pos
    item_pos: List[Pos]


def _pos(file: str, node: yaml.Node) -> Pos:
    """Where a node starts; for a quoted scalar, where its text starts (inside the quote)."""
    quoted = isinstance(node, yaml.ScalarNode) and node.style in ("'", '"')
    return Pos(file, node.start_mark.line + 1, node.start_mark.column + 1 + (1 if quoted else 0))


# libyaml's parser when PyYAML was built with it (Debian's is): same nodes and marks, ~10x faster.
_Builder = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


MAX_NODES = 200000


class _Budget:
    """Counts converted nodes: aliases can make a small file expand without bound."""

    def __init__(self, file: str):
        self.left = MAX_NODES
        self.file = file

    def spend(self, node: yaml.Node) -> None:
        self.left -= 1
        if self.left < 0:
            raise TreeErrors([TreeError(_pos(self.file, node), "the document expands to more than %d YAML nodes "
                                                                "(recursive or repeated aliases?)" % MAX_NODES)])


def _convert(node: yaml.Node, file: str, ctor: yaml.constructor.SafeConstructor, budget: _Budget) -> Any:
    budget.spend(node)
    if isinstance(node, yaml.MappingNode):
        out = LMap()
        out.pos, out.key_pos, out.val_pos = _pos(file, node), {}, {}
        ctor.flatten_mapping(node)
        for k_node, v_node in node.value:
            key = _convert(k_node, file, ctor, budget)
            if isinstance(key, (dict, list)):
                raise TreeErrors([TreeError(_pos(file, k_node), "a mapping key must be a scalar")])
            if key in out:
                raise TreeErrors([TreeError(_pos(file, k_node), "duplicate key %r" % (key,))])
            out[key] = _convert(v_node, file, ctor, budget)
            out.key_pos[key] = _pos(file, k_node)
            out.val_pos[key] = _pos(file, v_node)
        return out
    if isinstance(node, yaml.SequenceNode):
        lst = LList(_convert(n, file, ctor, budget) for n in node.value)
        lst.pos = _pos(file, node)
        lst.item_pos = [_pos(file, n) for n in node.value]
        return lst
    if node.tag == _STR:  # the common case, without the constructor's machinery
        return node.value
    return ctor.construct_object(node, deep=True)


def load_yaml(text: str, file: str) -> Any:
    """Parse one YAML document (safe loader only); syntax errors become TreeErrors."""
    loader = _Builder(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        return _convert(node, file, loader, _Budget(file))
    except RecursionError:
        raise TreeErrors([TreeError(Pos(file, 1, 1), "the document is nested too deeply")])
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line, col = (mark.line + 1, mark.column + 1) if mark else (1, 1)
        raise TreeErrors([TreeError(Pos(file, line, col), "YAML syntax error: %s" % (exc.problem or exc))])
    except yaml.YAMLError as exc:
        raise TreeErrors([TreeError(Pos(file, 1, 1), "YAML error: %s" % exc)])
    finally:
        loader.dispose()


def pos_of(container: Any, key: Any = None, default: Any = None) -> Pos:
    """Position of a value inside a container (or of the container), falling back to ``default``."""
    if key is not None:
        if isinstance(container, LMap) and key in container.val_pos:
            return container.val_pos[key]
        if isinstance(container, LList) and isinstance(key, int) and key < len(container.item_pos):
            return container.item_pos[key]
    p = getattr(container, "pos", None)
    return p if p is not None else default
