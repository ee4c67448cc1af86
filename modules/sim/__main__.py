"""Run one simulated module as a ROS node: ``python -m modules.sim navigation --world W``.

Under roslaunch the private parameters ``~module`` and ``~world`` stand for the arguments.
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import List, Optional

from comm.nodeopts import parse_node_args
from modules.callers import unreachable_seconds
from modules.definition import load_definition
from modules.node import run_module
from modules.sim import DEFAULT_WORLD, SIM_CLASSES, World, WorldError, definition_path


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m modules.sim", description="Run a simulated basic module.")
    p.add_argument("module", nargs="?", choices=sorted(SIM_CLASSES))
    p.add_argument("--world", default=DEFAULT_WORLD, help="world YAML (default, or '': the shipped house)")
    p.add_argument("--unreachable-caller", type=unreachable_seconds, metavar="SECONDS",
                   help="cancel the calls of a caller that has not answered for this long (a dropped link, a stopped "
                        "process), as bmtree-module does (default 0: never; or ~unreachable_caller)")
    return p


def main(argv: Optional[List[str]] = None) -> int:
    parser = make_parser()
    args = parse_node_args(parser, (argv if argv is not None else sys.argv)[1:], None)
    if not args.module:
        parser.error("which module? one of %s (or the private parameter ~module)" % ", ".join(sorted(SIM_CLASSES)))
    try:
        # a launch file passes ~/ as written; faults of the user's own modules are theirs to apply
        # (sim.launch always sets ~world, '' for the default: a value left on the master by an earlier
        # launch with world:= would be taken otherwise)
        world = World.load(os.path.expanduser(args.world or DEFAULT_WORLD), others=True)
    except WorldError as exc:
        sys.stderr.write("error: %s\n" % exc)
        return 2
    return run_module(load_definition(definition_path(args.module)), SIM_CLASSES[args.module](world),
                      unreachable_caller=args.unreachable_caller)


if __name__ == "__main__":
    sys.exit(main())
