"""The interaction-memory file as untrusted input: its schema, SQLite's limits, a deadline, and value checks.

A memory file may come from anywhere (a colleague, a download, an attacker with write access to the directory),
and SQLite runs whatever the file's schema says: a trigger on ``interactions`` runs on every ``add()`` (an endless
recursive query, or one that grows a 2 GB blob), a view in place of a table runs on every read. So
:class:`~robocritics.llm.memory.InteractionMemory`, through this module:

* compares the file's schema with the one robocritics creates before running anything else on it
  (:func:`foreign_objects` before an upgrade, :func:`layout` after): exactly our tables, columns and indexes, and no
  trigger, view, virtual table or other object;
* sets SQLite's own limits on the connection (:func:`limit`: longest value, statement, columns, attached databases,
  trigger depth, ...) and ``trusted_schema = OFF``;
* runs every statement under a deadline (:class:`Deadline`, SQLite's progress handler);
* checks every value it reads against the contract of its column (:func:`checked_interaction`, :func:`whole`,
  :func:`finite`): text where text belongs, counts that are whole and not negative, scores within 0–10, known
  sources. A value out of contract raises ``ValueError`` naming the column, which the memory turns into an
  ``InteractionMemoryError``.
"""

from __future__ import annotations

import math
import sqlite3
import time
from collections.abc import Callable

from robocritics.llm.limits import MAX_QUERY_TERMS, MAX_STORED_FEEDBACK_CHARS, MAX_STORED_PROGRAM_CHARS, MAX_TASK_CHARS

__all__ = [
    "Deadline",
    "DEFAULT_STATEMENT_TIMEOUT_S",
    "MAX_VALUE_BYTES",
    "MAX_SESSION_CHARS",
    "checked_interaction",
    "finite",
    "foreign_objects",
    "layout",
    "limit",
    "shown",
    "text",
    "whole",
]

#: Seconds one statement (or one write transaction, or opening the file) may run: the memory's queries read a
#: handful of rows through indexes and take milliseconds on a file of a million interactions; far longer means a
#: hostile or damaged file, which must not hang the caller.
DEFAULT_STATEMENT_TIMEOUT_S = 30.0
#: Longest string or blob SQLite may make or read, bytes (``SQLITE_LIMIT_LENGTH``): a stored program is at most
#: 100,000 characters (400 kB of UTF-8), an embedding vector 8 bytes per dimension (4 MiB: 524,288 dimensions).
MAX_VALUE_BYTES = 4 * 1024 * 1024
#: Longest session id, characters (``add()`` refuses longer ones).
MAX_SESSION_CHARS = 200
#: The progress handler runs every this many SQLite virtual-machine instructions (~0.1 ms of work).
_PROGRESS_STEPS = 10_000

# SQLite's limits on the connection (sqlite3.Connection.setlimit, Python 3.11+): a hostile schema or value cannot
# make SQLite build a huge value, parse a huge statement, attach another file or nest triggers.
_LIMITS = {
    "SQLITE_LIMIT_LENGTH": MAX_VALUE_BYTES,
    "SQLITE_LIMIT_SQL_LENGTH": 1_000_000,  # the longest statement: a search's ids, MAX_SEARCH_K "?"s
    "SQLITE_LIMIT_COLUMN": 64,
    "SQLITE_LIMIT_EXPR_DEPTH": 100,
    "SQLITE_LIMIT_COMPOUND_SELECT": 4,
    "SQLITE_LIMIT_FUNCTION_ARG": 8,
    "SQLITE_LIMIT_ATTACHED": 0,
    "SQLITE_LIMIT_LIKE_PATTERN_LENGTH": 100,
    "SQLITE_LIMIT_VARIABLE_NUMBER": 2 * MAX_QUERY_TERMS + 1_100,  # a search binds at most MAX_SEARCH_K + a few
    "SQLITE_LIMIT_TRIGGER_DEPTH": 1,
    "SQLITE_LIMIT_WORKER_THREADS": 0,
}

