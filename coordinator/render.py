"""A tree drawn for people (``bmtree render``): py_trees' dot graph, labelled with what each node does.

py_trees names graph nodes after behaviours and makes repeated names unique by appending ``*``
(``speech.say``, ``speech.say*``, …), and it shows only the name: a named ``timeout`` hides its
seconds, a call its inputs. Here each node's label is its own name, then, on a second line, what
its kind and parameters are when a name hides them, and a leaf's main argument as written where its
name does not say it: a call's inputs, a ``set``'s values, a ``fail``'s text, a ``wait_event``'s
``where:`` (cut to :data:`MAX_DETAIL` characters).
"""
from __future__ import annotations

from typing import Any, Dict, List, Set

import py_trees
from py_trees import behaviour

from coordinator.refs import Ref

__all__ = ["tree_graph"]

MAX_DETAIL = 48  # characters of a label's second line


def tree_graph(name: str, root: behaviour.Behaviour, switches: Set[str]) -> Any:
    """The pydot graph of the built tree ``root`` (``switches``: names of ``switch`` nodes)."""
    graph = py_trees.display.dot_tree(root, collapse_decorators=False)
    graph.set_name(name)
    by_dot_name = _dot_names(root)
    for node in graph.get_nodes():
        dot_name = node.get_name().strip('"')
        b = by_dot_name.get(dot_name)
        label = node.get_label()
        if b is None or not isinstance(label, str):
            continue
        label = label.strip('"').replace("Ⓜ ", "")  # py_trees' memory mark: no font here has it (an empty box)
        if dot_name != b.name:
            label = label.replace(dot_name, b.name, 1)
        detail = _detail(b)
        if detail:
            label += "\n" + detail
        node.set_label(_quoted(label))
        if b.name in switches:  # py_trees draws a composite it does not know as a grey leaf
            node.set_shape("diamond")
            node.set_fillcolor("plum")
    return graph


def _dot_names(root: behaviour.Behaviour) -> Dict[str, behaviour.Behaviour]:
    """Graph node name → behaviour, made unique exactly as ``py_trees.display.dot_tree`` does."""
    names: Dict[str, behaviour.Behaviour] = {root.name: root}

    def add(parent: behaviour.Behaviour) -> None:
        for c in parent.children:
            dot_name = c.name
            while dot_name in names:
                dot_name += "*"
            names[dot_name] = c
            if c.children:
                add(c)

    add(root)
    return names


def _detail(b: behaviour.Behaviour) -> str:
    """What the name does not say: a named node's kind and parameters; a leaf's main argument."""
    node = getattr(b, "bmtree_node", None)
    if node is None:
        return ""
    parts: List[str] = []
    default = node.nodekind.default_name(node)
    if node.name != default:
        parts.append(default)
    main = _argument(node)
    if main:
        parts.append(main)
    text = " · ".join(parts)
    return text if len(text) <= MAX_DETAIL else text[:MAX_DETAIL - 1] + "…"


def _argument(node: Any) -> str:
    """A leaf's main argument as written, where its default name does not say it: a call's inputs, a
    ``set``'s values (its name says only the keys), a ``fail``'s text, a ``wait_event``'s ``where:``."""
    spec = node.spec
    if node.kind == "call":
        values = getattr(spec, "inputs", None)
    elif node.kind == "set":
        values = spec
    elif node.kind == "fail":
        return _shown(spec) if spec is not None else ""
    elif node.kind == "wait_event":
        where = getattr(spec, "where", None)
        return "where: %s" % getattr(where, "text", where) if where is not None else ""
    else:
        return ""
    return ", ".join("%s: %s" % (k, _shown(v)) for k, v in values.items()) if isinstance(values, dict) else ""


def _shown(value: Any) -> str:
    if isinstance(value, Ref):
        return str(value)
    if isinstance(value, str):
        return repr(value)
    return repr(value) if not isinstance(value, (dict, list)) else "{…}" if isinstance(value, dict) else "[…]"


def _quoted(label: str) -> str:
    """A dot string: quotes and backslashes escaped, line breaks as dot's ``\\n``."""
    return '"%s"' % label.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
