"""Interaction memory: (request, program, critic feedback, score) tuples in SQLite, with retrieval.

Step 4 of the RoboCritics workflow stores each attempt; step 5 retrieves
similar past attempts so the model can refine instead of starting over.

Storage (one SQLite file, or ``":memory:"``):

* ``sessions(id, created_s)`` — one row per conversation / task run.
* ``interactions(id, session_id, request, program, feedback, score, created_s)``
  — ``score`` is the 0–10 program quality index (NULL when the program was
  never critiqued, e.g. it failed to parse); times are unix seconds.
* ``embeddings(interaction_id, model, dim, vector, created_s)`` — one vector per
  interaction *per embedding model*, tagged with the model's name and length.

Retrieval (``search``) ranks by the request text:

* With an ``embedder``: cosine similarity between the query's vector and the
  stored vectors **of the current embedder's name and dimension only** —
  vectors from any other model are never compared. Interactions lacking a
  vector for the current model are embedded lazily, by ``search`` (or ahead of
  time by ``embed_missing``), and the vectors are stored for next time;
  ``add`` never calls the embedder, so storing works while the embedding
  server is down.
* Without one: BM25 (``llm.bm25``) over the request texts; interactions that
  share no word with the query are not returned.

Ties go to the newer interaction.

Concurrency and durability: file databases run in WAL mode with
``synchronous=FULL`` and a busy timeout; every write is one ``BEGIN
IMMEDIATE`` … ``COMMIT`` transaction, so several threads (sharing one
instance, which serialises on a lock, or holding their own) and several
processes can write to one file, and a writer killed at any moment loses
nothing that was committed and leaves no partial row. An instance inherited
through ``fork`` opens its own connection in the child.
"""

from __future__ import annotations

import os
import sqlite3
import threading
import time
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocritics.errors import LLMError, RoboCriticsError
from robocritics.llm.bm25 import bm25_scores
from robocritics.llm.client import EmbeddingModel, embedding_space_name

__all__ = ["Interaction", "InteractionMemory"]

SCHEMA_VERSION = 1

# Pause between tries to switch a file to WAL while another connection holds it: short, as the switch is.
_WAL_RETRY_PAUSE_S = 0.01

