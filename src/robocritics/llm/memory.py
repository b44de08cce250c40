"""Interaction memory: (request, program, critic feedback, score) tuples in SQLite, with retrieval.

Step 4 of the RoboCritics workflow stores each attempt; step 5 retrieves
similar past attempts so the model can refine instead of starting over.

Storage (one SQLite file, or ``":memory:"``; schema version 3):

* ``sessions(id, created_s)`` — one row per conversation / task run.
* ``interactions(id, session_id, request, program, feedback, score, created_s,
  request_tokens, source)`` — ``score`` is the 0–10 program quality index (NULL when
  the program was never critiqued, e.g. it failed to parse); times are unix
  seconds; ``request_tokens`` is the request's length in BM25 words;
  ``source`` is who wrote the program: ``'llm'`` (the model) or ``'repair'``
  (the critics' own repairs, :mod:`robocritics.repair`).
* ``request_terms(term, interaction_id, session_id, tf)`` — the inverted index
  of the requests (how often each word occurs in each request), and
  ``corpus_stats(session_id, documents, tokens)`` — counts per session and,
  under ``''``, over all sessions. BM25 is computed from these in SQL.
* ``embeddings(interaction_id, model, dim, vector, created_s)`` — one vector per
  interaction *per embedding model*, tagged with the model's name and length.

Older files are upgraded when they are opened: version 1 (before the index
existed) gets the index; versions 1 and 2 (before ``source``) get the column,
every older row counting as ``'llm'`` (only the model wrote programs then).

Bounds: stored texts are capped (request ``MAX_TASK_CHARS``, program
``MAX_STORED_PROGRAM_CHARS``, feedback ``MAX_STORED_FEEDBACK_CHARS``; longer
ones are cut, saying so) and cleaned of lone surrogates; a query is cut to
``MAX_TASK_CHARS`` characters and its first ``MAX_QUERY_TERMS`` distinct words.
Retrieval never loads every row: BM25 ranks in SQLite and returns ``k`` ids;
cosine similarity reads the stored vectors in batches of ``scan_batch_size``
keeping only the best ``k``; only the ``k`` results are read in full.

Retrieval (``search``) ranks by the request text:

* With an ``embedder``: cosine similarity between the query's vector and the
  stored vectors **of the current embedder's name and dimension only** —
  vectors from any other model are never compared. Interactions lacking a
  vector for the current model are embedded lazily, by ``search`` (or ahead of
  time by ``embed_missing``), in batches, and the vectors are stored for next
  time; ``add`` never calls the embedder, so storing works while the
  embedding server is down.
* Without one: BM25 (exactly ``llm.bm25.bm25_scores`` over the candidate
  requests: all, or the session's); interactions that share no word with the
  query are not returned.

Ties go to the newer interaction.

Errors: every failure of SQLite or of the file system — a corrupt file, a
read-only file or directory, a directory that cannot be created, a full disk,
a lock held too long — and every bad argument is an
:class:`InteractionMemoryError` naming the file and what was being done. A
read-only file is detected when the memory is opened and fails at once;
other write failures are never retried (only a busy lock is waited for, up
to ``busy_timeout_s``).

The file is untrusted input (see :mod:`robocritics.llm.memory_guard`): its schema must be exactly the one
robocritics creates (a trigger, view, virtual table or unknown object is refused when the file is opened, before
anything runs), SQLite's limits bound every value and statement, every statement runs under a deadline
(``statement_timeout_s``), and a value out of its column's contract (text in a numeric column, a negative count,
a blob for text, a score outside 0–10, an unknown source) is an :class:`InteractionMemoryError`. The file, and
SQLite's ``-wal``/``-shm``/``-journal`` files beside it, must not be symbolic links; a new file is created
exclusively (never through a link placed at its name).

Concurrency and durability: file databases run in WAL mode with
``synchronous=FULL`` and a busy timeout; every write is one ``BEGIN
IMMEDIATE`` … ``COMMIT`` transaction, so several threads (sharing one
instance, which serialises on a lock, or holding their own) and several
processes can write to one file, and a writer killed at any moment loses
nothing that was committed and leaves no partial row. An instance inherited
through ``fork`` opens its own connection in the child.
"""

from __future__ import annotations

import functools
import math
import os
import sqlite3
import stat
import threading
import time
import uuid
from collections import Counter
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocritics.errors import LLMError, RoboCriticsError
from robocritics.llm import memory_guard as guard
from robocritics.llm.bm25 import tokenize
from robocritics.llm.protocol import EmbeddingModel, embedding_space_name
from robocritics.llm.limits import (
    MAX_QUERY_TERMS,
    MAX_STORED_FEEDBACK_CHARS,
    MAX_STORED_PROGRAM_CHARS,
    MAX_TASK_CHARS,
    clean_text,
    cut_text,
)

__all__ = ["Interaction", "InteractionMemory", "InteractionMemoryError", "MAX_SEARCH_K", "SOURCES"]

SCHEMA_VERSION = 3
#: Who wrote a stored program: the chat model, or the critics' own repairs.
SOURCES = ("llm", "repair")

#: Seconds a write waits for another writer's lock: writes are single small transactions, so a lock held
#: this long means a stuck writer, not a busy one.
DEFAULT_BUSY_TIMEOUT_S = 10.0
#: Most results one search returns: examples for a prompt are a handful; more is a listing, not a search.
MAX_SEARCH_K = 1_000
#: Stored vectors compared per batch: 4096 vectors of 1536 floats are 50 MB at most in memory at once.
DEFAULT_SCAN_BATCH_SIZE = 4_096

