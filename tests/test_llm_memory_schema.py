"""The interaction-memory file as hostile input (issue 22, class 3): its schema is checked when it is opened, every
statement runs under SQLite's limits and a deadline, and every value read keeps its column's contract.

Each attack builds a real SQLite file with the standard library's sqlite3 (as an attacker would), then opens it
with :class:`InteractionMemory`: the result must be a typed :class:`InteractionMemoryError` naming what is wrong,
quickly, with nothing of the file's schema run.
"""

# ruff: noqa: F811  (pytest fixtures imported from llm_fixtures are parameters here)

from __future__ import annotations

import argparse
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from llm_fixtures import clean_llm_env, llm_server  # noqa: F401

from robocritics.cli.run import add_run_parser, run_command
from robocritics.llm.memory import InteractionMemory, InteractionMemoryError
from robocritics.llm.memory_guard import MAX_VALUE_BYTES, Deadline

TASK = "put the green apple in the white box"
PROGRAM = "move_above(green_apple)\n"


def _memory_file(path: Path, interactions: int = 3) -> Path:
    """A valid memory file written by robocritics, with ``interactions`` stored."""
    with InteractionMemory(path) as memory:
        for i in range(interactions):
            memory.add("s1", f"{TASK} number {i}", PROGRAM, "ok", 8.0)
    return path


def _tamper(path: Path, *statements: str) -> None:
    """Run ``statements`` on the file as an attacker would: check constraints off, the schema writable."""
    raw = sqlite3.connect(path, isolation_level=None)
    try:
        raw.execute("PRAGMA ignore_check_constraints = ON")
        for statement in statements:
            raw.execute(statement)
    finally:
        raw.close()


def _schema(path: Path) -> list[tuple]:
    raw = sqlite3.connect(path)
    try:
        return raw.execute("SELECT type, name, sql FROM sqlite_master ORDER BY name").fetchall()
    finally:
        raw.close()


ENDLESS = ("WITH RECURSIVE r(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM r) SELECT count(*) FROM r")


# --- the schema -------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "attack, named",
    [
        (f"CREATE TRIGGER loop AFTER INSERT ON interactions BEGIN SELECT ({ENDLESS}); END", "trigger 'loop'"),
        ("CREATE TRIGGER grow AFTER INSERT ON interactions BEGIN "
         "UPDATE interactions SET feedback = zeroblob(2000000000) WHERE id = new.id; END", "trigger 'grow'"),
        (f"CREATE TRIGGER on_read BEFORE DELETE ON sessions BEGIN SELECT ({ENDLESS}); END", "trigger 'on_read'"),
        ("CREATE VIEW extra AS SELECT * FROM interactions", "view 'extra'"),
        ("CREATE TABLE notes (x)", "table 'notes'"),
        ("CREATE INDEX by_program ON interactions(program)", "index 'by_program'"),
    ],
)  # fmt: skip
def test_an_object_robocritics_never_creates_is_refused_on_open_and_the_file_is_left_alone(tmp_path, attack, named):
    path = _memory_file(tmp_path / "memory.sqlite")
    _tamper(path, attack)
    before = _schema(path)
    with pytest.raises(InteractionMemoryError, match=f"its schema holds {named}"):
        InteractionMemory(path)
    assert _schema(path) == before


def test_a_trigger_disguised_as_a_table_with_writable_schema_is_refused(tmp_path):
    """SQLite itself finds this schema malformed (the memory also compares an object's statement with its type)."""
    path = _memory_file(tmp_path / "memory.sqlite")
    _tamper(path, f"CREATE TRIGGER loop AFTER INSERT ON interactions BEGIN SELECT ({ENDLESS}); END",
            "PRAGMA writable_schema = ON", "UPDATE sqlite_master SET type = 'table' WHERE name = 'loop'")  # fmt: skip
    with pytest.raises(InteractionMemoryError, match=r"trigger 'loop'|malformed database schema \(loop\)"):
        InteractionMemory(path)