_SCHEMA = """
CREATE TABLE IF NOT EXISTS sessions (
    id        TEXT PRIMARY KEY,
    created_s REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS interactions (
    id         INTEGER PRIMARY KEY AUTOINCREMENT,
    session_id TEXT NOT NULL REFERENCES sessions(id),
    request    TEXT NOT NULL,
    program    TEXT NOT NULL,
    feedback   TEXT NOT NULL,
    score      REAL CHECK (score IS NULL OR (score >= 0 AND score <= 10)),
    created_s  REAL NOT NULL
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

_COLUMNS = "id, session_id, request, program, feedback, score, created_s"


@dataclass(frozen=True)
class Interaction:
    """One stored attempt: what was asked, the program written, what the critics said.

    ``score`` is the 0–10 quality index or None if the program was not
    critiqued; ``created_s`` is unix time in seconds.
    """

    id: int
    session: str
    request: str
    program: str
    feedback: str
    score: float | None
    created_s: float


class InteractionMemory:
    """Stores interactions in SQLite at ``path`` and retrieves similar ones.

    ``path`` is a file path (created if missing, parent directory included) or
    ``":memory:"`` for a private in-process database. ``embedder`` (an
    ``EmbeddingModel``, e.g. ``OpenAICompatible`` with an embedding model)
    switches ``search`` from BM25 to cosine similarity; it may be replaced at
    any time by assigning ``memory.embedder``. ``busy_timeout_s`` is how long a
    write waits for another writer (seconds) before failing.

    Use as a context manager or call ``close()``.
    """

    def __init__(
        self,
        path: str | os.PathLike[str] = ":memory:",
        embedder: EmbeddingModel | None = None,
        *,
        busy_timeout_s: float = 30.0,
        embed_batch_size: int = 64,
    ):
        if embed_batch_size < 1:
            raise ValueError(f"embed_batch_size must be >= 1, got {embed_batch_size}")
        self.path = str(path)
        self.embedder = embedder
        self.busy_timeout_s = float(busy_timeout_s)
        self.embed_batch_size = int(embed_batch_size)
        self._in_memory = self.path == ":memory:" or self.path.startswith("file::memory:")
        self._lock = threading.RLock()
        self._conn: sqlite3.Connection | None = None
        self._pid = os.getpid()
        self._closed = False
        if not self._in_memory:
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        self._connection()  # open and create the schema now, so a bad path fails here

    def __repr__(self) -> str:
        name = embedding_space_name(self.embedder) if self.embedder is not None else None
        return f"InteractionMemory(path={self.path!r}, embedder={name!r})"

    # -- connection ---------------------------------------------------------

    def _connection(self) -> sqlite3.Connection:
        if self._closed:
            raise RoboCriticsError(f"interaction memory {self.path!r} is closed")
        if self._conn is not None and self._pid == os.getpid():
            return self._conn
        # First use, or first use in a forked child: never reuse a parent's connection.
        self._pid = os.getpid()
        try:
            self._conn = self._open()
        except sqlite3.DatabaseError as exc:
            self._conn = None
            raise RoboCriticsError(f"interaction memory {self.path!r} cannot be opened: {exc}") from exc
        return self._conn

    def _open(self) -> sqlite3.Connection:
        conn = sqlite3.connect(self.path, timeout=self.busy_timeout_s, isolation_level=None, check_same_thread=False)
        conn.execute(f"PRAGMA busy_timeout = {int(self.busy_timeout_s * 1000)}")
        conn.execute("PRAGMA foreign_keys = ON")
        if not self._in_memory:
            self._enable_wal(conn)
            conn.execute("PRAGMA synchronous = FULL")
        conn.execute("BEGIN IMMEDIATE")
        try:
            version = conn.execute("PRAGMA user_version").fetchone()[0]
            if version > SCHEMA_VERSION:
                raise sqlite3.DatabaseError(
                    f"schema version {version} is newer than this robocritics understands ({SCHEMA_VERSION})"
                )
            for statement in _SCHEMA.split(";"):
                if statement.strip():
                    conn.execute(statement)
            conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            conn.execute("COMMIT")
        except BaseException:
            conn.execute("ROLLBACK")
            conn.close()
            raise
        return conn

    def _enable_wal(self, conn: sqlite3.Connection) -> None:
        """Switch the file to WAL; retried because the switch needs a moment without other writers."""
        deadline = time.monotonic() + self.busy_timeout_s
        while True:
            try:
                mode = conn.execute("PRAGMA journal_mode = WAL").fetchone()[0]
                if str(mode).lower() != "wal":
                    raise sqlite3.DatabaseError(f"could not enable WAL journaling (mode is {mode!r})")
                return
            except sqlite3.OperationalError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(_WAL_RETRY_PAUSE_S)

    @contextmanager
    def _write(self) -> Iterator[sqlite3.Connection]:
        """One write transaction: BEGIN IMMEDIATE, COMMIT on success, ROLLBACK on any exception."""
        with self._lock:
            conn = self._connection()
            conn.execute("BEGIN IMMEDIATE")
            try:
                yield conn
                conn.execute("COMMIT")
            except BaseException:
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                raise

    def _read(self, sql: str, parameters: Sequence[object] = ()) -> list[tuple]:
        with self._lock:
            return self._connection().execute(sql, parameters).fetchall()

    def close(self) -> None:
        """Close the database connection (idempotent). Later calls raise ``RoboCriticsError``."""
        with self._lock:
            if self._conn is not None and self._pid == os.getpid():
                self._conn.close()
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
    ) -> int:
        """Store one interaction in ``session`` (created if new); return its id.

        ``score`` must be within 0–10 or None. Ids increase in commit order,
        across threads and processes. Raises ``ValueError`` for invalid values.
        """
        if not isinstance(session, str) or not session:
            raise ValueError("session must be a non-empty string")
        for label, text in (("request", request), ("program", program), ("feedback", feedback)):
            if not isinstance(text, str):
                raise ValueError(f"{label} must be a string, got {type(text).__name__}")
        if score is not None:
            score = float(score)
            if not 0.0 <= score <= 10.0:  # also rejects NaN
                raise ValueError(f"score must be within 0-10 (the program quality index), got {score}")
        now = time.time()
        with self._write() as conn:
            conn.execute("INSERT OR IGNORE INTO sessions (id, created_s) VALUES (?, ?)", (session, now))
            cursor = conn.execute(
                "INSERT INTO interactions (session_id, request, program, feedback, score, created_s) "
                "VALUES (?, ?, ?, ?, ?, ?)",
                (session, request, program, feedback, score, now),
            )
            assert cursor.lastrowid is not None  # an INSERT always sets it
            return int(cursor.lastrowid)

    def get(self, interaction_id: int) -> Interaction:
        """The interaction with this id; ``KeyError`` if there is none."""
        rows = self._read(f"SELECT {_COLUMNS} FROM interactions WHERE id = ?", (int(interaction_id),))
        if not rows:
            raise KeyError(f"no interaction with id {interaction_id} in {self.path!r}")
        return _interaction(rows[0])

    def history(self, session: str) -> list[Interaction]:
        """Every interaction of ``session``, oldest first ([] for an unknown session)."""
        rows = self._read(f"SELECT {_COLUMNS} FROM interactions WHERE session_id = ? ORDER BY id", (session,))
        return [_interaction(r) for r in rows]

    def sessions(self) -> list[str]:
        """Every session id, in order of creation."""
        return [r[0] for r in self._read("SELECT id FROM sessions ORDER BY created_s, rowid")]

    def __len__(self) -> int:
        return int(self._read("SELECT COUNT(*) FROM interactions")[0][0])

    def _candidates(self, session: str | None) -> list[Interaction]:
        if session is not None:
            return self.history(session)
        return [_interaction(r) for r in self._read(f"SELECT {_COLUMNS} FROM interactions ORDER BY id")]

    # -- retrieval -------------------------------------------------------------

    def search(self, query: str, k: int = 3, session: str | None = None) -> list[Interaction]:
        """The ``k`` interactions whose requests are most similar to ``query``, best first.

        Limited to ``session`` when given. See the module docstring for how
        similarity is measured with and without an embedder.
        """
        return [interaction for interaction, _ in self.search_scored(query, k, session)]

    def search_scored(self, query: str, k: int = 3, session: str | None = None) -> list[tuple[Interaction, float]]:
        """Like ``search``, with each result's similarity: cosine (−1…1) or BM25 score (> 0)."""
        if k < 0:
            raise ValueError(f"k must be >= 0, got {k}")
        candidates = self._candidates(session)
        if k == 0 or not candidates:
            return []
        if self.embedder is None:
            similarity = bm25_scores(query, [c.request for c in candidates])
            keep = similarity > 0
        else:
            similarity = self._cosine_similarities(query, candidates, session)
            keep = np.ones(len(candidates), dtype=bool)
        ids = np.array([c.id for c in candidates])
        order = np.lexsort((-ids, -similarity))  # best similarity first, then newest
        ranked = [(candidates[i], float(similarity[i])) for i in order if keep[i]]
        return ranked[:k]

    def embed_missing(self, session: str | None = None) -> int:
        """Embed and store every interaction (of ``session``) that has no vector from the current embedder.

        Returns how many were embedded. ``search`` does this lazily; call it
        to pay the cost up front. Raises ``ValueError`` without an embedder.
        """
        if self.embedder is None:
            raise ValueError("embed_missing needs an embedder")
        name = embedding_space_name(self.embedder)
        stored = self._stored_vectors(name, session)
        missing = [c for c in self._candidates(session) if c.id not in stored]
        self._embed_and_store(name, missing)
        return len(missing)

    def _cosine_similarities(self, query: str, candidates: list[Interaction], session: str | None) -> np.ndarray:
        """Cosine similarity of ``query`` to each candidate, with the current embedder's vectors only.

        Candidates without a vector of this model name and of the query's
        length are embedded now and their vectors stored (replacing any
        stale vector of the same model name but another length).
        """
        assert self.embedder is not None
        name = embedding_space_name(self.embedder)
        query_vector = self._embed([query])[0]
        dim = query_vector.shape[0]
        vectors = {i: v for i, v in self._stored_vectors(name, session).items() if v.shape[0] == dim}
        missing = [c for c in candidates if c.id not in vectors]
        vectors.update(self._embed_and_store(name, missing, dim))
        matrix = np.vstack([vectors[c.id] for c in candidates])
        norms = np.linalg.norm(matrix, axis=1) * np.linalg.norm(query_vector)
        dots = matrix @ query_vector
        return np.divide(dots, norms, out=np.zeros_like(dots), where=norms > 0)

    def _stored_vectors(self, name: str, session: str | None) -> dict[int, np.ndarray]:
        """Stored vectors of embedding model ``name`` (of interactions in ``session``), by interaction id."""
        sql = (
            "SELECT e.interaction_id, e.vector FROM embeddings e "
            "JOIN interactions i ON i.id = e.interaction_id WHERE e.model = ?"
        )
        parameters: list[object] = [name]
        if session is not None:
            sql += " AND i.session_id = ?"
            parameters.append(session)
        return {row[0]: np.frombuffer(row[1], dtype="<f8") for row in self._read(sql, parameters)}

    def _embed_and_store(
        self, name: str, interactions: list[Interaction], dim: int | None = None
    ) -> dict[int, np.ndarray]:
        """Embed the requests of ``interactions`` in batches and store the vectors, one transaction per batch.

        All vectors must have length ``dim`` (the first batch's length when None).
        """
        new: dict[int, np.ndarray] = {}
        for start in range(0, len(interactions), self.embed_batch_size):
            batch = interactions[start : start + self.embed_batch_size]
            vectors = self._embed([c.request for c in batch])
            if dim is None:
                dim = vectors.shape[1]
            if vectors.shape[1] != dim:
                raise LLMError(
                    f"embedding model {name!r} returned vectors of length {vectors.shape[1]}, "
                    f"but of length {dim} for other texts"
                )
            now = time.time()
            with self._write() as conn:
                conn.executemany(
                    "INSERT OR REPLACE INTO embeddings (interaction_id, model, dim, vector, created_s) "
                    "SELECT ?, ?, ?, ?, ? WHERE EXISTS (SELECT 1 FROM interactions WHERE id = ?)",
                    [
                        (c.id, name, dim, np.asarray(v, dtype="<f8").tobytes(), now, c.id)
                        for c, v in zip(batch, vectors)
                    ],
                )
            new.update((c.id, v) for c, v in zip(batch, vectors))
        return new

    def _embed(self, texts: list[str]) -> np.ndarray:
        """Call the embedder and check it kept its promise: finite floats of shape (len(texts), d)."""
        assert self.embedder is not None
        vectors = np.asarray(self.embedder.embed(texts), dtype=np.float64)
        if vectors.ndim != 2 or vectors.shape[0] != len(texts) or vectors.shape[1] == 0:
            raise LLMError(
                f"embedder {embedding_space_name(self.embedder)!r} returned shape {vectors.shape} "
                f"for {len(texts)} texts; expected ({len(texts)}, d)"
            )
        if not np.all(np.isfinite(vectors)):
            raise LLMError(f"embedder {embedding_space_name(self.embedder)!r} returned non-finite values")
        return vectors


def _interaction(row: tuple) -> Interaction:
    return Interaction(
        id=int(row[0]),
        session=row[1],
        request=row[2],
        program=row[3],
        feedback=row[4],
        score=None if row[5] is None else float(row[5]),
        created_s=float(row[6]),
    )
