"""A hostile or broken interaction-memory file: every failure is typed and fast, retrieval is bounded (issue 10, item 5).

Damaged files, read-only files and directories, directories that cannot be
created, a lock held forever, a schema from the future: each ends at once (or
within ``busy_timeout_s``) with an ``InteractionMemoryError`` that names the
file and says what to do. Retrieval never loads every row into Python and
ranks exactly like the plain reference (``bm25_scores`` / a full cosine matrix).

Root ignores file permissions, so the permission cases run in a child process
that first gives up the capabilities that let it (``DROP_FILE_CAPABILITIES``);
as another user they are plain ``chmod`` cases.
"""

from __future__ import annotations

import json
import os
import random
import sqlite3
import subprocess
import sys
import textwrap
import time
import tracemalloc

import numpy as np
import pytest
from llm_server import hashed_embedding

from robocritics.errors import RoboCriticsError
from robocritics.llm.bm25 import bm25_scores
from robocritics.llm.limits import MAX_STORED_FEEDBACK_CHARS, MAX_STORED_PROGRAM_CHARS, MAX_TASK_CHARS
from robocritics.llm.memory import MAX_SEARCH_K, InteractionMemory, InteractionMemoryError

# How late a failure that should be immediate may come on a loaded machine (process start excluded).
SLACK_S = 2.0

WORDS = "put pick place the green red apple box white brown cup bottle trash plate cupcake wave sort ripe".split()

DROP_FILE_CAPABILITIES = '''
import ctypes, os
if os.geteuid() == 0:  # give up CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH and CAP_FOWNER: permissions apply again
    class _Header(ctypes.Structure):
        _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]
    class _Data(ctypes.Structure):
        _fields_ = [("effective", ctypes.c_uint32), ("permitted", ctypes.c_uint32), ("inheritable", ctypes.c_uint32)]
    _libc = ctypes.CDLL(None, use_errno=True)
    _header, _data = _Header(0x20080522, 0), (_Data * 2)()
    if _libc.capget(ctypes.byref(_header), _data) != 0:
        raise OSError(ctypes.get_errno(), "capget")
    _data[0].effective &= ~0b1110
    _data[0].permitted &= ~0b1110
    if _libc.capset(ctypes.byref(_header), _data) != 0:
        raise OSError(ctypes.get_errno(), "capset")
'''

OPEN_AND_REPORT = '''
import json, sys, time
from robocritics.llm.memory import InteractionMemory
started = time.monotonic()
try:
    with InteractionMemory(sys.argv[1]) as memory:
        memory.add("s", "r", "p")
    outcome = {"raised": None}
except BaseException as exc:
    outcome = {"raised": type(exc).__name__, "message": str(exc), "typed": isinstance(exc, __import__("robocritics").errors.RoboCriticsError)}
outcome["elapsed_s"] = time.monotonic() - started
print(json.dumps(outcome))
'''


def open_without_file_privileges(path: os.PathLike[str] | str) -> dict:
    """Open a memory at ``path`` in a child process that file permissions apply to; what happened, as a dict."""
    if not sys.platform.startswith("linux"):
        pytest.skip("dropping root's file capabilities needs Linux")
    code = DROP_FILE_CAPABILITIES + textwrap.dedent(OPEN_AND_REPORT)
    done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def filled(path, rows: int = 600, seed: int = 3) -> list[int]:
    rng = random.Random(seed)
    with InteractionMemory(path) as memory:
        return [
            memory.add(f"s{i % 3}", " ".join(rng.choices(WORDS, k=rng.randint(1, 9))), "lib.home()\n" * 40, "ok", i % 11)
            for i in range(rows)
        ]


# -- damaged files ---------------------------------------------------------------------------------


def exercise(path) -> list[BaseException]:
    """Open, search, read and write ``path``; every exception raised along the way."""
    raised: list[BaseException] = []
    try:
        memory = InteractionMemory(path)
    except BaseException as exc:  # noqa: BLE001 - the test inspects it
        return [exc]
    with memory:
        for step in (
            lambda: memory.search("green apple box", k=5),
            lambda: memory.history("s1"),
            lambda: [memory.get(i) for i in range(1, 600, 7)],
            lambda: memory.add("s9", "put the cup in the bin", "lib.home()"),
            lambda: len(memory),
        ):
            try:
                step()
            except KeyError:
                pass  # a row the damage took away
            except BaseException as exc:  # noqa: BLE001
                raised.append(exc)
    return raised