@pytest.mark.parametrize("version", [0, 1, 3])
def test_views_in_place_of_the_tables_are_refused_before_any_upgrade(tmp_path, version):
    path = tmp_path / "memory.sqlite"
    _tamper(path, f"CREATE VIEW sessions AS SELECT 1 AS id, 0.0 AS created_s FROM ({ENDLESS})",
            f"CREATE VIEW interactions AS SELECT * FROM sessions", f"PRAGMA user_version = {version}")  # fmt: skip
    with pytest.raises(InteractionMemoryError, match="its schema holds view 'interactions', view 'sessions'"):
        InteractionMemory(path)


@pytest.mark.parametrize(
    "attack, table",
    [
        (["DROP INDEX interactions_by_session", "CREATE INDEX interactions_by_session ON interactions(program)"],
         "interactions"),
        (["DROP TABLE corpus_stats", "CREATE TABLE corpus_stats (session_id TEXT PRIMARY KEY, documents TEXT, tokens)"],
         "corpus_stats"),
        (["ALTER TABLE embeddings ADD COLUMN extra BLOB"], "embeddings"),
        (["DROP INDEX embeddings_by_space"], "embeddings"),
    ],
)  # fmt: skip
def test_a_table_or_index_of_another_shape_is_refused(tmp_path, attack, table):
    path = _memory_file(tmp_path / "memory.sqlite")
    _tamper(path, *attack)
    with pytest.raises(InteractionMemoryError, match=f"its table '{table}' .* is not the one robocritics creates"):
        InteractionMemory(path)


# --- values out of contract ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "attack, read, message",
    [
        ("UPDATE interactions SET score = 'high' WHERE id = 2", "get", "interaction 2: score holds the text 'high'"),
        ("UPDATE interactions SET score = 11 WHERE id = 2", "get", "score holds float 11.0, not a finite number within 0-10"),
        ("UPDATE interactions SET score = -0.5 WHERE id = 2", "history", "within 0-10"),
        ("UPDATE interactions SET created_s = 'yesterday' WHERE id = 2", "get", "created_s holds the text"),
        ("UPDATE interactions SET program = X'00ff' WHERE id = 2", "get", "program holds a blob of 2 bytes"),
        ("UPDATE interactions SET feedback = X'41' WHERE id = 2", "history", "feedback holds a blob of 1 bytes"),
        ("UPDATE interactions SET source = 'evil' WHERE id = 2", "search", "source holds the text 'evil', not one of llm, repair"),
        ("UPDATE interactions SET program = printf('%.*c', 200000, 'x') WHERE id = 2", "get", "program holds the text"),
        ("UPDATE corpus_stats SET documents = -5", "search", "corpus_stats.documents holds int -5"),
        ("UPDATE corpus_stats SET tokens = 'many'", "search", "corpus_stats.tokens holds the text 'many'"),
        ("UPDATE sessions SET id = X'01' WHERE id = 's2'", "sessions", "sessions.id holds a blob"),
    ],
)  # fmt: skip
def test_each_value_out_of_contract_is_a_typed_error_naming_its_column(tmp_path, attack, read, message):
    path = _memory_file(tmp_path / "memory.sqlite")
    with InteractionMemory(path) as memory:
        memory.add("s2", "another request", PROGRAM)
    _tamper(path, attack)
    with InteractionMemory(path) as memory:
        call = {"get": lambda: memory.get(2), "history": lambda: memory.history("s1"), "search": lambda: memory.search(TASK, 5),
                "sessions": memory.sessions}[read]  # fmt: skip
        with pytest.raises(InteractionMemoryError, match="holds a value robocritics never stores") as caught:
            call()
        assert message in str(caught.value) and caught.value.path == str(path)


def test_a_value_larger_than_sqlites_limit_is_a_typed_error_not_gigabytes(tmp_path):
    path = _memory_file(tmp_path / "memory.sqlite")
    _tamper(path, f"UPDATE interactions SET feedback = zeroblob({4 * MAX_VALUE_BYTES}) WHERE id = 1")
    with InteractionMemory(path) as memory:
        with pytest.raises(InteractionMemoryError, match="larger than 4,194,304 bytes"):
            memory.get(1)
        assert memory.get(2).feedback == "ok"  # the other rows stay readable


