"""``bmtree import TREE.xml``: a BehaviorTree.CPP tree (XML, format 3 or 4, as Groot writes it) as a bmtree
YAML tree, so that a team switching does not rewrite each tree by hand.

The result is checked by the real loader (``load_tree``, what ``bmtree check`` runs) before anything is
written: a problem is said at the XML's line (each YAML line remembers its element), exit 2, and no file
is written, so no tree with a placeholder or a silent change ever lands.

SubTrees are inlined, not written as ``include:`` files: BehaviorTree.CPP gives a subtree its own
blackboard and remaps its ports to the caller's keys (or to literals), which renaming keys inside the
inlined copy says exactly, literals included, while bmtree's ``include`` shares one blackboard; and one
file keeps ``-o``/stdout simple and the result whole (nothing half written). A subtree's keys that it
does not remap are its own there, so they get its ID as a prefix here (``search_room_pos``), unless
``_autoremap`` shares the caller's.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
from typing import Any, Dict, List, Mapping, Optional, Tuple

from comm.textfile import read_text
from coordinator.btimportformat import format_of
from coordinator.btimportnodes import Converter, Out
from coordinator.btimportports import Scope
from coordinator.btimportreactive import POLL_DEFAULT, model_kinds
from coordinator.btxml import Element, XmlErrors, byte_pos, parse_xml
from coordinator.errors import Pos, TreeError, TreeErrors, UsageError
from modules.definition import ModuleDefinition

__all__ = ["add_import_parser", "cmd_import", "import_tree"]

_PLAIN = re.compile(r"^[A-Za-z_$][\w.$/-]*( [\w.$/-]+)*$")
_QUOTED_WORDS = frozenset(("y", "n", "Y", "N", "yes", "no", "on", "off", "true", "false", "null", "none"))
_IGNORED_TOP = ("TreeNodesModel",)
_LINE = re.compile(r"\bline (\d+)\b")
_MILLISECONDS_HINT = re.compile(r": durations are in seconds; for \S+ milliseconds write ")
POLL_RANGE = (0.01, 3600.0)   # 100 checks a second (a call each) to one an hour


def _poll(value: Any) -> float:
    """``--poll``'s seconds, from POLL_RANGE."""
    try:
        out = float(value)
    except ValueError:
        out = math.nan
    if not POLL_RANGE[0] <= out <= POLL_RANGE[1]:   # nan and inf too
        raise argparse.ArgumentTypeError("expected seconds from %g to %g, got %r" % (POLL_RANGE + (value,)))
    return out


def _forever(value: Any) -> int:
    """``--forever``'s count: a whole number a loop may take (1 to bmtree's bound of a count)."""
    from coordinator.bounds import beyond_bound

    try:
        out = int(value)
    except ValueError:
        out = 0
    if out < 1 or beyond_bound("count", out):
        raise argparse.ArgumentTypeError("expected a whole number of runs from 1, got %r" % (value,))
    return out


def add_import_parser(sub: Any) -> None:
    from coordinator.cliutil import path_arg, text

    i = sub.add_parser("import", help="convert a BehaviorTree.CPP XML tree into a bmtree YAML tree",
                       description="Convert a BehaviorTree.CPP tree (XML, format 3 or 4) into a bmtree tree, checked "
                                   "as bmtree check does; nothing is written when a node cannot be converted.")
    i.add_argument("tree", metavar="TREE.xml", type=path_arg("a BehaviorTree.CPP XML file"))
    i.add_argument("-o", "--output", metavar="OUT.yaml", type=path_arg("a tree file to write"),
                   help="write the tree there (default: standard output)")
    i.add_argument("--modules", action="append", metavar="PATH", type=path_arg("a definition file or folder"),
                   help="more module definitions, file or directory (repeatable; added to the default ones)")
    i.add_argument("--map", action="append", metavar="ID=module.function", type=text("ID=module.function"),
                   help="the module function an action or condition ID is (repeatable; default: the function "
                        "whose name matches the ID: GoTo, go_to, Navigation.GoTo); ID=module.function(port=input,"
                        "-port) also renames its ports to the function's inputs and outputs, or drops them")
    i.add_argument("--tree", dest="tree_id", metavar="ID", type=text("a BehaviorTree ID"),
                   help="the BehaviorTree to import (default: main_tree_to_execute, or the file's only one), as "
                        "BehaviorTree.CPP's createTree(ID) chooses it")
    i.add_argument("--poll", type=_poll, default=POLL_DEFAULT, metavar="S",
                   help="seconds between two checks of a ReactiveSequence's or ReactiveFallback's Conditions while "
                        "its action runs (default %g; BehaviorTree.CPP checks them at each tick)" % POLL_DEFAULT)
    i.add_argument("--forever", type=_forever, metavar="N",
                   help="write a count of -1 (BehaviorTree.CPP's for ever: RetryUntilSuccessful's num_attempts, "
                        "Repeat's num_cycles) as N, each said in a warning (default: an error; every bmtree loop is "
                        "bounded)")
    i.set_defaults(func=cmd_import)