def test_garbage_pages_in_the_middle_of_the_file_are_a_typed_error(tmp_path):
    path = tmp_path / "m.sqlite"
    filled(path)
    size = path.stat().st_size
    with open(path, "r+b") as f:
        f.seek(size // 3)
        f.write(random.Random(7).randbytes(size // 3))
    raised = exercise(path)
    assert raised, "damage that is never noticed is not this test's case"
    for exc in raised:
        assert isinstance(exc, InteractionMemoryError), repr(exc)
        assert not isinstance(exc, sqlite3.Error)
        assert str(path) in str(exc) and "damaged or not a database" in str(exc)


def test_a_truncated_file_is_a_typed_error(tmp_path):
    path = tmp_path / "m.sqlite"
    filled(path)
    with open(path, "r+b") as f:
        f.truncate(path.stat().st_size // 2)
    raised = exercise(path)
    assert raised and all(isinstance(e, InteractionMemoryError) for e in raised), raised


@pytest.mark.parametrize("content", [b"\x00" * 8192, b"SQLite format 3\x00" + b"\xff" * 4000])
def test_files_that_only_look_like_databases_are_typed_errors(tmp_path, content):
    path = tmp_path / "m.sqlite"
    path.write_bytes(content)
    raised = exercise(path)
    assert raised and all(isinstance(e, InteractionMemoryError) for e in raised), raised
    assert "cannot be opened" in str(raised[0]) or "failed" in str(raised[0])


def test_a_directory_as_the_path_is_a_typed_error(tmp_path):
    with pytest.raises(InteractionMemoryError, match="it is a directory, not a file"):
        InteractionMemory(tmp_path)


def test_a_schema_from_a_newer_robocritics_is_refused(tmp_path):
    path = tmp_path / "m.sqlite"
    filled(path, rows=3)
    with sqlite3.connect(path) as raw:
        raw.execute("PRAGMA user_version = 99")
    with pytest.raises(InteractionMemoryError, match="schema version 99 is newer"):
        InteractionMemory(path)


# -- files and directories that cannot be written ----------------------------------------------------


def test_a_read_only_file_fails_at_once(tmp_path):
    path = tmp_path / "m.sqlite"
    filled(path, rows=3)
    path.chmod(0o444)
    outcome = open_without_file_privileges(path)
    assert outcome["raised"] == "InteractionMemoryError" and outcome["typed"], outcome
    assert "read-only" in outcome["message"] and str(path) in outcome["message"]
    assert outcome["elapsed_s"] < SLACK_S  # the old code retried the WAL switch for 30 s


def test_a_read_only_directory_fails_at_once(tmp_path):
    folder = tmp_path / "locked"
    folder.mkdir()
    filled(folder / "m.sqlite", rows=3)
    for leftover in ("m.sqlite-wal", "m.sqlite-shm"):
        (folder / leftover).unlink(missing_ok=True)
    folder.chmod(0o555)
    try:
        outcome = open_without_file_privileges(folder / "m.sqlite")
    finally:
        folder.chmod(0o755)
    assert outcome["raised"] == "InteractionMemoryError", outcome
    assert "read-only" in outcome["message"] and outcome["elapsed_s"] < SLACK_S


def test_a_directory_that_cannot_be_created_for_lack_of_permission_is_a_typed_error(tmp_path):
    parent = tmp_path / "closed"
    parent.mkdir(mode=0o555)
    try:
        outcome = open_without_file_privileges(parent / "sub" / "m.sqlite")
    finally:
        parent.chmod(0o755)
    assert outcome["raised"] == "InteractionMemoryError", outcome  # was a raw PermissionError
    assert "cannot be created (Permission denied)" in outcome["message"]


def test_a_directory_that_cannot_be_created_because_a_file_is_in_the_way_is_a_typed_error(tmp_path):
    (tmp_path / "notes.txt").write_text("a file, not a directory")
    with pytest.raises(InteractionMemoryError, match=r"its directory .*notes.txt' cannot be created"):
        InteractionMemory(tmp_path / "notes.txt" / "m.sqlite")


def test_a_lock_held_too_long_is_a_typed_error_after_the_busy_timeout(tmp_path):
    path = tmp_path / "m.sqlite"
    with InteractionMemory(path, busy_timeout_s=0.3) as memory:
        memory.add("s", "r", "p")
        holder = sqlite3.connect(path, isolation_level=None)
        holder.execute("BEGIN IMMEDIATE")  # another process's writer that never commits
        try:
            started = time.monotonic()
            with pytest.raises(InteractionMemoryError, match=r"held the write lock for more than busy_timeout_s=0.3 s"):
                memory.add("s", "r2", "p2")
            assert 0.25 <= time.monotonic() - started < 0.3 + SLACK_S
        finally:
            holder.execute("ROLLBACK")
            holder.close()
        assert len(memory) == 1  # the failed write left nothing behind
        memory.add("s", "r3", "p3")  # and the memory works once the lock is free


# -- bad arguments ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda m: m.search("apple", k=MAX_SEARCH_K + 1), "k must be at most"),
        (lambda m: m.search("apple", k=1.5), "k must be a whole number"),
        (lambda m: m.search(b"apple"), "query must be a string"),
        (lambda m: m.get("seven"), "interaction ids are whole numbers"),
        (lambda m: m.history(None), "session must be a string"),
        (lambda m: m.add("s" * 201, "r", "p"), "session must be at most 200"),
        (lambda m: m.add("s", "r", "p", "f", "high"), "score must be a number"),
        (lambda m: m.embed_missing(), "needs an embedder"),
    ],
)
def test_bad_arguments_are_typed_errors(call, message):
    with InteractionMemory() as memory:
        with pytest.raises(InteractionMemoryError, match=message):
            call(memory)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"path": "bad\x00path.sqlite"}, "path must be a file path"),
        ({"embed_batch_size": 0}, "embed_batch_size must be a whole number"),
        ({"scan_batch_size": -3}, "scan_batch_size must be a whole number"),
        ({"busy_timeout_s": float("nan")}, "busy_timeout_s must be a finite number"),
    ],
)
def test_bad_settings_are_typed_errors(kwargs, message):
    with pytest.raises(InteractionMemoryError, match=message):
        InteractionMemory(**kwargs)