class _Embedder:
    name, dim = "tiny", 4

    def embed(self, texts):
        return np.ones((len(texts), self.dim))


@pytest.mark.parametrize(
    "vector, message",
    [("X'0011'", "a blob of 2 bytes, not 4 float64 values"), ("'text'", "the text 'text'"),
     ("X'" + "000000000000f87f" * 4 + "'", "not finite")],
)  # fmt: skip
def test_a_stored_vector_out_of_contract_is_a_typed_error(tmp_path, vector, message):
    path = _memory_file(tmp_path / "memory.sqlite")
    with InteractionMemory(path, embedder=_Embedder()) as memory:
        memory.embed_missing()
    _tamper(path, f"UPDATE embeddings SET vector = {vector} WHERE interaction_id = 2")
    with InteractionMemory(path, embedder=_Embedder()) as memory:
        with pytest.raises(InteractionMemoryError, match=message):
            memory.search(TASK)


# --- the deadline and SQLite's limits -----------------------------------------------------------------------------


def test_an_endless_statement_is_interrupted_at_the_deadline(tmp_path):
    memory = InteractionMemory(_memory_file(tmp_path / "memory.sqlite"), statement_timeout_s=0.2)
    with memory, pytest.raises(InteractionMemoryError, match="longer than statement_timeout_s=0.2 s"):
        memory._read(ENDLESS)


def test_the_deadline_is_counted_from_each_statement_with_an_injected_clock():
    conn = sqlite3.connect(":memory:")
    now = [0.0]
    deadline = Deadline(conn, 5.0, clock=lambda: now[0])
    deadline.start()
    assert conn.execute("WITH RECURSIVE r(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM r LIMIT 100000) "
                        "SELECT count(*) FROM r").fetchone() == (100000,)  # fmt: skip
    now[0] = 5.1  # past the deadline: the next long statement stops at the handler's first call
    with pytest.raises(sqlite3.OperationalError, match="interrupted"):
        conn.execute(ENDLESS).fetchone()
    deadline.start()  # a new statement has its own time
    assert conn.execute("SELECT 1").fetchone() == (1,)


def test_sqlite_refuses_to_build_a_huge_value_on_the_memorys_connection(tmp_path):
    with InteractionMemory(_memory_file(tmp_path / "memory.sqlite")) as memory:
        with pytest.raises(InteractionMemoryError, match="too big"):
            memory._read("SELECT zeroblob(2000000000)")
        with pytest.raises(InteractionMemoryError):
            memory._read("ATTACH DATABASE ? AS other", (str(tmp_path / "other.sqlite"),))
    assert not (tmp_path / "other.sqlite").exists()


def test_a_trigger_file_costs_little_memory_in_a_child(tmp_path):
    """The reported case took 2 GB: refusing it costs the interpreter and its imports (bound: 400 MB of max RSS)."""
    path = _memory_file(tmp_path / "memory.sqlite")
    _tamper(path, "CREATE TRIGGER grow AFTER INSERT ON interactions BEGIN "
            "UPDATE interactions SET feedback = zeroblob(1000000000) WHERE id = new.id; END")  # fmt: skip
    code = ("import resource, sys\nfrom robocritics.llm.memory import InteractionMemory, InteractionMemoryError\n"
            "try:\n    InteractionMemory(sys.argv[1]).add('s', 'r', 'p')\nexcept InteractionMemoryError as e:\n"
            "    print('refused:', e)\nprint(int(next(l for l in open('/proc/self/status') if l.startswith('VmHWM:')).split()[1]))\n")  # fmt: skip
    done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=120)
    refused, rss_kib = done.stdout.splitlines()
    assert refused.startswith("refused:") and "trigger 'grow'" in refused, done.stdout + done.stderr
    assert int(rss_kib) < 400 * 1024