# BM25 parameters: those of llm.bm25.bm25_scores' defaults, which this module reproduces in SQL.
_BM25_K1 = 1.5
_BM25_B = 0.75
# Scores are compared rounded to this many decimals, so equal requests tie whatever order SQLite sums in.
_SCORE_DECIMALS = 9
# Rows read per step when an old file is upgraded (its requests indexed).
_UPGRADE_BATCH = 500
# Pause between tries to switch a file to WAL while another connection holds it: short, as the switch is.
_WAL_RETRY_PAUSE_S = 0.01
# The key of the all-sessions row of corpus_stats (session ids are never empty).
_ALL = ""
# SQLite result codes that mean "someone else holds the lock": the only ones worth waiting out.
_BUSY = frozenset({"SQLITE_BUSY", "SQLITE_LOCKED", "SQLITE_BUSY_RECOVERY", "SQLITE_BUSY_SNAPSHOT"})

_TABLES = """
CREATE TABLE IF NOT EXISTS sessions (
    id        TEXT PRIMARY KEY,
    created_s REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS interactions (
    id             INTEGER PRIMARY KEY AUTOINCREMENT,
    session_id     TEXT NOT NULL REFERENCES sessions(id),
    request        TEXT NOT NULL,
    program        TEXT NOT NULL,
    feedback       TEXT NOT NULL,
    score          REAL CHECK (score IS NULL OR (score >= 0 AND score <= 10)),
    created_s      REAL NOT NULL,
    request_tokens INTEGER NOT NULL DEFAULT 0,
    source         TEXT NOT NULL DEFAULT 'llm' CHECK (source IN ('llm', 'repair'))
);
CREATE INDEX IF NOT EXISTS interactions_by_session ON interactions(session_id, id);
CREATE TABLE IF NOT EXISTS embeddings (
    interaction_id INTEGER NOT NULL REFERENCES interactions(id) ON DELETE CASCADE,
    model          TEXT NOT NULL,
    dim            INTEGER NOT NULL CHECK (dim > 0),
    vector         BLOB NOT NULL,
    created_s      REAL NOT NULL,
    PRIMARY KEY (interaction_id, model)
);
CREATE INDEX IF NOT EXISTS embeddings_by_model ON embeddings(model, dim);
"""

# Added in version 2 (created by a fresh file as well as by the upgrade of a version-1 file).
_INDEX_TABLES = """
CREATE TABLE IF NOT EXISTS request_terms (
    term           TEXT NOT NULL,
    interaction_id INTEGER NOT NULL REFERENCES interactions(id) ON DELETE CASCADE,
    session_id     TEXT NOT NULL,
    tf             INTEGER NOT NULL CHECK (tf > 0),
    PRIMARY KEY (term, interaction_id)
) WITHOUT ROWID;
CREATE INDEX IF NOT EXISTS request_terms_by_session ON request_terms(session_id, term);
CREATE TABLE IF NOT EXISTS corpus_stats (
    session_id TEXT PRIMARY KEY,
    documents  INTEGER NOT NULL,
    tokens     INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS embeddings_by_space ON embeddings(model, dim, interaction_id);
"""

_COLUMNS = "id, session_id, request, program, feedback, score, created_s, source"
# Added in version 3 to a file that has the interactions table without it (older rows: the model's).
_SOURCE_COLUMN = (
    "ALTER TABLE interactions ADD COLUMN source TEXT NOT NULL DEFAULT 'llm' CHECK (source IN ('llm', 'repair'))"
)


class InteractionMemoryError(RoboCriticsError, ValueError):
    """The interaction memory cannot do what was asked: its file is unusable (corrupt, read-only, in a
    directory that cannot be created, locked too long, on a full disk) or an argument is invalid.

    ``path`` is the database file.
    """

    def __init__(self, message: str, path: str = ""):
        self.path = path
        super().__init__(message)


@dataclass(frozen=True)
class Interaction:
    """One stored attempt: what was asked, the program written, what the critics said.

    ``score`` is the 0–10 quality index or None if the program was not
    critiqued; ``created_s`` is unix time in seconds; ``source`` who wrote the
    program (:data:`SOURCES`: ``"llm"`` or ``"repair"``).
    """

    id: int
    session: str
    request: str
    program: str
    feedback: str
    score: float | None
    created_s: float
    source: str = "llm"


def _query_terms(text: str) -> list[str]:
    """The distinct BM25 words of a query, in order of first appearance, at most ``MAX_QUERY_TERMS``."""
    return list(dict.fromkeys(tokenize(text[:MAX_TASK_CHARS])))[:MAX_QUERY_TERMS]


def _document_terms(request: str) -> Counter[str]:
    """The BM25 words of a stored request (its first ``MAX_TASK_CHARS`` characters) and their counts."""
    return Counter(tokenize(request[:MAX_TASK_CHARS]))