# -- bounded rows and text --------------------------------------------------------------------------


def test_stored_texts_are_capped_and_cleaned():
    huge = "move_to(0.1)\n" * 200_000  # 2.6 MB of each
    with InteractionMemory() as memory:
        stored = memory.get(memory.add("s", "sort \ud800 " + huge, huge, huge + "\udfff"))
    assert len(stored.request) <= MAX_TASK_CHARS and "more characters not shown" in stored.request
    assert len(stored.program) <= MAX_STORED_PROGRAM_CHARS and len(stored.feedback) <= MAX_STORED_FEEDBACK_CHARS
    assert stored.request.startswith("sort \ufffd move_to")
    for text in (stored.request, stored.program, stored.feedback):
        text.encode("utf-8")


def test_a_huge_query_is_bounded():
    with InteractionMemory() as memory:
        target = memory.add("s", "put the green apple in the white box", "p")
        memory.add("s", "wave the gripper", "p")
        query = "green apple " + " ".join(f"word{i}" for i in range(500_000))  # 5 MB, 500 000 distinct words
        started = time.process_time()
        assert [i.id for i in memory.search(query, k=1)] == [target]
        assert time.process_time() - started < 1.0


# -- retrieval that never loads every row -----------------------------------------------------------


def peak_heap_of(call) -> tuple[object, int]:
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        result = call()
        return result, tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()


class HashedEmbedder:
    """A local EmbeddingModel: the test server's hashed bag of words."""

    def __init__(self, name: str = "hashed", dim: int = 64):
        self.name = name
        self.dim = dim

    def embed(self, texts):
        return np.array([hashed_embedding(t, self.dim, self.name) for t in texts]).reshape(len(texts), self.dim)


def test_a_search_reads_only_what_it_returns():
    big = "lib.move_to(0.1, 0.2, 0.3)\n" * 2_500  # 67 kB per row: 1000 rows hold 67 MB of programs
    target = "stack the cupcake on the plate"
    with InteractionMemory(embedder=None) as memory:  # SQLite's own pages are not on the Python heap
        for i in range(1_000):
            memory.add("s", target if i == 417 else f"put apple {i} into box {i % 13}", big, "fine " * 500, 5.0)
        found, peak = peak_heap_of(lambda: memory.search("cupcake plate", k=3))
        assert [f.request for f in found] == [target]
        assert peak < 2_000_000  # one row and the query; loading all of them took > 67 MB

        memory.embedder = HashedEmbedder()
        memory.scan_batch_size = 100
        memory.embed_missing()
        found, peak = peak_heap_of(lambda: memory.search(target, k=3))
        assert found[0].request == target and len(found) == 3
        assert peak < 3_000_000  # 100 vectors at a time, three rows in full


def reference_ranking(requests: dict[int, str], query: str, k: int) -> list[tuple[int, float]]:
    """The plain BM25 ranking over every candidate: best score first, ties to the newest, only > 0."""
    ids = list(requests)
    scores = bm25_scores(query, [requests[i] for i in ids])
    ranked = sorted(((round(float(s), 9), i, float(s)) for i, s in zip(ids, scores, strict=True) if s > 0), key=lambda x: (-x[0], -x[1]))
    return [(i, s) for _, i, s in ranked[:k]]


