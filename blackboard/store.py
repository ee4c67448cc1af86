"""The Blackboard's durable store: SQLite in WAL mode, one row per output value.

Values are kept as the JSON text that travelled on the wire, so storing and
answering never re-encode a message.
"""
from __future__ import annotations

import os
import sqlite3
from dataclasses import dataclass
from typing import Any, Iterable, List, Optional, Sequence, Tuple

__all__ = ["Store", "StoredValue", "default_db_path", "parse_name", "DEFAULT_KEEP", "MAX_NAME", "name_problem",
           "shown_name"]

DEFAULT_KEEP = 1000

_SCHEMA = """
CREATE TABLE IF NOT EXISTS value (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    name TEXT NOT NULL,
    rostype TEXT NOT NULL,
    msg TEXT NOT NULL,
    basic_mod TEXT,
    function TEXT,
    call_id TEXT,
    stamp REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS value_name ON value (name, id);
CREATE INDEX IF NOT EXISTS value_qualified ON value (basic_mod, function, name, id);
CREATE INDEX IF NOT EXISTS value_call ON value (call_id);
"""


@dataclass
class StoredValue:
    name: str
    rostype: str
    msg: str
    basic_mod: Optional[str]
    function: Optional[str]
    call_id: Optional[str]
    stamp: float

    @property
    def source(self) -> dict:
        return {"basic_mod": self.basic_mod, "function": self.function, "call_id": self.call_id,
                "stamp": self.stamp}


def default_db_path() -> str:
    home = os.environ.get("ROS_HOME") or os.path.join(os.path.expanduser("~"), ".ros")
    return os.path.join(home, "bmtree", "blackboard.sqlite")


def parse_name(name: str) -> Tuple[Optional[str], Optional[str], str]:
    """``name`` or ``module/function/name``; ValueError for anything else."""
    if not isinstance(name, str) or not name:
        raise ValueError("invalid name %r: expected 'name' or 'module/function/name'" % (name,))
    parts = name.split("/")
    if len(parts) == 1:
        return None, None, name
    if len(parts) == 3 and all(parts):
        return parts[0], parts[1], parts[2]
    raise ValueError("invalid name %r: expected 'name' or 'module/function/name'" % (name,))


MAX_NAME = 256   # characters of a value's name: far above any output's name


def name_problem(name: Any) -> str:
    """Why ``name`` cannot be a stored value's name, "" if it can: a request must be able to ask for it
    (``name``, not ``module/function/name``) and a dump to show it on its line."""
    if not isinstance(name, str) or not name:
        return "an empty name"
    if len(name) > MAX_NAME:
        return "a name longer than %d characters" % MAX_NAME
    if "/" in name:
        return "a name with '/' (a request would read it as module/function/name)"
    if not name.isprintable():
        return "a name with control characters"
    return ""


def shown_name(name: Any) -> str:
    """A stored name as a dump line shows it: quoted when it is not a usable name (an old store's '')."""
    return name if not name_problem(name) else repr(name)


