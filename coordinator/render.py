"""A tree drawn for people (``bmtree render``): a dot graph in py_trees' style (its shapes and colours
of sequences, selectors, parallels, decorators and leaves), labelled with what each node does.

Each node's label is its own name, then, on a second line, what its kind and parameters are when a
name hides them, and a leaf's main argument as written where its name does not say it: a call's
inputs, a ``set``'s values, a ``fail``'s text, a ``wait_event``'s ``where:`` (cut to
:data:`MAX_DETAIL` characters). A graph node's id is its name, made unique by ``*2``, ``*3``, … (the
second ``speech.say`` is ``speech.say*2``; the id is what an svg shows as a node's tooltip). Every
id and label is quoted with its quotes and backslashes escaped (a name may hold any text), and the
graph is built in one pass over the tree: py_trees' ``dot_tree`` compared each name with all the
names given before it and appended a ``*`` per repeat (a sequence of 5,000 ``wait: 1`` took minutes
and wrote 25 MB).
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Set, Tuple

import py_trees
import pydot
from py_trees import behaviour, composites, decorators

from coordinator.refs import Ref

__all__ = ["tree_graph"]

MAX_DETAIL = 48  # characters of a label's second line
_FONT = "times-roman"


def tree_graph(name: str, root: behaviour.Behaviour, switches: Set[str]) -> Any:
    """The pydot graph of the built tree ``root`` (``switches``: names of ``switch`` nodes)."""
    graph = pydot.Dot(graph_name=_quoted(name), graph_type="digraph", ordering="out")
    graph.set_graph_defaults(fontname=_FONT)
    graph.set_node_defaults(fontname=_FONT)
    graph.set_edge_defaults(fontname=_FONT)
    ids = _Ids()
    todo: List[Tuple[behaviour.Behaviour, Optional[str]]] = [(root, None)]
    while todo:  # depth first, children in order: each node, then the edge to it, as py_trees wrote them
        b, parent = todo.pop()
        node_id = ids.new(b.name)
        shape, colour = ("diamond", "plum") if b.name in switches else _look(b)  # a switch: not a grey leaf
        graph.add_node(pydot.Node(_quoted(node_id), label=_quoted(_label(b)), shape=shape, style="filled",
                                  fillcolor=colour, fontsize=9, fontcolor="black"))
        if parent is not None:
            graph.add_edge(pydot.Edge(_quoted(parent), _quoted(node_id)))
        todo.extend((c, node_id) for c in reversed(b.children))
    return graph


class _Ids:
    """Unique graph node ids: a name, then ``name*2``, ``name*3``, … for its repeats (the number a
    name tries next is remembered: no search over the ids given)."""

    def __init__(self) -> None:
        self.used: Set[str] = set()
        self.next: Dict[str, int] = {}

    def new(self, name: str) -> str:
        n = self.next.get(name, 1)
        node_id = name if n == 1 else "%s*%d" % (name, n)
        while node_id in self.used:   # a node named 'x*2' itself
            n += 1
            node_id = "%s*%d" % (name, n)
        self.next[name] = n + 1
        self.used.add(node_id)
        return node_id


def _look(b: behaviour.Behaviour) -> Tuple[str, str]:
    """py_trees' shape and fill colour of a behaviour."""
    if isinstance(b, composites.Selector):
        return "octagon", "cyan"
    if isinstance(b, composites.Sequence):
        return "box", "orange"
    if isinstance(b, composites.Parallel):
        return "parallelogram", "gold"
    if isinstance(b, decorators.Decorator):
        return "ellipse", "ghostwhite"
    return "ellipse", "gray"


def _label(b: behaviour.Behaviour) -> str:
    """The name (a synchronised parallel's mark before it), a parallel's policy, then :func:`_detail`
    (py_trees' memory mark is left out: no font here has it, it showed as an empty box)."""
    label = b.name
    policy = getattr(b, "policy", None)
    if isinstance(b, composites.Parallel) and policy is not None:
        if getattr(policy, "synchronise", False):
            symbols = py_trees.display.unicode_symbols if py_trees.console.has_unicode() else \
                py_trees.display.ascii_symbols
            label = "%s %s" % (symbols["synchronised"], label)
        said = type(policy).__name__
        selected = getattr(policy, "children", None)
        if selected is not None:
            index = {id(c): i for i, c in enumerate(b.children)}
            said += "(%s)" % ", ".join(sorted(str(index[id(c)]) for c in selected if id(c) in index))
        label += "\n" + said
    detail = _detail(b)
    return label + "\n" + detail if detail else label


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
