"""Reading a text file the way every bmtree input is read (trees, definitions, worlds, the language
reference): bounded, devices refused, a pipe read whole while a program writes it and refused when
none does, and a byte that is not UTF-8 placed at its line and column."""
from __future__ import annotations

import errno
import os
import stat
from typing import Any, Optional, Tuple

__all__ = ["MAX_BYTES", "read_text", "text_pos"]

MAX_BYTES = 16 * 1024 * 1024   # a file bmtree reads; generous (a 1,000-node tree is ~50 KB)


def read_text(path: str, limit: Optional[int] = None) -> str:
    """A text file of at most ``limit`` bytes (MAX_BYTES), read no further than that (``/dev/zero`` or a
    huge file must not fill the memory); devices are refused (a terminal would wait for input). Raises
    OSError, and UnicodeDecodeError over the whole bytes (see :func:`text_pos`)."""
    limit = MAX_BYTES if limit is None else limit
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)   # a FIFO without a writer: no wait at open
    except ValueError:   # os.open's own error for a NUL in the name (an include: "a\0b")
        raise OSError(errno.EINVAL, "a file name cannot hold a NUL character") from None
    with os.fdopen(fd, "rb") as fh:
        mode = os.fstat(fd).st_mode
        if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) or stat.S_ISSOCK(mode):
            raise OSError(errno.EINVAL, "not a regular file")
        data = b""
        if stat.S_ISFIFO(mode):   # a pipe (bash's <(...), a mkfifo) is read as a file while a writer has it open
            try:
                data = os.read(fd, limit + 1)
                if not data:   # no writer (and nothing left in it): it would read as an empty file
                    raise OSError(errno.ENODATA, "a pipe that no program writes to (start the writer first)")
            except BlockingIOError:   # a writer that has not written yet: wait for it
                pass
        os.set_blocking(fd, True)
        data += fh.read(limit + 1 - len(data))
    if len(data) > limit:
        raise OSError(errno.EFBIG, "larger than %d MiB" % (limit >> 20) if limit >= 1 << 20
                      else "larger than %d bytes" % limit)
    return data.decode("utf-8")


def text_pos(text: Any, index: int) -> Tuple[int, int]:
    """Line and column (from 1, in characters) of ``text[index]``; for bytes, of the character at byte ``index``."""
    nl = b"\n" if isinstance(text, bytes) else "\n"
    start = text.rfind(nl, 0, index) + 1
    head = text[start:index]
    column = len(head.decode("utf-8", "replace") if isinstance(head, bytes) else head) + 1
    return text.count(nl, 0, index) + 1, column
