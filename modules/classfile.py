"""The class of a module author's file (``bmtree-module --class FILE.py:CLASS`` or ``package.module:CLASS``),
loaded for the node that runs it, and where in the author's code a load or an ``__init__`` raised."""
from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from typing import Any, Callable

from modules.runtime import BasicModule

__all__ = ["load_class", "where_raised"]


def load_class(spec: str) -> Callable[[], BasicModule]:
    """``package.module:Class`` or ``path/to/file.py:Class`` (whose folder is put first on the path, as
    ``python path/to/file.py`` does, so that it imports the modules beside it)."""
    if ":" not in spec:
        raise ValueError("expected MODULE:CLASS or FILE.py:CLASS, got %r" % spec)
    where, cls_name = spec.rsplit(":", 1)
    if where.endswith(".py"):
        mod_name = "bmtree_user_" + os.path.splitext(os.path.basename(where))[0]
        sp = importlib.util.spec_from_file_location(mod_name, where)
        if sp is None or sp.loader is None:
            raise ValueError("cannot load %s" % where)
        with open(where, "rb") as fh:
            if b"\0" in fh.read():
                raise ValueError("%s: not a Python source file (it contains NUL bytes)" % where)
        module = importlib.util.module_from_spec(sp)
        sys.modules[mod_name] = module
        folder = os.path.dirname(os.path.abspath(where))
        if folder not in sys.path:   # as ``python FILE.py`` does: a driver wrapper beside the file imports
            sys.path.insert(0, folder)
        sp.loader.exec_module(module)
    else:
        module = _import_module(where, spec)
    cls = getattr(module, cls_name, None)
    if cls is None:
        from comm.errors import did_you_mean

        classes = sorted(n for n, v in vars(module).items() if isinstance(v, type) and not n.startswith("_"))
        raise ValueError("%s has no class %r%s" % (where, cls_name, did_you_mean(cls_name, classes)
                                                   or " (its classes: %s)" % (", ".join(classes) or "none")))
    if not isinstance(cls, type) or not issubclass(cls, BasicModule):
        raise ValueError("%s: %s is not a subclass of BasicModule (from modules.runtime import BasicModule; "
                         "class %s(BasicModule): ...)" % (where, cls_name, cls_name))
    return cls


def _import_module(name: str, spec: str) -> Any:
    """``import name`` for ``--class name:CLASS``; a module that is not on the path is a ValueError
    that says how to give its file instead (the current directory is not searched: it is not on
    the path of a node)."""
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        missing = exc.name or ""
        if not missing or not (name == missing or name.startswith(missing + ".")):
            raise  # the module was found, and something it imports was not: said where it imports it
        cls_name = spec.rsplit(":", 1)[1]
        path = os.path.join(*name.split(".")) + ".py"
        if os.path.isfile(path):
            hint = "give the file, --class %s:%s" % (path, cls_name)
        else:
            hint = ("MODULE must be importable (on PYTHONPATH, or installed); --class FILE.py:%s loads a file "
                    "directly" % cls_name)
        raise ValueError("%s: no Python module %r on the path (PYTHONPATH): %s" % (spec, name, hint))


def where_raised(exc: BaseException, spec: str) -> str:
    """``file:line`` of the deepest frame of the author's code in a traceback (else the class spec)."""
    import traceback

    here = os.path.dirname(os.path.abspath(__file__))   # bmtree's own modules/, not modules/example/
    frames = [f for f in traceback.extract_tb(exc.__traceback__)
              if os.path.dirname(os.path.abspath(f.filename)) != here and "importlib" not in f.filename]
    return "%s:%s" % (frames[-1].filename, frames[-1].lineno) if frames else spec