def cmd_import(args: argparse.Namespace) -> int:
    from coordinator.cliutil import EXIT_OK, definitions_from, err

    maps, renames = _maps(args.map)
    if args.output and os.path.abspath(args.output) == os.path.abspath(args.tree):
        raise UsageError("-o %s is the XML file itself: give another name" % args.output)
    defs = definitions_from(args.modules)
    out_path = args.output or os.path.splitext(args.tree)[0] + ".yaml"
    text, warnings = import_tree(args.tree, defs, maps, out_path, args.tree_id, args.poll, args.forever, renames)
    for w in warnings:
        err(str(w))
    if not args.output:
        sys.stdout.write(text)
        return EXIT_OK
    try:
        with open(args.output, "w", encoding="utf-8") as fh:
            fh.write(text)
    except OSError as exc:
        raise UsageError("-o %s: cannot write it: %s" % (args.output, exc.strerror or exc))
    print("%s: written from %s" % (args.output, args.tree), file=sys.stderr)
    return EXIT_OK


_MAP = re.compile(r"^(\w+\.\w+)(?:\((.*)\))?$")


def _maps(pairs: Optional[List[str]]) -> Tuple[Dict[str, str], Dict[str, Dict[str, Optional[str]]]]:
    """``--map ID=module.function``, maybe with its ports renamed or dropped: ``Speak=speech.say(say_text=text,
    -server_timeout)``. The functions by ID, and each ID's port renames (None: the port is dropped)."""
    out: Dict[str, str] = {}
    renames: Dict[str, Dict[str, Optional[str]]] = {}
    form = ("--map takes ID=module.function, or ID=module.function(port=input,-port) to rename or drop ports "
            "(e.g. --map 'Speak=speech.say(say_text=text)'), got %r")
    for pair in pairs or []:
        node_id, sep, target = pair.partition("=")
        m = _MAP.match(target.strip())
        if not sep or not node_id or m is None:
            raise UsageError(form % pair)
        out[node_id] = m.group(1)
        ports: Dict[str, Optional[str]] = {}
        for item in (m.group(2) or "").split(","):
            item = item.strip()
            port, eq, name = item.partition("=")
            if not item:
                continue
            if item.startswith("-") and item[1:].isidentifier():
                ports[item[1:]] = None
            elif eq and port.strip().isidentifier() and name.strip().isidentifier():
                ports[port.strip()] = name.strip()
            else:
                raise UsageError(form % pair)
        if ports:
            renames[node_id] = ports
    return out, renames


def _shown(path: str) -> str:
    rel = os.path.relpath(os.path.abspath(path))
    return os.path.abspath(path) if rel.startswith(os.pardir) else rel