# --- the file itself ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("which", ["", "-wal", "-shm", "-journal"])
def test_a_link_at_the_file_or_a_companion_is_refused_and_its_target_unchanged(tmp_path, which):
    path = tmp_path / "memory.sqlite"
    if which:
        _memory_file(path)
    victim = tmp_path / "victim.txt"
    victim.write_bytes(b"precious")
    (tmp_path / f"memory.sqlite{which}").unlink(missing_ok=True)
    (tmp_path / f"memory.sqlite{which}").symlink_to(victim)
    with pytest.raises(InteractionMemoryError, match="is a symbolic link"):
        InteractionMemory(path)
    assert victim.read_bytes() == b"precious"


def test_a_hard_link_to_another_database_is_refused_and_it_is_unchanged(tmp_path):
    victim = _memory_file(tmp_path / "victim.sqlite")
    before = victim.read_bytes()
    os.link(victim, tmp_path / "memory.sqlite")
    with pytest.raises(InteractionMemoryError, match="has 2 hard links"):
        InteractionMemory(tmp_path / "memory.sqlite")
    assert victim.read_bytes() == before


def test_a_fifo_as_the_file_is_refused_without_hanging(tmp_path):
    path = tmp_path / "memory.sqlite"
    os.mkfifo(path)
    with pytest.raises(InteractionMemoryError, match="not a regular file"):
        InteractionMemory(path)


def test_a_new_file_is_created_with_the_umask_permissions_at_a_unicode_path(tmp_path):
    path = tmp_path / "mémoire ✓" / "mem.sqlite"
    old = os.umask(0o077)
    try:
        InteractionMemory(path).close()
    finally:
        os.umask(old)
    assert path.is_file() and (path.stat().st_mode & 0o777) == 0o600


@pytest.mark.parametrize("content", [b"", b"SQLite format 3\x00" + b"\xff" * 100, os.urandom(4096)])
def test_files_that_are_not_a_memory_are_typed_errors(tmp_path, content):
    path = tmp_path / "memory.sqlite"
    path.write_bytes(content)
    if not content:  # an empty file is a new, empty database: robocritics creates its tables
        InteractionMemory(path).close()
        return
    with pytest.raises(InteractionMemoryError):
        InteractionMemory(path)


def test_a_truncated_memory_is_a_typed_error_on_open_or_read(tmp_path):
    path = _memory_file(tmp_path / "memory.sqlite", interactions=300)
    raw = sqlite3.connect(path)
    raw.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    raw.close()
    data = path.read_bytes()
    assert len(data) > 8192
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(InteractionMemoryError):
        with InteractionMemory(path) as memory:
            memory.history("s1")


# --- robocritics run --memory -------------------------------------------------------------------------------------


def _run(*argv: str) -> int:
    parser = argparse.ArgumentParser(prog="robocritics")
    add_run_parser(parser.add_subparsers(dest="command", required=True))
    return run_command(parser.parse_args(["run", *argv]))


@pytest.mark.usefixtures("clean_llm_env")
def test_run_with_a_trigger_memory_ends_with_a_clear_error_before_asking_the_model(llm_server, tmp_path, capsys):
    path = _memory_file(tmp_path / "memory.sqlite")
    _tamper(path, f"CREATE TRIGGER loop AFTER INSERT ON interactions BEGIN SELECT ({ENDLESS}); END")
    llm_server.reply(f"```python\n{PROGRAM}```")
    code = _run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--memory", str(path))
    err = capsys.readouterr().err
    assert code == 2 and "trigger 'loop'" in err and "Traceback" not in err, err
    assert llm_server.requests == []


@pytest.mark.usefixtures("clean_llm_env")
def test_run_with_out_of_contract_values_ends_with_a_clear_error(llm_server, tmp_path, capsys):
    path = _memory_file(tmp_path / "memory.sqlite")
    _tamper(path, "UPDATE interactions SET source = 'evil'")
    llm_server.reply(f"```python\n{PROGRAM}```")
    code = _run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--memory", str(path))
    err = capsys.readouterr().err
    assert code == 2 and "source holds the text 'evil'" in err and "Traceback" not in err, err