# The longest text each column holds (add() cuts texts to these).
_TEXT_CHARS = {
    "session": MAX_SESSION_CHARS,
    "request": MAX_TASK_CHARS,
    "program": MAX_STORED_PROGRAM_CHARS,
    "feedback": MAX_STORED_FEEDBACK_CHARS,
}


def limit(conn: sqlite3.Connection) -> None:
    """Set SQLite's limits (see :data:`_LIMITS`) and pragmas that distrust the file's schema on ``conn``."""
    setlimit = getattr(conn, "setlimit", None)  # Python 3.11+
    if setlimit is not None:
        for name, value in _LIMITS.items():
            category = getattr(sqlite3, name, None)
            if category is not None:
                setlimit(category, value)
    # functions with side effects never run from a schema's views, triggers or indexes; damaged cells are caught
    # when read instead of being trusted; no file mapping (a truncated file under a mapping is SIGBUS, not an error)
    for pragma in ("trusted_schema = OFF", "cell_size_check = ON", "mmap_size = 0", "recursive_triggers = OFF"):
        conn.execute(f"PRAGMA {pragma}")


class Deadline:
    """SQLite's progress handler on a connection: a statement still running ``timeout_s`` after :meth:`start` is
    interrupted (it raises ``sqlite3.OperationalError`` with ``sqlite_errorname`` ``SQLITE_INTERRUPT``).

    ``clock`` returns seconds (monotonic); injected by tests."""

    def __init__(self, conn: sqlite3.Connection, timeout_s: float, clock: Callable[[], float] = time.monotonic):
        self.timeout_s, self.clock = timeout_s, clock
        self.ends = math.inf
        conn.set_progress_handler(self._over, _PROGRESS_STEPS)

    def start(self) -> None:
        """The next statements have ``timeout_s`` from now."""
        self.ends = self.clock() + self.timeout_s

    def _over(self) -> int:
        return 1 if self.clock() > self.ends else 0


# --- the schema ------------------------------------------------------------------------------------------------


def foreign_objects(conn: sqlite3.Connection, tables: set[str], indexes: set[str]) -> list[str]:
    """What the file's schema holds besides ``tables`` and ``indexes`` (and SQLite's own ``sqlite_sequence`` and
    automatic indexes): triggers, views, virtual tables, other tables and indexes, each as ``"trigger 'name'"``.

    Reading ``sqlite_master`` runs nothing of the schema, so this is safe on any file."""
    found = []
    rows = conn.execute("SELECT type, name, sql FROM sqlite_master ORDER BY type, name").fetchall()
    for kind, name, sql in rows:
        # the statement SQLite runs to load an object is its sql, whatever its type says (a schema edited with
        # writable_schema can call a trigger a table): both must agree
        words = sql.split(None, 2)[:2] if isinstance(sql, str) else []
        said = " ".join(w.upper() for w in words)
        if kind == "table" and (name in tables or name == "sqlite_sequence") and said == "CREATE TABLE":
            continue
        if kind == "index" and name in indexes and said in ("CREATE INDEX", "CREATE UNIQUE"):
            continue
        if kind == "index" and isinstance(name, str) and name.startswith("sqlite_autoindex_") and sql is None:
            continue
        what = {"CREATE TRIGGER": "trigger", "CREATE VIEW": "view", "CREATE VIRTUAL": "virtual table"}.get(said, kind)
        found.append(f"{what} {name!r:.80}")
    return found


def layout(conn: sqlite3.Connection, tables: list[str]) -> dict[str, object]:
    """What the schema means for ``tables``: each table's kind (table, view, virtual), WITHOUT ROWID and STRICT
    flags, its columns (name, declared type, NOT NULL, default, primary key position, hidden/generated), and each
    of its indexes (name, unique, origin, partial, and the column, order and collation of every key). Two files
    with equal layouts store and index the same way."""
    out: dict[str, object] = {}
    for table in tables:
        kind = _kind(conn, table)
        columns = conn.execute(f"PRAGMA table_xinfo({_quoted(table)})").fetchall()
        listed = conn.execute(f"PRAGMA index_list({_quoted(table)})").fetchall()  # seq, name, unique, origin, partial
        indexes = []
        for _, name, unique, origin, partial in listed:
            keys = conn.execute(f"PRAGMA index_xinfo({_quoted(name)})").fetchall()
            indexes.append((str(name), unique, origin, partial, [tuple(k[1:]) for k in keys]))
        out[table] = (kind, [tuple(c[1:]) for c in columns], sorted(indexes, key=repr))
    return out