class Store:
    """One connection; use one Store per thread (SQLite's rule)."""

    def __init__(self, path: str, keep: int = DEFAULT_KEEP):
        if path != ":memory:":
            os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        self.path = path
        self.keep = keep
        self.db = sqlite3.connect(path, check_same_thread=False, isolation_level=None)
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute("PRAGMA synchronous=NORMAL")
        self.db.executescript(_SCHEMA)

    @classmethod
    def read_only(cls, path: str) -> Store:
        """The store at ``path``, opened so that nothing in it is created or changed (``bmtree blackboard
        dump``, maybe while the node writes); sqlite3.DatabaseError if it is not a store."""
        import urllib.parse

        store = cls.__new__(cls)
        store.path, store.keep = path, DEFAULT_KEEP
        # SQLite deletes the -wal file when its last writer closes the store. Without one, nobody writes
        # it, and "immutable" reads it without the -wal/-shm files a WAL reader would leave behind.
        flags = "mode=ro" if os.path.exists(path + "-wal") else "mode=ro&immutable=1"
        store.db = sqlite3.connect("file:%s?%s" % (urllib.parse.quote(os.path.abspath(path)), flags), uri=True,
                                   check_same_thread=False, isolation_level=None)
        try:
            columns = {row[1] for row in store.db.execute("PRAGMA table_info(value)")}
            if not {"name", "rostype", "msg", "basic_mod", "function", "call_id", "stamp"} <= columns:
                raise sqlite3.DatabaseError("it has no table of Blackboard values")
        except sqlite3.DatabaseError:
            store.db.close()
            raise
        return store

    def close(self) -> None:
        self.db.close()

    def add(self, rows: Iterable[Tuple[str, str, str, Optional[str], Optional[str], Optional[str], float]]) -> int:
        """Insert (name, rostype, msg, basic_mod, function, call_id, stamp) rows in one transaction."""
        rows = list(rows)
        if not rows:
            return 0
        with self.db:
            self.db.execute("BEGIN")
            self.db.executemany(
                "INSERT INTO value (name, rostype, msg, basic_mod, function, call_id, stamp)"
                " VALUES (?, ?, ?, ?, ?, ?, ?)", rows)
        return len(rows)

    def add_each(self, rows: Iterable[tuple]) -> Tuple[int, List[Tuple[tuple, str]]]:
        """Insert rows one transaction each: (stored count, [(row, error)] of the refused)."""
        stored, bad = 0, []
        for row in rows:
            try:
                stored += self.add([row])
            except (sqlite3.Error, UnicodeError, ValueError, OverflowError) as exc:
                bad.append((row, "%s: %s" % (type(exc).__name__, exc)))
        return stored, bad

    def prune(self, names: Iterable[str]) -> int:
        """Apply the retention policy (keep the newest ``keep`` values) to the given names."""
        removed = 0
        with self.db:
            self.db.execute("BEGIN")
            for name in set(names):
                cur = self.db.execute(
                    "DELETE FROM value WHERE name = ? AND id <= (SELECT id FROM value WHERE name = ?"
                    " ORDER BY id DESC LIMIT 1 OFFSET ?)", (name, name, self.keep))
                removed += cur.rowcount
        return removed

    def latest(self, name: str, history: int = 1) -> List[StoredValue]:
        """Newest first; ``name`` may be qualified (``module/function/name``)."""
        mod, fn, short = parse_name(name)
        if mod is None:
            cur = self.db.execute("SELECT name, rostype, msg, basic_mod, function, call_id, stamp FROM value"
                                  " WHERE name = ? ORDER BY id DESC LIMIT ?", (short, history))
        else:
            cur = self.db.execute("SELECT name, rostype, msg, basic_mod, function, call_id, stamp FROM value"
                                  " WHERE basic_mod = ? AND function = ? AND name = ? ORDER BY id DESC LIMIT ?",
                                  (mod, fn, short, history))
        return [StoredValue(*row) for row in cur]

    def by_call(self, call_id: str) -> List[StoredValue]:
        cur = self.db.execute("SELECT name, rostype, msg, basic_mod, function, call_id, stamp FROM value"
                              " WHERE call_id = ? ORDER BY id", (call_id,))
        return [StoredValue(*row) for row in cur]

    def has_call(self, call_id: str) -> bool:
        return self.db.execute("SELECT 1 FROM value WHERE call_id = ? LIMIT 1", (call_id,)).fetchone() is not None

    def latest_each(self) -> List[Tuple[Any, int, StoredValue]]:
        """(name, count, newest value) of every name stored, by name, each name as it is stored (an old
        store may hold names no request can ask for, such as '')."""
        cur = self.db.execute("SELECT v.name, c.n, v.rostype, v.msg, v.basic_mod, v.function, v.call_id, v.stamp"
                              " FROM value v JOIN (SELECT MAX(id) AS last, COUNT(*) AS n FROM value GROUP BY name) c"
                              " ON v.id = c.last ORDER BY v.name")
        return [(row[0], row[1], StoredValue(*row[:1], *row[2:])) for row in cur]

    def names(self) -> List[Tuple[str, int, float]]:
        """(name, count, newest stamp) of every name stored."""
        return list(self.db.execute("SELECT name, COUNT(*), MAX(stamp) FROM value GROUP BY name ORDER BY name"))

    def count(self) -> int:
        return int(self.db.execute("SELECT COUNT(*) FROM value").fetchone()[0])


def rows_of(names: Sequence[str], rostypes: Sequence[str], texts: Sequence[str], basic_mod: Optional[str],
            function: Optional[str], call_id: Optional[str], stamp: float) -> List[tuple]:
    return [(n, t, m, basic_mod, function, call_id, stamp) for n, t, m in zip(names, rostypes, texts)]