class InteractionMemory:
    """Stores interactions in SQLite at ``path`` and retrieves similar ones.

    ``path`` is a file path (created if missing, parent directory included) or
    ``":memory:"`` for a private in-process database. ``embedder`` (an
    ``EmbeddingModel``, e.g. ``OpenAICompatible`` with an embedding model)
    switches ``search`` from BM25 to cosine similarity; it may be replaced at
    any time by assigning ``memory.embedder``. ``busy_timeout_s`` is how long a
    write waits for another writer (seconds) before failing; ``statement_timeout_s``
    how long one statement or write transaction may run (seconds) before it is
    interrupted (a hostile or damaged file must not hang the caller).
    ``embed_batch_size`` texts are embedded per call of the embedder, and
    ``scan_batch_size`` stored vectors compared per step of a search.

    Use as a context manager or call ``close()``. Every failure is an
    :class:`InteractionMemoryError` (see the module docstring).
    """

    def __init__(
        self,
        path: str | os.PathLike[str] = ":memory:",
        embedder: EmbeddingModel | None = None,
        *,
        busy_timeout_s: float = DEFAULT_BUSY_TIMEOUT_S,
        statement_timeout_s: float = guard.DEFAULT_STATEMENT_TIMEOUT_S,
        embed_batch_size: int = 64,
        scan_batch_size: int = DEFAULT_SCAN_BATCH_SIZE,
    ):
        raw_path = os.fspath(path) if isinstance(path, os.PathLike) else path
        self.path = clean_text(raw_path) if isinstance(raw_path, str) else repr(raw_path)
        if not isinstance(raw_path, str) or not raw_path or "\x00" in raw_path:
            raise self._error(f"path must be a file path or ':memory:', got {self.path!r:.80}")
        for name, value in (("embed_batch_size", embed_batch_size), ("scan_batch_size", scan_batch_size)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise self._error(f"{name} must be a whole number >= 1, got {value!r}")
        if not (isinstance(busy_timeout_s, (int, float)) and math.isfinite(busy_timeout_s) and busy_timeout_s >= 0):
            raise self._error(f"busy_timeout_s must be a finite number of seconds >= 0, got {busy_timeout_s!r}")
        timeout = statement_timeout_s
        if isinstance(timeout, bool) or not (isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0):
            raise self._error(f"statement_timeout_s must be a finite number of seconds > 0, got {timeout!r:.40}")
        self.statement_timeout_s = float(statement_timeout_s)
        self._deadline: guard.Deadline | None = None
        self.embedder = embedder
        self.busy_timeout_s = float(busy_timeout_s)
        self.embed_batch_size = int(embed_batch_size)
        self.scan_batch_size = int(scan_batch_size)
        self._in_memory = self.path == ":memory:" or self.path.startswith("file::memory:")
        self._lock = threading.RLock()
        self._conn: sqlite3.Connection | None = None
        self._pid = os.getpid()
        self._closed = False
        if not self._in_memory:
            self._check_path()
        self._connection()  # open and create the schema now, so a bad path fails here

    def __repr__(self) -> str:
        name = embedding_space_name(self.embedder) if self.embedder is not None else None
        return f"InteractionMemory(path={self.path!r}, embedder={name!r})"

    # -- errors --------------------------------------------------------------

    def _error(self, message: str) -> InteractionMemoryError:
        return InteractionMemoryError(message, self.path)

    def _advice(self, exc: sqlite3.Error) -> str:
        """What an SQLite failure means for the user, from its result code."""
        code = getattr(exc, "sqlite_errorname", "") or ""
        if code.startswith(("SQLITE_CORRUPT", "SQLITE_NOTADB")):
            return "the file is damaged or not a database: restore it from a backup, or move it away to start afresh"
        if code.startswith("SQLITE_READONLY"):
            return "the file or its directory is read-only: make both writable, or use another path"
        if code in _BUSY:
            return f"another connection held the write lock for more than busy_timeout_s={self.busy_timeout_s:g} s"
        if code == "SQLITE_INTERRUPT":
            return (f"it ran longer than statement_timeout_s={self.statement_timeout_s:g} s: the file is damaged, "
                    "hostile or far larger than expected")  # fmt: skip
        if code == "SQLITE_TOOBIG":
            return f"the file holds a value larger than {guard.MAX_VALUE_BYTES:,} bytes, which robocritics never stores"
        if code.startswith("SQLITE_FULL"):
            return "the disk is full"
        if code.startswith("SQLITE_CANTOPEN"):
            return "the file cannot be opened or created there: check the path and its permissions"
        if code.startswith("SQLITE_IOERR"):
            return "the file system reported an I/O error"
        return "SQLite refused the operation"

    def _failure(self, exc: sqlite3.Error, doing: str) -> InteractionMemoryError:
        """An SQLite failure while ``doing`` something, in words the user can act on."""
        return self._error(f"interaction memory {self.path!r}: {doing} failed: {exc} ({self._advice(exc)})")

    @contextmanager
    def _sqlite(self, doing: str) -> Iterator[None]:
        try:
            yield
        except sqlite3.Error as exc:
            raise self._failure(exc, doing) from exc

    @contextmanager
    def _contract(self) -> Iterator[None]:
        """A stored value out of its column's contract (a ``ValueError`` of :mod:`.memory_guard`) as an
        :class:`InteractionMemoryError`: the file was not written by robocritics, or was changed since."""
        try:
            yield
        except ValueError as exc:
            if isinstance(exc, InteractionMemoryError):
                raise
            raise self._error(f"interaction memory {self.path!r} holds a value robocritics never stores: {exc} "
                              "(the file was changed by something else; move it away to start afresh)") from None  # fmt: skip

    def _check_path(self) -> None:
        """Fail at once, with the reason, for a path the memory could not be written at."""
        path = Path(self.path)
        where = f"interaction memory {self.path!r}"
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise self._error(
                f"{where} cannot be opened: its directory {str(path.parent)!r} cannot be created "
                f"({exc.strerror or exc})"
            ) from None
        if not path.parent.is_dir():
            raise self._error(f"{where} cannot be opened: {str(path.parent)!r} is not a directory")
        for companion in (path, *(path.with_name(path.name + end) for end in ("-wal", "-shm", "-journal"))):
            try:
                info = os.lstat(companion)
                mode = info.st_mode
            except FileNotFoundError:
                continue
            except OSError as exc:
                raise self._error(f"{where} cannot be opened: {str(companion)!r}: {exc.strerror or exc}") from None
            if stat.S_ISLNK(mode):
                raise self._error(f"{where} cannot be opened: {str(companion)!r} is a symbolic link; robocritics "
                                  "does not write through links: use the file itself")  # fmt: skip
            if stat.S_ISDIR(mode) and companion == path:
                raise self._error(f"{where} cannot be opened: it is a directory, not a file")
            if not stat.S_ISREG(mode):
                raise self._error(f"{where} cannot be opened: {str(companion)!r} is not a regular file")
            if info.st_nlink > 1:  # a hard link: writing it would change another file too
                raise self._error(f"{where} cannot be opened: {str(companion)!r} has {info.st_nlink} hard links; "
                                  "copy it to a file of its own")  # fmt: skip
        if path.exists() and not os.access(path, os.R_OK | os.W_OK):
            raise self._error(
                f"{where} cannot be opened: the file is read-only (no read and write permission): make it "
                "writable, or use another path"
            )
        if not os.access(path.parent, os.W_OK | os.X_OK):
            # SQLite creates the file and its -wal and -shm companions next to it.
            raise self._error(
                f"{where} cannot be opened: its directory {str(path.parent)!r} is read-only (SQLite keeps its "
                "journal files beside the database): make it writable, or use another path"
            )
        try:  # a new file is created here, exclusively: O_EXCL refuses anything at the name, a link included
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666))
        except FileExistsError:
            pass  # the existing regular file checked above (or one another process has just created)
        except OSError as exc:
            raise self._error(f"{where} cannot be created: {exc.strerror or exc}") from None

    # -- connection ---------------------------------------------------------

    def _connection(self) -> sqlite3.Connection:
        if self._closed:
            raise self._error(f"interaction memory {self.path!r} is closed")
        if self._conn is not None and self._pid == os.getpid():
            return self._conn
        # First use, or first use in a forked child: never reuse a parent's connection.
        self._pid = os.getpid()
        try:
            self._conn = self._open()
        except sqlite3.Error as exc:
            self._conn = None
            raise self._error(
                f"interaction memory {self.path!r} cannot be opened: {exc} ({self._advice(exc)})"
            ) from exc
        except ValueError as exc:  # a value out of contract met while upgrading an older file
            self._conn = None
            if isinstance(exc, InteractionMemoryError):
                raise
            raise self._error(f"interaction memory {self.path!r} cannot be opened: it holds a value robocritics never "
                              f"stores: {exc}") from None  # fmt: skip
        return self._conn

    def _open(self) -> sqlite3.Connection:
        conn = sqlite3.connect(self.path, timeout=self.busy_timeout_s, isolation_level=None, check_same_thread=False)
        try:
            guard.limit(conn)
            self._deadline = guard.Deadline(conn, self.statement_timeout_s)
            self._deadline.start()  # opening (and upgrading) is bounded like any statement
            conn.execute(f"PRAGMA busy_timeout = {int(self.busy_timeout_s * 1000)}")
            conn.execute("PRAGMA foreign_keys = ON")
            if not self._in_memory:
                self._enable_wal(conn)
                conn.execute("PRAGMA synchronous = FULL")
            conn.execute("BEGIN IMMEDIATE")
            try:
                version = conn.execute("PRAGMA user_version").fetchone()[0]
                self._check_schema(conn, complete=version >= SCHEMA_VERSION)
                if version > SCHEMA_VERSION:
                    raise self._error(
                        f"interaction memory {self.path!r} cannot be opened: its schema version {version} is newer "
                        f"than this robocritics understands ({SCHEMA_VERSION}); upgrade robocritics"
                    )
                if version < SCHEMA_VERSION:
                    _executescript(conn, _TABLES)
                    if version == 1:
                        _upgrade_from_1(conn)
                    _executescript(conn, _INDEX_TABLES)
                    columns = {row[1] for row in conn.execute("PRAGMA table_info(interactions)")}
                    if "source" not in columns:  # versions 1 and 2 (a fresh file was created with it)
                        conn.execute(_SOURCE_COLUMN)
                    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
                    self._check_schema(conn, complete=True)
                conn.execute("COMMIT")
            except BaseException:
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                raise
        except BaseException:
            conn.close()
            raise
        return conn

    def _check_schema(self, conn: sqlite3.Connection, complete: bool) -> None:
        """Refuse a file whose schema is not robocritics': any object but our tables and indexes (a trigger, a
        view, a virtual table), and once ``complete`` (the current version), any table or index of another shape."""
        where = f"interaction memory {self.path!r} cannot be opened"
        foreign = guard.foreign_objects(conn, set(_reference_layout()), _INDEX_NAMES)
        if foreign:
            more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
            raise self._error(f"{where}: its schema holds {', '.join(foreign[:3])}{more}, which robocritics never "
                              "creates (a trigger or view would run on every read or write): move the file away, or "
                              "remove them")  # fmt: skip
        if complete:
            reference = _reference_layout()
            found = guard.layout(conn, list(reference))
            wrong = [table for table in reference if found[table] != reference[table]]
            if wrong:
                raise self._error(f"{where}: its table {wrong[0]!r} (or its indexes) is not the one robocritics "
                                  "creates: move the file away to start afresh")  # fmt: skip

    def _enable_wal(self, conn: sqlite3.Connection) -> None:
        """Switch the file to WAL; retried only while another connection holds the file (a busy lock)."""
        deadline = time.monotonic() + self.busy_timeout_s
        while True:
            try:
                mode = conn.execute("PRAGMA journal_mode = WAL").fetchone()[0]
                if str(mode).lower() != "wal":
                    raise self._error(
                        f"interaction memory {self.path!r} cannot be opened: WAL journaling could not be enabled "
                        f"(the journal mode is {mode!r})"
                    )
                return
            except sqlite3.OperationalError as exc:
                if getattr(exc, "sqlite_errorname", "") not in _BUSY or time.monotonic() > deadline:
                    raise
                time.sleep(_WAL_RETRY_PAUSE_S)

    @contextmanager
    def _write(self, doing: str = "writing") -> Iterator[sqlite3.Connection]:
        """One write transaction: BEGIN IMMEDIATE, COMMIT on success, ROLLBACK on any exception."""
        with self._lock:
            conn = self._connection()
            with self._sqlite(doing):
                self._start_deadline()  # the whole transaction: a write is a few statements
                conn.execute("BEGIN IMMEDIATE")
                try:
                    yield conn
                    conn.execute("COMMIT")
                except BaseException:
                    if conn.in_transaction:
                        conn.execute("ROLLBACK")
                    raise

    def _read(self, sql: str, parameters: Sequence[object] = (), doing: str = "reading") -> list[tuple]:
        with self._lock:
            conn = self._connection()
            with self._sqlite(doing):
                self._start_deadline()
                return conn.execute(sql, parameters).fetchall()

    def _start_deadline(self) -> None:
        if self._deadline is not None:
            self._deadline.start()

    def close(self) -> None:
        """Close the database connection (idempotent). Later calls raise ``InteractionMemoryError``."""
        with self._lock:
            if self._conn is not None and self._pid == os.getpid():
                try:
                    self._conn.close()
                except sqlite3.Error:  # nothing to save: every write committed or rolled back
                    pass
            self._conn = None
            self._closed = True

    def __enter__(self) -> InteractionMemory:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- writing and reading interactions -------------------------------------

    @staticmethod
    def new_session_id() -> str:
        """A fresh random session id (32 hex characters)."""
        return uuid.uuid4().hex

    def add(
        self,
        session: str,
        request: str,
        program: str,
        feedback: str = "",
        score: float | None = None,
        *,
        source: str = "llm",
    ) -> int:
        """Store one interaction in ``session`` (created if new); return its id.

        ``score`` must be within 0–10 or None; ``source`` one of :data:`SOURCES`
        (who wrote the program). Texts are cleaned of lone
        surrogates and cut to their limits (module docstring). Ids increase in
        commit order, across threads and processes. Raises
        ``InteractionMemoryError`` (a ``ValueError``) for invalid values.
        """
        if not isinstance(session, str) or not session:
            raise self._error("session must be a non-empty string")
        if len(session) > 200:
            raise self._error(f"session must be at most 200 characters, got {len(session)}")
        for label, text in (("request", request), ("program", program), ("feedback", feedback)):
            if not isinstance(text, str):
                raise self._error(f"{label} must be a string, got {type(text).__name__}")
        if source not in SOURCES:
            raise self._error(f"source must be one of {', '.join(SOURCES)}, got {source!r:.40}")
        if score is not None:
            try:
                score = float(score)
            except (TypeError, ValueError):
                raise self._error(f"score must be a number within 0-10 or None, got {score!r:.40}") from None
            if not 0.0 <= score <= 10.0:  # also rejects NaN
                raise self._error(f"score must be within 0-10 (the program quality index), got {score}")
        session = clean_text(session)
        request = cut_text(clean_text(request), MAX_TASK_CHARS)
        program = cut_text(clean_text(program), MAX_STORED_PROGRAM_CHARS)
        feedback = cut_text(clean_text(feedback), MAX_STORED_FEEDBACK_CHARS)
        terms = _document_terms(request)
        tokens = sum(terms.values())
        now = time.time()
        with self._write("storing an interaction") as conn:
            conn.execute("INSERT OR IGNORE INTO sessions (id, created_s) VALUES (?, ?)", (session, now))
            cursor = conn.execute(
                "INSERT INTO interactions (session_id, request, program, feedback, score, created_s, request_tokens, "
                "source) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (session, request, program, feedback, score, now, tokens, source),
            )
            assert cursor.lastrowid is not None  # an INSERT always sets it
            interaction_id = int(cursor.lastrowid)
            _index(conn, interaction_id, session, terms)
            return interaction_id

    def get(self, interaction_id: int) -> Interaction:
        """The interaction with this id; ``KeyError`` if there is none."""
        if isinstance(interaction_id, bool) or not isinstance(interaction_id, (int, np.integer)):
            raise self._error(f"interaction ids are whole numbers, got {interaction_id!r:.40}")
        rows = self._read(f"SELECT {_COLUMNS} FROM interactions WHERE id = ?", (int(interaction_id),))
        if not rows:
            raise KeyError(f"no interaction with id {interaction_id} in {self.path!r}")
        with self._contract():
            return _interaction(rows[0])

    def history(self, session: str) -> list[Interaction]:
        """Every interaction of ``session``, oldest first ([] for an unknown session)."""
        if not isinstance(session, str):
            raise self._error(f"session must be a string, got {type(session).__name__}")
        rows = self._read(
            f"SELECT {_COLUMNS} FROM interactions WHERE session_id = ? ORDER BY id", (session,), "reading a session"
        )
        with self._contract():
            return [_interaction(r) for r in rows]

    def sessions(self) -> list[str]:
        """Every session id, in order of creation."""
        rows = self._read("SELECT id FROM sessions ORDER BY created_s, rowid")
        with self._contract():
            return [guard.text(r[0], "sessions.id", guard.MAX_SESSION_CHARS, 1) for r in rows]

    def __len__(self) -> int:
        return int(self._read("SELECT COUNT(*) FROM interactions")[0][0])

    def _fetch(self, ids: Sequence[int]) -> dict[int, Interaction]:
        """The interactions with these ids (at most ``MAX_SEARCH_K``), by id."""
        if not ids:
            return {}
        marks = ",".join("?" * len(ids))
        rows = self._read(f"SELECT {_COLUMNS} FROM interactions WHERE id IN ({marks})", list(ids), "searching")
        with self._contract():
            return {i.id: i for i in map(_interaction, rows)}

    # -- retrieval -------------------------------------------------------------

    def search(self, query: str, k: int = 3, session: str | None = None) -> list[Interaction]:
        """The ``k`` interactions whose requests are most similar to ``query``, best first.

        Limited to ``session`` when given. See the module docstring for how
        similarity is measured with and without an embedder.
        """
        return [interaction for interaction, _ in self.search_scored(query, k, session)]

    def search_scored(self, query: str, k: int = 3, session: str | None = None) -> list[tuple[Interaction, float]]:
        """Like ``search``, with each result's similarity: cosine (−1…1) or BM25 score (> 0).

        ``k`` is at most ``MAX_SEARCH_K``.
        """
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
            raise self._error(f"k must be a whole number, got {k!r:.40}")
        if k < 0:
            raise self._error(f"k must be >= 0, got {k}")
        if k > MAX_SEARCH_K:
            raise self._error(f"k must be at most {MAX_SEARCH_K} (MAX_SEARCH_K), got {k}")
        if not isinstance(query, str):
            raise self._error(f"query must be a string, got {type(query).__name__}")
        if session is not None and not isinstance(session, str):
            raise self._error(f"session must be a string or None, got {type(session).__name__}")
        query = clean_text(query[:MAX_TASK_CHARS])
        if k == 0 or self._count(session) == 0:
            return []  # nothing to compare with: not even the query is embedded
        if self.embedder is None:
            ranked = self._bm25_top(query, int(k), session)
        else:
            ranked = self._cosine_top(query, int(k), session)
        found = self._fetch([i for i, _ in ranked])
        return [(found[i], score) for i, score in ranked if i in found]

    def _stats(self, session: str | None) -> tuple[int, int]:
        """(interactions, BM25 words of their requests) of ``session``, or of all sessions for None."""
        key = _ALL if session is None else session
        rows = self._read("SELECT documents, tokens FROM corpus_stats WHERE session_id = ?", (key,), "searching")
        if not rows:
            return (0, 0)
        with self._contract():
            return (guard.whole(rows[0][0], "corpus_stats.documents"), guard.whole(rows[0][1], "corpus_stats.tokens"))

    def _count(self, session: str | None) -> int:
        return self._stats(session)[0]

    def _bm25_top(self, query: str, k: int, session: str | None) -> list[tuple[int, float]]:
        """The ``k`` best (id, BM25 score > 0), computed in SQLite from the inverted index."""
        terms = _query_terms(query)
        if not terms:
            return []
        documents, tokens = self._stats(session)
        if documents == 0:
            return []
        mean_length = tokens / documents if tokens > 0 else 1.0
        marks = ",".join("?" * len(terms))
        if session is None:
            counts = self._read(
                f"SELECT term, COUNT(*) FROM request_terms WHERE term IN ({marks}) GROUP BY term", terms, "searching"
            )
        else:
            counts = self._read(
                f"SELECT term, COUNT(*) FROM request_terms WHERE session_id = ? AND term IN ({marks}) GROUP BY term",
                [session, *terms],
                "searching",
            )
        idf = {t: math.log(1.0 + (documents - n + 0.5) / (n + 0.5)) for t, n in counts if n > 0}
        if not idf:
            return []
        values = ",".join("(?, ?)" for _ in idf)
        parameters: list[object] = [x for pair in idf.items() for x in pair]
        where = ""
        if session is not None:
            where = "WHERE p.session_id = ?"
            parameters.append(session)
        sql = (
            f"WITH q(term, idf) AS (VALUES {values}) "
            "SELECT p.interaction_id, SUM(q.idf * p.tf * (? + 1.0) / (p.tf + ? * (1.0 - ? + ? * i.request_tokens / ?))) "
            "AS relevance FROM q JOIN request_terms p ON p.term = q.term JOIN interactions i ON i.id = p.interaction_id "
            f"{where} GROUP BY p.interaction_id ORDER BY ROUND(relevance, ?) DESC, p.interaction_id DESC LIMIT ?"
        )
        # The BM25 constants come after the VALUES and before the session in the statement's order of "?".
        head = parameters[: 2 * len(idf)]
        tail = parameters[2 * len(idf) :]
        bound = [*head, _BM25_K1, _BM25_K1, _BM25_B, _BM25_B, mean_length, *tail, _SCORE_DECIMALS, k]
        rows = self._read(sql, bound, "searching")
        with self._contract():  # a score of text, a negative or missing count makes the sum NULL or not finite
            what = "a BM25 score of request_terms.tf and interactions.request_tokens"
            ranked = [(guard.whole(i, "request_terms.interaction_id", 1), guard.finite(s, what)) for i, s in rows]
        return [(i, score) for i, score in ranked if score > 0]

    def _cosine_top(self, query: str, k: int, session: str | None) -> list[tuple[int, float]]:
        """The ``k`` best (id, cosine similarity) with the current embedder's vectors, read in batches.

        Interactions without a vector of this model name and of the query's
        length are embedded first and their vectors stored (replacing any
        stale vector of the same model name but another length).
        """
        assert self.embedder is not None
        name = embedding_space_name(self.embedder)
        query_vector = self._embed([query])[0]
        dim = int(query_vector.shape[0])
        self._embed_backlog(name, session, dim)
        query_norm = float(np.linalg.norm(query_vector))
        best_ids = np.zeros(0, dtype=np.int64)
        best_sims = np.zeros(0)
        last = 0
        join = " JOIN interactions i ON i.id = e.interaction_id" if session is not None else ""
        condition = " AND i.session_id = ?" if session is not None else ""
        while True:
            parameters: list[object] = [name, dim, last]
            if session is not None:
                parameters.append(session)
            rows = self._read(
                f"SELECT e.interaction_id, e.vector FROM embeddings e{join} "
                f"WHERE e.model = ? AND e.dim = ? AND e.interaction_id > ?{condition} "
                "ORDER BY e.interaction_id LIMIT ?",
                [*parameters, self.scan_batch_size],
                "searching",
            )
            if not rows:
                break
            with self._contract():
                ids = np.fromiter((guard.whole(r[0], "embeddings.interaction_id", 1) for r in rows), dtype=np.int64,
                                  count=len(rows))  # fmt: skip
                matrix = _vectors([r[1] for r in rows], dim)
            norms = np.linalg.norm(matrix, axis=1) * query_norm
            dots = matrix @ query_vector
            sims = np.divide(dots, norms, out=np.zeros_like(dots), where=norms > 0)
            ids = np.concatenate([best_ids, ids])
            sims = np.concatenate([best_sims, sims])
            keep = np.lexsort((-ids, -sims))[:k]  # best similarity first, then newest
            best_ids, best_sims = ids[keep], sims[keep]
            last = int(rows[-1][0])
        return [(int(i), float(s)) for i, s in zip(best_ids, best_sims, strict=True)]

    def embed_missing(self, session: str | None = None) -> int:
        """Embed and store every interaction (of ``session``) that has no vector from the current embedder.

        Returns how many were embedded. ``search`` does this lazily; call it
        to pay the cost up front. Raises ``InteractionMemoryError`` without an embedder.
        """
        if self.embedder is None:
            raise self._error("embed_missing needs an embedder")
        return self._embed_backlog(embedding_space_name(self.embedder), session, None)

    def _embed_backlog(self, name: str, session: str | None, dim: int | None) -> int:
        """Embed, ``embed_batch_size`` at a time, the interactions lacking a vector of model ``name``
        (of length ``dim``; any length when None); return how many."""
        done = 0
        last = 0
        while True:
            parameters: list[object] = [last]
            sql = "SELECT i.id, i.request FROM interactions i WHERE i.id > ?"
            if session is not None:
                sql += " AND i.session_id = ?"
                parameters.append(session)
            sql += " AND NOT EXISTS (SELECT 1 FROM embeddings e WHERE e.interaction_id = i.id AND e.model = ?"
            parameters.append(name)
            if dim is not None:
                sql += " AND e.dim = ?"
                parameters.append(dim)
            sql += ") ORDER BY i.id LIMIT ?"
            parameters.append(self.embed_batch_size)
            rows = self._read(sql, parameters, "finding interactions to embed")
            if not rows:
                return done
            with self._contract():
                batch = [(guard.whole(r[0], "interactions.id", 1), guard.text(r[1], "interactions.request", MAX_TASK_CHARS))
                         for r in rows]  # fmt: skip
            dim = self._embed_and_store(name, batch, dim)
            done += len(rows)
            last = int(rows[-1][0])

    def _embed_and_store(self, name: str, batch: list[tuple[int, str]], dim: int | None) -> int:
        """Embed the requests of one batch of (id, request) and store the vectors in one transaction.

        All vectors must have length ``dim`` (the batch's own when None); returns that length.
        """
        vectors = self._embed([request for _, request in batch])
        if dim is None:
            dim = int(vectors.shape[1])
        if vectors.shape[1] != dim:
            raise LLMError(
                f"embedding model {name!r} returned vectors of length {vectors.shape[1]}, "
                f"but of length {dim} for other texts"
            )
        now = time.time()
        with self._write("storing embeddings") as conn:
            conn.executemany(
                "INSERT OR REPLACE INTO embeddings (interaction_id, model, dim, vector, created_s) "
                "SELECT ?, ?, ?, ?, ? WHERE EXISTS (SELECT 1 FROM interactions WHERE id = ?)",
                [
                    (i, name, dim, np.asarray(v, dtype="<f8").tobytes(), now, i)
                    for (i, _), v in zip(batch, vectors, strict=True)
                ],
            )
        return dim

    def _embed(self, texts: list[str]) -> np.ndarray:
        """Call the embedder and check it kept its promise: finite floats of shape (len(texts), d)."""
        assert self.embedder is not None
        returned = self.embedder.embed(texts)
        try:
            vectors = np.asarray(returned, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise LLMError(
                f"embedder {embedding_space_name(self.embedder)!r} returned something that is not an array of "
                f"numbers ({exc})"
            ) from None
        if vectors.ndim != 2 or vectors.shape[0] != len(texts) or vectors.shape[1] == 0:
            raise LLMError(
                f"embedder {embedding_space_name(self.embedder)!r} returned shape {vectors.shape} "
                f"for {len(texts)} texts; expected ({len(texts)}, d)"
            )
        if not np.all(np.isfinite(vectors)):
            raise LLMError(f"embedder {embedding_space_name(self.embedder)!r} returned non-finite values")
        return vectors


def _executescript(conn: sqlite3.Connection, script: str) -> None:
    """Run ``;``-separated statements inside the current transaction (``executescript`` would commit it)."""
    for statement in script.split(";"):
        if statement.strip():
            conn.execute(statement)


def _index(conn: sqlite3.Connection, interaction_id: int, session: str, terms: Counter[str]) -> None:
    """Add one request to the inverted index and the corpus counts (inside the caller's transaction)."""
    conn.executemany(
        "INSERT INTO request_terms (term, interaction_id, session_id, tf) VALUES (?, ?, ?, ?)",
        [(term, interaction_id, session, tf) for term, tf in terms.items()],
    )
    tokens = sum(terms.values())
    conn.executemany(
        "INSERT INTO corpus_stats (session_id, documents, tokens) VALUES (?, 1, ?) "
        "ON CONFLICT(session_id) DO UPDATE SET documents = documents + 1, tokens = tokens + excluded.tokens",
        [(_ALL, tokens), (session, tokens)],
    )


def _upgrade_from_1(conn: sqlite3.Connection) -> None:
    """Version 1 → 2, inside the caller's transaction: count and index every stored request."""
    conn.execute("ALTER TABLE interactions ADD COLUMN request_tokens INTEGER NOT NULL DEFAULT 0")
    _executescript(conn, _INDEX_TABLES)
    last = 0
    while True:
        rows = conn.execute(
            "SELECT id, session_id, request FROM interactions WHERE id > ? ORDER BY id LIMIT ?", (last, _UPGRADE_BATCH)
        ).fetchall()
        if not rows:
            return
        for interaction_id, session, request in rows:
            terms = _document_terms(guard.text(request, f"interaction {interaction_id!r:.20}: request", MAX_TASK_CHARS))
            conn.execute(
                "UPDATE interactions SET request_tokens = ? WHERE id = ?", (sum(terms.values()), interaction_id)
            )
            _index(conn, interaction_id, session, terms)
        last = int(rows[-1][0])


def _interaction(row: tuple) -> Interaction:
    """An ``interactions`` row as an Interaction; ValueError naming the column if a value is out of contract."""
    row_id, session, request, program, feedback, score, created_s, source = guard.checked_interaction(row, SOURCES)
    return Interaction(row_id, session, request, program, feedback, score, created_s, source)


def _vectors(blobs: list[object], dim: int) -> np.ndarray:
    """Stored embedding blobs as a ``(len(blobs), dim)`` matrix; ValueError unless each is ``dim`` finite float64s."""
    for blob in blobs:
        if not isinstance(blob, bytes) or len(blob) != 8 * dim:
            raise ValueError(f"embeddings.vector holds {guard.shown(blob)}, not {dim} float64 values ({8 * dim} bytes)")
    matrix = np.frombuffer(b"".join(blobs), dtype="<f8").reshape(len(blobs), dim)  # type: ignore[arg-type]
    if not np.isfinite(matrix).all():
        raise ValueError("embeddings.vector holds a value that is not finite")
    return matrix


@functools.cache
def _reference_layout() -> dict[str, object]:
    """The layout (:func:`~robocritics.llm.memory_guard.layout`) of a file this version creates: what every opened
    file's schema must equal."""
    conn = sqlite3.connect(":memory:")
    try:
        _executescript(conn, _TABLES)
        _executescript(conn, _INDEX_TABLES)
        tables = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table' AND name != "
                                             "'sqlite_sequence' ORDER BY name")]  # fmt: skip
        return guard.layout(conn, tables)
    finally:
        conn.close()


# Our indexes' names (an automatic index of a table's keys is SQLite's, and allowed by name pattern).
_INDEX_NAMES = {"interactions_by_session", "embeddings_by_model", "request_terms_by_session", "embeddings_by_space"}