def _kind(conn: sqlite3.Connection, table: str) -> list[tuple]:
    """(type, WITHOUT ROWID, STRICT) of ``table`` from ``pragma_table_list`` (SQLite 3.37+), or what an older SQLite
    can tell from ``sqlite_master``: the same answer for the file and the reference, which one SQLite reads."""
    try:
        return conn.execute("SELECT type, wr, strict FROM pragma_table_list WHERE schema = 'main' AND name = ?",
                            (table,)).fetchall()  # fmt: skip
    except sqlite3.OperationalError:
        return conn.execute("SELECT type, instr(upper(sql), 'WITHOUT ROWID') > 0, 0 FROM sqlite_master WHERE name = ?",
                            (table,)).fetchall()  # fmt: skip


def _quoted(name: object) -> str:
    return '"' + str(name).replace('"', '""') + '"'


# --- values ----------------------------------------------------------------------------------------------------


def whole(value: object, column: str, least: int = 0) -> int:
    """``value`` if it is a whole number (not a bool, not text) of at least ``least``; else ValueError naming ``column``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        raise ValueError(f"{column} holds {shown(value)}, not a whole number >= {least}")
    return value


def finite(value: object, column: str, low: float = -math.inf, high: float = math.inf) -> float:
    """``value`` as a float if it is a finite number within [low, high]; else ValueError naming ``column``."""
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not number or not math.isfinite(value) or not low <= value <= high:  # type: ignore[operator, arg-type]
        bounds = "" if math.isinf(low) and math.isinf(high) else f" within {low:g}-{high:g}"
        raise ValueError(f"{column} holds {shown(value)}, not a finite number{bounds}")
    return float(value)


def text(value: object, column: str, max_chars: int, least: int = 0) -> str:
    """``value`` if it is text of ``least`` to ``max_chars`` characters; else ValueError naming ``column``."""
    if not isinstance(value, str) or not least <= len(value) <= max_chars:
        raise ValueError(f"{column} holds {shown(value)}, not text of {least} to {max_chars:,} characters")
    return value


def checked_interaction(row: tuple, sources: tuple[str, ...]) -> tuple:
    """An ``interactions`` row (id, session, request, program, feedback, score, created_s, source) if every value
    keeps the contract of its column; else ValueError naming the column and the interaction."""
    try:
        row_id = whole(row[0], "interactions.id", 1)
    except ValueError as exc:
        raise ValueError(f"an interaction's {exc}") from None
    try:
        session = text(row[1], "session_id", MAX_SESSION_CHARS, 1)
        texts = [text(row[i], name, _TEXT_CHARS[name]) for i, name in ((2, "request"), (3, "program"), (4, "feedback"))]
        score = None if row[5] is None else finite(row[5], "score", 0.0, 10.0)
        created = finite(row[6], "created_s")
        if row[7] not in sources:
            raise ValueError(f"source holds {shown(row[7])}, not one of {', '.join(sources)}")
    except ValueError as exc:
        raise ValueError(f"interaction {row_id}: {exc}") from None
    return (row_id, session, *texts, score, created, row[7])


def shown(value: object) -> str:
    """A value for a message: its type and at most 40 characters of it."""
    if isinstance(value, (bytes, bytearray)):
        return f"a blob of {len(value):,} bytes"
    if isinstance(value, str):
        return f"the text {value[:40]!r}" + ("..." if len(value) > 40 else "")
    return f"{type(value).__name__} {value!r:.40}"
