"""A basic module as a ROS node: the runtime bound to the wire topics.

Run one from the command line::

    bmtree-module --definition my_module.json --class my_package.my_module:MyModule

or ``python -m modules.node ...``. ROS remappings and private parameters work as
usual; ``_basic_mod:=other_name`` renames the module as the original modules did, and
``_max_bytes:=N`` changes the payload size limit (default 1 MiB).
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import logging
import os
import sys
from typing import Any, Callable, List, Optional

from comm import TOPIC_CALL, TOPIC_CANCEL, TOPIC_EVENT, TOPIC_RESULT, sync_publisher
from comm.messages import DEFAULT_MAX_BYTES
from modules.definition import DefinitionError, ModuleDefinition, load_definition
from modules.discovery import PARAM_ROOT, announcement
from modules.runtime import BasicModule, BindingError, ModuleServer

__all__ = ["ModuleNode", "load_class", "make_parser", "main", "run_module"]

log = logging.getLogger("bmtree.module")


class ModuleNode:
    """Wires a :class:`ModuleServer` to ROS; call :meth:`start` after ``rospy.init_node``."""

    def __init__(self, definition: ModuleDefinition, impl: BasicModule, max_bytes: int = DEFAULT_MAX_BYTES):
        self.definition = definition
        self.impl = impl
        self.max_bytes = max_bytes
        self.server: Optional[ModuleServer] = None
        self._subs: List[Any] = []
        self._param = ""

    def start(self) -> None:
        import rospy
        from std_msgs.msg import String

        name = rospy.get_param("~basic_mod", self.definition.name)
        self.max_bytes = int(rospy.get_param("~max_bytes", self.max_bytes))
        if name != self.definition.name:
            self.definition = self.definition.renamed(name)
        res_pub = sync_publisher(TOPIC_RESULT, String)  # from the call's worker thread
        ev_pub = rospy.Publisher(TOPIC_EVENT, String, queue_size=1000)
        self.server = ModuleServer(self.definition, self.impl,
                                   publish_result=lambda text: res_pub.publish(String(text)),
                                   publish_event=lambda text: ev_pub.publish(String(text)),
                                   max_bytes=self.max_bytes)
        self._subs = [
            rospy.Subscriber(TOPIC_CALL, String, lambda m: self.server.handle_call(m.data), queue_size=1000,
                             tcp_nodelay=True),
            rospy.Subscriber(TOPIC_CANCEL, String, lambda m: self.server.handle_cancel(m.data), queue_size=100,
                             tcp_nodelay=True),
        ]
        self.impl.setup(self)
        self._param = "%s/%s" % (PARAM_ROOT, self.definition.name)
        rospy.set_param(self._param, announcement(rospy.get_name(), self.definition))
        rospy.loginfo("basic module %r serving %s", self.definition.name, ", ".join(self.definition.functions))

    def stop(self) -> None:
        import rospy

        for s in self._subs:
            s.unregister()
        try:
            if self._param and rospy.get_param(self._param, {}).get("node") == rospy.get_name():
                rospy.delete_param(self._param)
        except Exception:  # the master may be gone already
            pass
        self.impl.shutdown()


def load_class(spec: str) -> Callable[[], BasicModule]:
    """``package.module:Class`` or ``path/to/file.py:Class``."""
    if ":" not in spec:
        raise ValueError("expected MODULE:CLASS or FILE.py:CLASS, got %r" % spec)
    where, cls_name = spec.rsplit(":", 1)
    if where.endswith(".py"):
        mod_name = "bmtree_user_" + os.path.splitext(os.path.basename(where))[0]
        sp = importlib.util.spec_from_file_location(mod_name, where)
        if sp is None or sp.loader is None:
            raise ValueError("cannot load %s" % where)
        module = importlib.util.module_from_spec(sp)
        sys.modules[mod_name] = module
        sp.loader.exec_module(module)
    else:
        module = importlib.import_module(where)
    cls = getattr(module, cls_name, None)
    if cls is None:
        raise ValueError("%s has no class %r" % (where, cls_name))
    return cls


def run_module(definition: ModuleDefinition, impl: BasicModule, node_name: Optional[str] = None) -> int:
    """Init a ROS node, serve until SIGINT/SIGTERM or ROS shutdown, clean up. Exit code."""
    import rospy

    rospy.init_node(node_name or "bm_%s" % definition.name, anonymous=False)
    node = ModuleNode(definition, impl)
    try:
        node.start()
    except BindingError as exc:
        sys.stderr.write("error: %s\n" % exc)
        return 2
    try:
        rospy.spin()
    finally:
        node.stop()
    return 0


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bmtree-module", description="Run a Python basic module as a ROS node.")
    p.add_argument("--definition", required=True, help="the module's definition JSON")
    p.add_argument("--class", dest="cls", required=True, help="MODULE:CLASS or FILE.py:CLASS implementing it")
    p.add_argument("--node-name", help="ROS node name (default bm_<module>)")
    return p


def main(argv: Optional[List[str]] = None) -> int:
    import rospy

    args = make_parser().parse_args(rospy.myargv(argv if argv is not None else sys.argv)[1:])
    try:
        definition = load_definition(args.definition)
        factory = load_class(args.cls)
        impl = factory()
    except DefinitionError as exc:
        sys.stderr.write("%s\n" % exc)
        return 2
    except (ValueError, ImportError, OSError) as exc:
        sys.stderr.write("error: %s\n" % exc)
        return 2
    try:
        ModuleServer(definition, impl, lambda t: None, lambda t: None)
    except BindingError as exc:
        sys.stderr.write("error: %s\n" % exc)
        return 2
    return run_module(definition, impl, args.node_name)


if __name__ == "__main__":
    sys.exit(main())
