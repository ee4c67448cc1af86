"""The error texts of a module's answers: bounded in size, and naming the place in the
author's code an exception came from; and the keys salvaged from a payload too broken to
parse, so that even it gets an answer.
"""
from __future__ import annotations

import os
import re
import sysconfig
import traceback
from typing import Any, Dict, Optional, Set

from modules.basicmodule import BasicModule

__all__ = ["MAX_ERROR_CHARS", "salvage_keys", "bounded", "wire_text", "said", "author_files",
           "place_of", "raised_text", "which_call", "service_error"]

#: the longest ``error`` text the runtime sends (a message that long is cut, the place in the code kept)
MAX_ERROR_CHARS = 2000

_HERE = os.path.dirname(os.path.abspath(__file__))
# bmtree's own code: never "the place" of a module's error (modules/sim/ is a module's code, so it is not)
_OURS = tuple(os.path.join(os.path.dirname(_HERE), d, "") for d in ("comm", "coordinator", "blackboard"))
_LIBRARY = tuple({os.path.join(sysconfig.get_paths()[k], "") for k in ("stdlib", "platstdlib")})

_KEY_TEXT = {k: re.compile(r'"%s"\s*:\s*"([^"\\]{1,200})"' % k) for k in ("basic_mod", "function", "call_id")}


def salvage_keys(text: Any) -> Dict[str, str]:
    """The plain string keys of a payload too big, deep or broken to parse, to answer it."""
    if isinstance(text, (bytes, bytearray)):
        text = bytes(text[:1 << 20]).decode("utf-8", "replace")
    if not isinstance(text, str):
        return {}
    out = {}
    for key, pattern in _KEY_TEXT.items():
        m = pattern.search(text)
        if m:
            out[key] = m.group(1)
    return out


def bounded(text: str, limit: int = MAX_ERROR_CHARS) -> str:
    """``text`` cut to ``limit`` characters: an error text travels in every answer and run log."""
    return text if len(text) <= limit else text[:limit] + "..."


def wire_text(text: str) -> str:
    """``text`` as valid Unicode: a lone surrogate (``"\\udc80"``, from a file name or bytes decoded with
    ``surrogateescape``) written as its escape, since a payload holding one does not decode at the
    coordinator, and an answer that does not decode is no answer."""
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


def said(value: Any) -> str:
    """``str(value)``, never raising: an author's exception (or reason) whose ``__str__`` raises,
    even a BaseException, must not lose the call's answer."""
    try:
        text = value if isinstance(value, str) else str(value)
        return text if isinstance(text, str) else "(its message cannot be shown)"
    except BaseException:  # noqa: B036 - SystemExit from __str__ is the author's bug too
        return "(its message cannot be shown)"


_SERVER_SAID = re.compile(r"(responded with an error: )b(['\"])(.*)\2$", re.S)


def service_error(exc: BaseException) -> str:
    """A rospy service error as text to answer with: rospy says what the server raised as the repr of
    its bytes (``service [/detect] responded with an error: b'error processing request: camera
    unplugged'``, non-ASCII as ``\\xc3\\xad``); this gives the server's words."""
    text = said(exc)
    found = _SERVER_SAID.search(text)
    if found is None:
        return text
    try:
        words = found.group(3).encode("latin-1", "backslashreplace").decode("unicode_escape")
        words = words.encode("latin-1").decode("utf-8", "replace")
    except (UnicodeError, ValueError):
        return text
    return text[:found.start()] + found.group(1) + words


def _ours(path: str) -> bool:
    path = os.path.abspath(path)
    return os.path.dirname(path) == _HERE or path.startswith(_OURS)


def _library(path: str) -> bool:
    return path.startswith(_LIBRARY) or path.startswith("<frozen") or any(
        d in path for d in (os.sep + "site-packages" + os.sep, os.sep + "dist-packages" + os.sep))


def author_files(impl: Any) -> Set[str]:
    """The files that define the methods of ``impl``'s class and its bases, bmtree's own excepted."""
    files = set()
    for cls in type(impl).__mro__:
        if cls in (BasicModule, object):
            continue
        for value in vars(cls).values():
            code = getattr(getattr(value, "__func__", value), "__code__", None)
            if code is not None and not _ours(code.co_filename):
                files.add(os.path.abspath(code.co_filename))
    return files


def place_of(exc: BaseException, authors: Optional[Set[str]] = None) -> str:
    """``arm.py:10 in pick``: the innermost frame of the module author's code in ``exc``'s traceback.

    That is the line the author fixes: not the runtime's frames that called the method, and not
    the standard library's or an installed package's frames it called, unless it is in one of the
    ``authors`` files (the class's own, which may be installed) or no other frame is left. ""
    when the exception came from bmtree's own code alone."""
    authors = authors or set()
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if not _ours(f.filename)]
    if not frames:
        return ""
    frame = next((f for f in reversed(frames) if os.path.abspath(f.filename) in authors or not _library(f.filename)),
                 frames[-1])
    return "%s:%s in %s" % (os.path.basename(frame.filename), frame.lineno, frame.name)


def raised_text(exc: BaseException, authors: Optional[Set[str]] = None) -> str:
    """The ``error`` of a call whose method raised: ``KeyError: 'banana' (arm.py:10 in pick)``, or
    ``AssertionError at arm.py:10 in pick`` for an empty message; bounded in size, the place kept,
    so the tree's log says where to look without the module's terminal."""
    name = type(exc).__name__
    message = said(exc)  # a broken __str__ must not lose the answer
    place = place_of(exc, authors)
    message = bounded(message, MAX_ERROR_CHARS - len(name) - len(place) - 8)
    if not message:
        return "%s at %s" % (name, place) if place else name
    return "%s: %s (%s)" % (name, message, place) if place else "%s: %s" % (name, message)


def which_call(call_id: Optional[str]) -> str:
    """A call as a log line names it (a malformed call may come without an id)."""
    return "call %s" % call_id if call_id is not None else "a call without an id"