def test_bm25_in_sqlite_ranks_exactly_like_the_reference():
    rng = random.Random(11)
    with InteractionMemory() as memory:
        requests: dict[str, dict[int, str]] = {"s0": {}, "s1": {}, "s2": {}}
        for _ in range(400):
            session = rng.choice(list(requests))
            text = " ".join(rng.choices(WORDS, k=rng.randint(0, 12)))
            requests[session][memory.add(session, text, "p")] = text
        everything = {i: t for per_session in requests.values() for i, t in per_session.items()}
        for _ in range(40):
            query = " ".join(rng.choices(WORDS + ["nothing"], k=rng.randint(1, 6)))
            k = rng.randint(1, 25)
            for session, candidates in [(None, everything), *requests.items()]:
                got = [(i.id, score) for i, score in memory.search_scored(query, k=k, session=session)]
                expected = reference_ranking(candidates, query, k)
                assert [i for i, _ in got] == [i for i, _ in expected], (query, session)
                assert np.allclose([s for _, s in got], [s for _, s in expected], rtol=1e-12)


def test_batched_cosine_search_ranks_exactly_like_the_full_matrix():
    rng = random.Random(5)
    embedder = HashedEmbedder(dim=16)
    with InteractionMemory(embedder=embedder, scan_batch_size=7, embed_batch_size=5) as memory:
        texts = {memory.add("s", " ".join(rng.choices(WORDS, k=rng.randint(1, 6))), "p"): None for _ in range(90)}
        ids = np.array(list(texts))
        matrix = np.array([hashed_embedding(memory.get(int(i)).request, 16, "hashed") for i in ids])
        for _ in range(15):
            query = " ".join(rng.choices(WORDS, k=3))
            q = np.array(hashed_embedding(query, 16, "hashed"))
            norms = np.linalg.norm(matrix, axis=1) * np.linalg.norm(q)
            sims = np.divide(matrix @ q, norms, out=np.zeros(len(ids)), where=norms > 0)
            order = np.lexsort((-ids, -sims))[:10]
            got = memory.search_scored(query, k=10)
            assert [i.id for i, _ in got] == ids[order].tolist()
            assert np.allclose([s for _, s in got], sims[order])


# -- files written by the previous schema -------------------------------------------------------------

VERSION_1 = """
CREATE TABLE sessions (id TEXT PRIMARY KEY, created_s REAL NOT NULL);
CREATE TABLE interactions (
    id INTEGER PRIMARY KEY AUTOINCREMENT, session_id TEXT NOT NULL REFERENCES sessions(id),
    request TEXT NOT NULL, program TEXT NOT NULL, feedback TEXT NOT NULL,
    score REAL CHECK (score IS NULL OR (score >= 0 AND score <= 10)), created_s REAL NOT NULL);
CREATE INDEX interactions_by_session ON interactions(session_id, id);
CREATE TABLE embeddings (
    interaction_id INTEGER NOT NULL REFERENCES interactions(id) ON DELETE CASCADE, model TEXT NOT NULL,
    dim INTEGER NOT NULL CHECK (dim > 0), vector BLOB NOT NULL, created_s REAL NOT NULL,
    PRIMARY KEY (interaction_id, model));
CREATE INDEX embeddings_by_model ON embeddings(model, dim);
PRAGMA user_version = 1;
"""


def test_a_version_1_file_is_upgraded_and_searched_like_the_reference(tmp_path):
    path = tmp_path / "old.sqlite"
    rng = random.Random(2)
    requests = {}
    with sqlite3.connect(path) as raw:
        raw.executescript(VERSION_1)
        raw.execute("INSERT INTO sessions VALUES ('old', 0)")
        for i in range(1, 1_201):  # more than one upgrade batch
            requests[i] = " ".join(rng.choices(WORDS, k=rng.randint(1, 8)))
            raw.execute("INSERT INTO interactions VALUES (?, 'old', ?, 'p', 'f', NULL, 0)", (i, requests[i]))
    with InteractionMemory(path) as memory:
        assert memory._read("PRAGMA user_version") == [(3,)]
        for query in ("green apple box", "trash cup bottle", "wave"):
            got = [i.id for i in memory.search(query, k=8)]
            assert got == [i for i, _ in reference_ranking(requests, query, 8)]
        new = memory.add("old", "green apple green apple box", "p")
        assert memory.search("green apple", k=1)[0].id == new
    with InteractionMemory(path) as reopened:  # upgraded once, not again
        assert len(reopened) == 1_201


def test_memory_errors_are_robocritics_errors_and_value_errors():
    assert issubclass(InteractionMemoryError, RoboCriticsError) and issubclass(InteractionMemoryError, ValueError)