def import_tree(path: str, definitions: Mapping[str, ModuleDefinition], maps: Mapping[str, str],
                out_path: str, tree_id: Optional[str] = None,
                poll: float = POLL_DEFAULT, forever: Optional[int] = None,
                renames: Optional[Mapping[str, Mapping[str, Optional[str]]]] = None) -> Tuple[str, List[TreeError]]:
    """The YAML text of the main tree of ``path`` (or of ``tree_id``), checked as if written at ``out_path``,
    and the warnings (at the XML's positions); TreeErrors (at the XML's positions) when it cannot be
    converted. ``poll``: the seconds between two checks of a reactive node's Conditions; ``forever``: what a
    count of -1 becomes (None: an error); ``renames``: by ID, its ports renamed to the function's inputs and
    outputs (None: dropped), from ``--map ID=module.function(port=input,-port)``."""
    shown = _shown(path)
    try:
        text = read_text(path)
    except OSError as exc:
        raise TreeErrors([TreeError(Pos(shown, 1, 1), "cannot read %s: %s" % (shown, exc.strerror or exc))])
    except UnicodeDecodeError as exc:
        raise TreeErrors([TreeError(Pos(shown, *byte_pos(exc.object, exc.start)), "not UTF-8 text: byte 0x%02x"
                                    % exc.object[exc.start])])
    try:
        root = parse_xml(text, shown)
    except XmlErrors as exc:
        raise TreeErrors(exc.errors)
    errors: List[TreeError] = []
    notes: List[TreeError] = []
    version, trees, main = _top(root, errors, notes, tree_id)
    if main is None:
        raise TreeErrors(notes + errors)   # the format chosen may be why
    conv = Converter(trees, version, definitions, maps, model_kinds(root), poll, forever, renames)
    top = conv.tree(main, Scope(), trees[main])
    conv.finish()
    errors += conv.errors
    if errors or top is None:
        raise TreeErrors(notes + errors)
    if conv.initial:   # generated keys a node reads before it writes them (SequenceWithMemory's progress)
        top = Out(top.pos, ("sequence", [Out(top.pos, ("set", conv.initial)), top]))
    inputs = sorted(conv.reads - conv.written)
    lines = _document(top, main, shown, version, inputs)
    yaml_text = "".join(t + "\n" for t, _p in lines)
    warnings = [w for w in _check(yaml_text, lines, out_path, definitions)   # BehaviorTree.CPP wrote milliseconds
                if not (_MILLISECONDS_HINT.search(w.message) and (w.pos.line, w.pos.column) in conv.from_ms)]
    return yaml_text, notes + conv.notes + warnings


def _top(root: Element, errors: List[TreeError], notes: List[TreeError],
         chosen: Optional[str]) -> Tuple[int, Dict[str, Element], Optional[str]]:
    """The format, the BehaviorTrees by ID and the one to import (None after reporting); ``notes``: how the
    format was chosen when the file does not say."""
    if root.tag != "root":
        errors.append(TreeError(root.pos, "not a BehaviorTree.CPP file: its top element is <%s>, not <root>" % root.tag))
        return 3, {}, None
    raw = root.attrs.get("BTCPP_format")
    if raw is None:
        version, why = format_of(root)
        notes.append(TreeError(root.pos, "warning: %s" % why))
        raw = str(version)
    raw = raw.strip()
    if raw not in ("3", "4"):
        errors.append(TreeError(root.at("BTCPP_format"), "BTCPP_format %r: bmtree import reads formats 3 and 4" % raw))
        return 3, {}, None
    trees: Dict[str, Element] = {}
    for el in root.children:
        if el.tag == "BehaviorTree":
            tid = el.attrs.get("ID", "")
            if not tid:
                errors.append(TreeError(el.pos, "<BehaviorTree> needs an ID"))
            elif tid in trees:
                errors.append(TreeError(el.at("ID"), "a second BehaviorTree %r (the first at line %d)" % (
                    tid, trees[tid].pos.line)))
            else:
                trees[tid] = el
        elif el.tag == "include":
            errors.append(TreeError(el.pos, "<include path=%r> is not converted: bmtree import reads one file; put "
                                            "the trees it needs in this file (Groot can save them together)"
                                    % el.attrs.get("path", "")))
        elif el.tag not in _IGNORED_TOP:
            errors.append(TreeError(el.pos, "<%s> is no element of a BehaviorTree.CPP file's <root> (BehaviorTree, "
                                            "TreeNodesModel, include)" % el.tag))
    from comm.errors import did_you_mean

    if chosen is not None and chosen not in trees:
        if not errors:
            raise UsageError("--tree %s: no BehaviorTree of that ID in %s (%s)%s" % (
                chosen, root.pos.file, ", ".join(trees) or "none", did_you_mean(chosen, trees)))
        return int(raw), trees, None
    main = chosen or root.attrs.get("main_tree_to_execute")
    if main is None and len(trees) == 1:
        main = next(iter(trees))
    elif main is None:
        errors.append(TreeError(root.pos, "several BehaviorTrees (%s) and no main_tree_to_execute on <root>: choose "
                                          "the one to import with --tree ID (BehaviorTree.CPP's createTree(ID))"
                                % ", ".join(trees) if trees else "no BehaviorTree in the file"))
    elif main not in trees:
        errors.append(TreeError(root.at("main_tree_to_execute"), "main_tree_to_execute %r: no BehaviorTree of that ID "
                                "(%s)%s; or choose one with --tree ID" % (main, ", ".join(trees) or "none",
                                                                         did_you_mean(main, trees))))
        main = None
    return int(raw), trees, main


# YAML ----------------------------------------------------------------------------------------
def scalar(v: Any) -> str:
    """One YAML scalar that bmtree's reader reads back as ``v``."""
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if _PLAIN.match(v) and v not in _QUOTED_WORDS and v.lower() not in _QUOTED_WORDS:
        return v
    return json.dumps(v, ensure_ascii=False)


def _flow(v: Any) -> str:
    if isinstance(v, dict):
        return "{%s}" % ", ".join("%s: %s" % (scalar(k), _flow(x)) for k, x in v.items())
    if isinstance(v, list):   # for_each's elements
        return "[%s]" % ", ".join(_flow(x) for x in v)
    return scalar(v)


Line = Tuple[str, Pos]


def _emit(node: Out, indent: int, lead: str, out: List[Line]) -> None:
    pad = " " * indent
    items = node.items
    if isinstance(items[0][1], (list, Out)) and len(items) > 1 and items[1][0] == "name":
        items = [items[1], items[0]] + items[2:]   # the name first, not below a block of children
    for n, (key, value) in enumerate(items):
        head = pad + (lead if n == 0 else " " * len(lead)) + scalar(key) + ":"
        inner = indent + len(lead) + 2
        if isinstance(value, Out):
            out.append((head, node.pos))
            _emit(value, inner, "", out)
        elif isinstance(value, list) and value and all(isinstance(c, Out) for c in value):   # children
            out.append((head, node.pos))
            for child in value:
                _emit(child, inner, "- ", out)
        elif isinstance(value, dict) and any(isinstance(x, Out) for x in value.values()):   # a switch's cases
            out.append((head, node.pos))
            for case, child in value.items():
                out.append((" " * inner + scalar(case) + ":", node.pos))
                _emit(child, inner + 2, "", out)
        else:
            out.append((head + " " + _flow(value), node.pos))


def _document(top: Out, main: str, shown: str, version: int, inputs: List[str]) -> List[Line]:
    first = Pos(shown, 1, 1)
    lines: List[Line] = [("# imported from %s (BehaviorTree.CPP format %d, tree %s) by bmtree import" % (
        shown, version, main), first), ("format: 1", first), ("name: %s" % scalar(main), first)]
    if inputs:
        lines.append(("# keys the tree reads but no node writes (the application set them): "
                      "bmtree run --set KEY=VALUE", first))
        lines.append(("inputs:", first))
        lines += [("  %s: {}" % scalar(k), first) for k in inputs]
    lines.append(("root:", top.pos))
    _emit(top, 2, "", lines)
    return lines


# the check -------------------------------------------------------------------------------------
def _check(text: str, lines: List[Line], out_path: str, definitions: Mapping[str, ModuleDefinition]) -> List[TreeError]:
    """``load_tree`` on the YAML (not written yet); its errors raised, its warnings returned, at the XML's
    positions (the YAML's own where a problem is not of one node)."""
    from coordinator.language import load_tree

    target = os.path.abspath(out_path)
    yaml_shown = _shown(out_path)

    def loader(path: str) -> str:
        return text if os.path.abspath(path) == target else read_text(path)

    def at_xml(e: TreeError) -> TreeError:
        if e.pos.file != yaml_shown or not 1 <= e.pos.line <= len(lines):
            return e
        said = _LINE.sub(lambda m: "line %d" % lines[int(m.group(1)) - 1][1].line
                         if 1 <= int(m.group(1)) <= len(lines) else m.group(0), e.message)   # "(written at line 8)"
        return TreeError(lines[e.pos.line - 1][1], "%s (imported YAML line %d)" % (said, e.pos.line))

    try:
        tree = load_tree(out_path, definitions, loader=loader)
    except TreeErrors as exc:
        raise TreeErrors([at_xml(e) for e in exc.errors])
    return sorted({at_xml(w) for w in tree.warnings}, key=lambda e: (e.pos.line, e.pos.column, e.message))
