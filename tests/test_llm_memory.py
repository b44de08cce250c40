"""InteractionMemory: storage, retrieval (BM25 and embeddings), concurrency, durability."""

# ruff: noqa: F811  (pytest fixtures imported from llm_fixtures are parameters here)

from __future__ import annotations

import dataclasses
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
import pytest
from llm_fixtures import TEST_EMBEDDING_MODEL, clean_llm_env, llm_server, make_client  # noqa: F401
from llm_server import Fail, hashed_embedding

from robocritics.errors import LLMError, RoboCriticsError
from robocritics.llm.bm25 import bm25_scores, tokenize
from robocritics.llm.limits import MAX_STORED_PROGRAM_CHARS
from robocritics.llm.memory import Interaction, InteractionMemory, InteractionMemoryError

pytestmark = pytest.mark.usefixtures("clean_llm_env")

TASKS = [
    "throw the coffee cup and the water bottle into the trash bin",
    "sort the apples by ripeness: red apples to the brown box, green apple to the white box",
    "prepare breakfast: move the cupcake from the brown box onto the plate",
    "put the green apple in the white box",
    "wave the gripper above the table",
]


class HashedEmbedder:
    """A local EmbeddingModel: hashed bag of words (as the test server computes), counting its calls."""

    def __init__(self, name: str = "hashed-a", dim: int = 32):
        self.name = name
        self.dim = dim
        self.embedded: list[str] = []

    def embed(self, texts: list[str]) -> np.ndarray:
        self.embedded.extend(texts)
        return np.array([hashed_embedding(t, self.dim, self.name) for t in texts]).reshape(len(texts), self.dim)


class TableEmbedder:
    """A local EmbeddingModel that maps texts containing a key word to a fixed vector."""

    def __init__(self, name: str, table: dict[str, list[float]], default: list[float]):
        self.name = name
        self.table = table
        self.default = default

    def embed(self, texts: list[str]) -> np.ndarray:
        rows = []
        for text in texts:
            rows.append(next((v for word, v in self.table.items() if word in text), self.default))
        return np.array(rows, dtype=float)


def fill(memory: InteractionMemory, session: str = "s1") -> list[int]:
    return [
        memory.add(session, task, f"# program {i}\nlib.open_gripper()\n", f"feedback {i}", float(i))
        for i, task in enumerate(TASKS)
    ]


# -- storing and reading -------------------------------------------------------------


def test_add_then_read_back():
    with InteractionMemory() as memory:
        before = time.time()
        first = memory.add("run-1", "put the apple in the box", "lib.close_gripper()", "Warning: joint speed", 7.5)
        second = memory.add("run-1", "put the apple in the box", "lib.reduce_speed(0.5)", "", 10)
        other = memory.add("run-2", "wave", "lib.open_gripper()")
        assert first < second < other

        history = memory.history("run-1")
        assert [i.id for i in history] == [first, second]
        got = history[0]
        assert isinstance(got, Interaction)
        assert (got.session, got.request, got.program, got.feedback, got.score) == (
            "run-1",
            "put the apple in the box",
            "lib.close_gripper()",
            "Warning: joint speed",
            7.5,
        )
        assert before - 1 <= got.created_s <= time.time() + 1
        assert memory.get(other).score is None and memory.get(other).feedback == ""
        assert memory.history("nobody") == []
        assert memory.sessions() == ["run-1", "run-2"]
        assert len(memory) == 3
        with pytest.raises(KeyError):
            memory.get(999)


def test_interactions_are_immutable():
    with InteractionMemory() as memory:
        interaction = memory.get(memory.add("s", "r", "p"))
        with pytest.raises(dataclasses.FrozenInstanceError):
            interaction.score = 10  # type: ignore[misc]


@pytest.mark.parametrize("score", [-0.1, 10.01, float("nan"), float("inf")])
def test_scores_outside_0_to_10_are_rejected(score):
    with InteractionMemory() as memory:
        with pytest.raises(ValueError, match="0-10"):
            memory.add("s", "r", "p", "f", score)
        assert len(memory) == 0


def test_bad_arguments_are_rejected():
    with InteractionMemory() as memory:
        with pytest.raises(ValueError, match="session"):
            memory.add("", "r", "p")
        with pytest.raises(ValueError, match="program"):
            memory.add("s", "r", None)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="k must be"):
            memory.search("r", k=-1)


def test_new_session_ids_are_unique():
    ids = {InteractionMemory.new_session_id() for _ in range(100)}
    assert len(ids) == 100


def test_a_file_memory_persists_and_a_new_instance_reads_it(tmp_path):
    path = tmp_path / "sub" / "memory.sqlite"
    with InteractionMemory(path) as memory:
        ids = fill(memory)
    with InteractionMemory(path) as reopened:
        assert [i.id for i in reopened.history("s1")] == ids
        assert [i.request for i in reopened.history("s1")] == TASKS
        assert reopened.search("apples ripeness")[0].request == TASKS[1]
    with sqlite3.connect(path) as raw:
        assert raw.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert raw.execute("PRAGMA integrity_check").fetchone()[0] == "ok"


def test_closed_memory_refuses_work(tmp_path):
    memory = InteractionMemory(tmp_path / "m.sqlite")
    memory.close()
    memory.close()  # idempotent
    with pytest.raises(RoboCriticsError, match="closed"):
        memory.add("s", "r", "p")


def test_a_file_that_is_not_a_database_is_reported(tmp_path):
    path = tmp_path / "notes.sqlite"
    path.write_text("these are my notes, not a database " * 100)
    with pytest.raises(RoboCriticsError, match="cannot be opened"):
        InteractionMemory(path)


# -- BM25 ------------------------------------------------------------------------------


def test_tokenize_splits_words_and_identifiers():
    assert tokenize("Put the green_apple in Box-2!") == ["put", "the", "green", "apple", "in", "box", "2"]


def test_bm25_prefers_rare_terms_and_short_documents():
    documents = ["the apple", "the box", "the the the", "apple apple apple in a very long sentence about many things"]
    scores = bm25_scores("the apple", documents)
    assert scores.shape == (4,)
    assert scores[0] == scores.max()  # both words, short
    assert scores[0] > scores[3] > scores[1]  # 'apple' is rarer than 'the'
    assert bm25_scores("banana", documents).tolist() == [0.0] * 4
    assert bm25_scores("", documents).tolist() == [0.0] * 4
    assert bm25_scores("apple", []).shape == (0,)


def test_bm25_matches_a_hand_computed_value():
    documents = ["red apple", "green apple box", "box"]
    k1, b = 1.2, 0.75
    average_length = 2.0
    idf_green = np.log(1 + (3 - 1 + 0.5) / (1 + 0.5))
    expected = idf_green * 1 * (k1 + 1) / (1 + k1 * (1 - b + b * 3 / average_length))
    assert bm25_scores("green", documents, k1=k1, b=b)[1] == pytest.approx(expected)


def test_lexical_search_ranks_the_relevant_interaction_first():
    with InteractionMemory() as memory:
        fill(memory)
        assert memory.search("sort apples by ripeness", k=1)[0].request == TASKS[1]
        assert memory.search("put the coffee cup in the trash")[0].request == TASKS[0]
        assert memory.search("cupcake on the plate")[0].request == TASKS[2]
        assert memory.search("quantum chromodynamics") == []
        assert {i.request for i in memory.search("box", k=10)} == {TASKS[1], TASKS[2], TASKS[3]}  # only matches
        ranked = memory.search_scored("green apple white box", k=2)
        assert [i.request for i, _ in ranked] == [TASKS[3], TASKS[1]]
        assert ranked[0][1] > ranked[1][1] > 0


def test_search_respects_session_and_k():
    with InteractionMemory() as memory:
        fill(memory, "a")
        fill(memory, "b")
        results = memory.search("apple", k=10, session="b")
        assert results and {r.session for r in results} == {"b"}
        assert len(memory.search("apple", k=1)) == 1
        assert memory.search("apple", k=0) == []
        assert memory.search("apple", session="nobody") == []


def test_ties_go_to_the_newest_interaction():
    with InteractionMemory() as memory:
        old = memory.add("s", "pick the apple", "v1")
        new = memory.add("s", "pick the apple", "v2")
        assert [i.id for i in memory.search("pick apple", k=2)] == [new, old]


# -- embeddings ------------------------------------------------------------------------


def test_embedding_search_ranks_by_cosine_and_embeds_lazily(tmp_path):
    embedder = HashedEmbedder(dim=256)
    with InteractionMemory(tmp_path / "m.sqlite", embedder=embedder) as memory:
        fill(memory)
        assert embedder.embedded == []  # add() never calls the embedder
        ranked = memory.search_scored("sort apples ripeness", k=5)
        assert ranked[0][0].request == TASKS[1]
        query = np.array(hashed_embedding("sort apples ripeness", 256, "hashed-a"))
        for interaction, similarity in ranked:
            vector = np.array(hashed_embedding(interaction.request, 256, "hashed-a"))
            assert similarity == pytest.approx(float(query @ vector))
        assert sorted(embedder.embedded) == sorted(TASKS + ["sort apples ripeness"])

        embedder.embedded.clear()
        memory.search("put the green apple in the white box")
        assert embedder.embedded == ["put the green apple in the white box"]  # vectors were cached

        new = memory.add("s1", "stack the plate on the box", "p")
        memory.search("plate")
        assert embedder.embedded[-2:] == ["plate", "stack the plate on the box"]
        assert memory.get(new).request == "stack the plate on the box"


def test_embedding_search_through_the_http_client(llm_server, make_client, tmp_path):
    llm_server.embedding_dim = 128
    with InteractionMemory(tmp_path / "m.sqlite", embedder=make_client()) as memory:
        fill(memory)
        assert memory.search("breakfast cupcake plate", k=1)[0].request == TASKS[2]
        assert all(r.json["model"] == TEST_EMBEDDING_MODEL for r in llm_server.embedding_requests())
    with sqlite3.connect(tmp_path / "m.sqlite") as raw:
        models = raw.execute("SELECT model, dim, COUNT(*) FROM embeddings GROUP BY model, dim").fetchall()
    assert models == [(TEST_EMBEDDING_MODEL, 128, len(TASKS))]


def test_embedding_failures_surface_as_llm_errors_and_store_nothing(llm_server, make_client, tmp_path):
    llm_server.embedding_dim = 512
    llm_server.script(Fail(500), Fail(500))
    query = "sort apples by ripeness"
    with InteractionMemory(tmp_path / "m.sqlite", embedder=make_client(max_retries=0)) as memory:
        fill(memory)
        with pytest.raises(LLMError, match="HTTP 500"):
            memory.search(query)  # the query could not be embedded
        assert len(memory) == len(TASKS)  # the interactions are safe
        with pytest.raises(LLMError, match="HTTP 500"):
            memory.search(query)  # the query was embedded, the backlog batch failed
        assert memory._read("SELECT COUNT(*) FROM embeddings") == [(0,)]
        assert memory.search(query)[0].request == TASKS[1]  # the server recovered
        assert memory._read("SELECT COUNT(*) FROM embeddings") == [(len(TASKS),)]


def test_switching_embedding_models_never_mixes_vectors(tmp_path):
    path = tmp_path / "m.sqlite"
    # Model A thinks the 'wave' task is exactly like any query about apples.
    liar = TableEmbedder("model-a", {"wave": [1.0, 0.0], "apple": [0.0, 1.0]}, default=[0.0, 1.0])
    with InteractionMemory(path, embedder=liar) as memory:
        fill(memory)
        assert memory.search("wave hello")[0].request == TASKS[4]
        assert memory.embed_missing() == 0  # all already embedded by the search

    honest = HashedEmbedder("model-b", dim=2)  # same dimension, different space
    with InteractionMemory(path, embedder=honest) as memory:
        assert memory.embed_missing() == len(TASKS)
        ranked = memory.search_scored("wave hello", k=5)
        query = np.array(hashed_embedding("wave hello", 2, "model-b"))
        for interaction, similarity in ranked:
            vector = np.array(hashed_embedding(interaction.request, 2, "model-b"))
            expected = query @ vector / (np.linalg.norm(query) * np.linalg.norm(vector) or 1.0)
            assert similarity == pytest.approx(float(expected))

    with sqlite3.connect(path) as raw:
        rows = raw.execute("SELECT model, COUNT(*) FROM embeddings GROUP BY model ORDER BY model").fetchall()
    assert rows == [("model-a", len(TASKS)), ("model-b", len(TASKS))]

    with InteractionMemory(path, embedder=liar) as memory:  # back to A: its vectors are still there
        liar_calls = []
        original = liar.embed
        liar.embed = lambda texts: (liar_calls.extend(texts), original(texts))[1]
        assert memory.search("wave")[0].request == TASKS[4]
        assert liar_calls == ["wave"]


def test_a_model_that_changes_dimension_is_re_embedded(tmp_path):
    path = tmp_path / "m.sqlite"
    with InteractionMemory(path, embedder=HashedEmbedder("same-name", dim=8)) as memory:
        fill(memory)
        memory.embed_missing()
    bigger = HashedEmbedder("same-name", dim=64)
    with InteractionMemory(path, embedder=bigger) as memory:
        assert memory.search("apples ripeness")[0].request == TASKS[1]
        assert len(bigger.embedded) == 1 + len(TASKS)
    with sqlite3.connect(path) as raw:
        assert raw.execute("SELECT DISTINCT dim FROM embeddings").fetchall() == [(64,)]


def test_an_embedder_returning_the_wrong_shape_is_an_llm_error():
    class Broken:
        name = "broken"

        def embed(self, texts):
            return np.zeros(len(texts))  # 1-D

    with InteractionMemory(embedder=Broken()) as memory:
        memory.add("s", "r", "p")
        with pytest.raises(LLMError, match="shape"):
            memory.search("r")


def test_the_client_names_its_vectors_after_the_embedding_model_not_the_chat_model(make_client, llm_server):
    client = make_client(model="chat-x", embedding_model="embed-y")
    with InteractionMemory(embedder=client) as memory:
        memory.add("s", "apple", "p")
        memory.search("apple")
        models = memory._read("SELECT DISTINCT model FROM embeddings")
    assert models == [("embed-y",)]


# -- concurrency -----------------------------------------------------------------------


def test_threads_sharing_one_instance(tmp_path):
    per_thread = 40
    with InteractionMemory(tmp_path / "m.sqlite", embedder=HashedEmbedder()) as memory:
        errors: list[BaseException] = []

        def work(n: int) -> None:
            try:
                for i in range(per_thread):
                    memory.add(f"thread-{n}", f"task {n} {i}", "p", "", i % 11)
                    if i % 10 == 0:
                        memory.search(f"task {n}")
            except BaseException as exc:  # pragma: no cover - reported below
                errors.append(exc)

        threads = [threading.Thread(target=work, args=(n,)) for n in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert errors == []
        assert len(memory) == 8 * per_thread
        for n in range(8):
            assert [i.request for i in memory.history(f"thread-{n}")] == [f"task {n} {i}" for i in range(per_thread)]


def test_threads_with_their_own_instances_on_one_file(tmp_path):
    path = tmp_path / "m.sqlite"
    InteractionMemory(path).close()
    per_thread = 30
    errors: list[BaseException] = []

    def work(n: int) -> None:
        try:
            with InteractionMemory(path, busy_timeout_s=20) as memory:
                for i in range(per_thread):
                    memory.add(f"t{n}", f"request {i}", "p")
        except BaseException as exc:  # pragma: no cover
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(n,)) for n in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    with InteractionMemory(path) as memory:
        assert len(memory) == 6 * per_thread
        ids = [i.id for n in range(6) for i in memory.history(f"t{n}")]
        assert len(set(ids)) == len(ids)


WRITER = textwrap.dedent(
    """
    import os, sys, time
    from robocritics.llm.memory import InteractionMemory

    path, name, go = sys.argv[1], sys.argv[2], sys.argv[5]
    count, size, pause_s, parties = int(sys.argv[3]), int(sys.argv[4]), float(sys.argv[6]), int(sys.argv[7])
    memory = InteractionMemory(path, busy_timeout_s=30)
    if go:
        print("ready", flush=True)
    while go and not os.path.exists(go):  # start line
        time.sleep(0.001)
    for i in range(count):
        program = f"# {name} {i}\\n" + "x" * size
        row = memory.add(name, f"request {i}", program, f"feedback {i}", i % 11)
        print(row, i, flush=True)  # printed only after the commit returned
        if i == 0 and parties:  # barrier: nobody writes a second row before everyone wrote a first
            open(f"{go}.{name}", "w").close()
            while sum(f.startswith(os.path.basename(go) + ".") for f in os.listdir(os.path.dirname(go))) < parties:
                time.sleep(0.001)
        time.sleep(pause_s)  # like the LLM call between two interactions
    """
)


def run_writer(
    path, name: str, count: int, size: int = 10, go: str = "", pause_s: float = 0.0, parties: int = 0
) -> subprocess.Popen:
    """A process adding ``count`` interactions to ``path``, printing "<id> <i>" after each commit.

    With ``go`` it opens the memory, prints "ready", then waits until the file ``go`` exists;
    with ``parties`` too, after its first row it waits until that many writers wrote theirs, so
    the writers overlap however the machine schedules them. It sleeps ``pause_s`` after each
    write (without, one writer can hold on to the lock: SQLite's busy handler is not fair).
    """
    return subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path), name, str(count), str(size), go, str(pause_s), str(parties)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_several_processes_writing_one_file(tmp_path):
    path = tmp_path / "shared.sqlite"
    go = tmp_path / "go"
    writers = [run_writer(path, f"proc-{n}", 100, go=str(go), pause_s=0.002, parties=4) for n in range(4)]
    for writer in writers:
        assert writer.stdout is not None
        line = writer.stdout.readline()
        assert line == "ready\n", f"a writer did not start: {line!r}"
    go.touch()
    outputs = [w.communicate(timeout=120) for w in writers]
    for writer, (_, err) in zip(writers, outputs):
        assert writer.returncode == 0, err
    with InteractionMemory(path) as memory:
        assert len(memory) == 400
        spans = []
        for n, (out, _) in enumerate(outputs):
            history = memory.history(f"proc-{n}")
            assert [i.request for i in history] == [f"request {i}" for i in range(100)]
            reported = [int(line.split()[0]) for line in out.splitlines()]
            assert reported == [i.id for i in history]
            spans.append((history[0].id, history[-1].id))
    # the writers really ran at the same time (the barrier makes sure): every id range overlaps every other
    assert all(a[0] < b[1] and b[0] < a[1] for a in spans for b in spans if a != b), spans
    with sqlite3.connect(path) as raw:
        assert raw.execute("PRAGMA integrity_check").fetchone()[0] == "ok"


@pytest.mark.parametrize("kill_after_s", [0.0, 0.004, 0.013])
def test_a_killed_writer_loses_nothing_committed(tmp_path, kill_after_s):
    path = tmp_path / "killed.sqlite"
    size = MAX_STORED_PROGRAM_CHARS - 20  # big rows (the largest stored whole), so the kill may land inside a write
    writer = run_writer(path, "victim", 10_000, size)
    committed: list[tuple[int, int]] = []
    assert writer.stdout is not None
    for line in writer.stdout:
        row, i = map(int, line.split())
        committed.append((row, i))
        if len(committed) >= 8:
            break
    time.sleep(kill_after_s)  # somewhere in the middle of a later write
    writer.send_signal(signal.SIGKILL)
    writer.wait(timeout=30)
    assert writer.returncode == -signal.SIGKILL

    with sqlite3.connect(path) as raw:
        assert raw.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    with InteractionMemory(path) as memory:
        stored = {i.id: i for i in memory.history("victim")}
        for row, _ in committed:
            assert row in stored
        for n, interaction in enumerate(sorted(stored.values(), key=lambda x: x.id)):
            # every stored row is whole: no torn program, in order, nothing skipped
            assert interaction.request == f"request {n}"
            assert interaction.program == f"# victim {n}\n" + "x" * size
        assert len(stored) >= len(committed)
        # and the file is still writable after the crash
        memory.add("after", "r", "p")
        assert len(memory) == len(stored) + 1


def test_a_forked_child_gets_its_own_connection(tmp_path):
    if not hasattr(os, "fork"):
        pytest.skip("no fork on this platform")
    path = tmp_path / "fork.sqlite"
    with InteractionMemory(path) as memory:
        memory.add("parent", "before fork", "p")
        pid = os.fork()
        if pid == 0:  # child
            code = 1
            try:
                memory.add("child", "from the child", "p")
                code = 0
            finally:
                os._exit(code)
        _, status = os.waitpid(pid, 0)
        assert os.waitstatus_to_exitcode(status) == 0
        memory.add("parent", "after fork", "p")
        assert [i.request for i in memory.history("child")] == ["from the child"]
        assert [i.request for i in memory.history("parent")] == ["before fork", "after fork"]


# -- the program's source (schema version 3) -----------------------------------------------------------

# A version-2 file, as robocritics wrote it before programs had a source (all of them the model's then).
VERSION_2 = """
CREATE TABLE sessions (id TEXT PRIMARY KEY, created_s REAL NOT NULL);
CREATE TABLE interactions (
    id INTEGER PRIMARY KEY AUTOINCREMENT, session_id TEXT NOT NULL REFERENCES sessions(id),
    request TEXT NOT NULL, program TEXT NOT NULL, feedback TEXT NOT NULL,
    score REAL CHECK (score IS NULL OR (score >= 0 AND score <= 10)), created_s REAL NOT NULL,
    request_tokens INTEGER NOT NULL DEFAULT 0);
CREATE INDEX interactions_by_session ON interactions(session_id, id);
CREATE TABLE embeddings (
    interaction_id INTEGER NOT NULL REFERENCES interactions(id) ON DELETE CASCADE, model TEXT NOT NULL,
    dim INTEGER NOT NULL CHECK (dim > 0), vector BLOB NOT NULL, created_s REAL NOT NULL,
    PRIMARY KEY (interaction_id, model));
CREATE INDEX embeddings_by_model ON embeddings(model, dim);
CREATE TABLE request_terms (
    term TEXT NOT NULL, interaction_id INTEGER NOT NULL REFERENCES interactions(id) ON DELETE CASCADE,
    session_id TEXT NOT NULL, tf INTEGER NOT NULL CHECK (tf > 0), PRIMARY KEY (term, interaction_id)) WITHOUT ROWID;
CREATE INDEX request_terms_by_session ON request_terms(session_id, term);
CREATE TABLE corpus_stats (session_id TEXT PRIMARY KEY, documents INTEGER NOT NULL, tokens INTEGER NOT NULL);
CREATE INDEX embeddings_by_space ON embeddings(model, dim, interaction_id);
INSERT INTO sessions VALUES ('old', 0);
INSERT INTO interactions VALUES
    (1, 'old', 'put the green apple in the white box', 'move_above(green_apple)', 'ok', 9.0, 0, 7);
INSERT INTO request_terms VALUES ('green', 1, 'old', 1), ('apple', 1, 'old', 1), ('white', 1, 'old', 1),
    ('box', 1, 'old', 1), ('put', 1, 'old', 1), ('the', 1, 'old', 2), ('in', 1, 'old', 1);
INSERT INTO corpus_stats VALUES ('', 1, 8), ('old', 1, 8);
PRAGMA user_version = 2;
"""


def test_every_interaction_has_the_source_of_its_program():
    with InteractionMemory() as memory:
        by_model = memory.add("s", TASKS[0], "home()", "fine", 10.0)
        by_repair = memory.add("s", TASKS[0], "lib.set_speed(0.5)\nhome()", "fine", 10.0, source="repair")
        assert [i.source for i in memory.history("s")] == ["llm", "repair"]
        assert memory.get(by_model).source == "llm" and memory.get(by_repair).source == "repair"
        assert {i.source for i in memory.search(TASKS[0], k=5)} == {"llm", "repair"}
        for bad in ("user", "", None, 3):
            with pytest.raises(InteractionMemoryError, match="source must be one of llm, repair"):
                memory.add("s", TASKS[0], "home()", source=bad)
        assert len(memory) == 2


def test_a_version_2_file_still_loads_its_rows_as_the_models_and_takes_new_sources(tmp_path):
    path = tmp_path / "v2.sqlite"
    with sqlite3.connect(path) as raw:
        raw.executescript(VERSION_2)
    with InteractionMemory(path) as memory:
        assert memory._read("PRAGMA user_version") == [(3,)]
        (old,) = memory.history("old")
        assert (old.id, old.program, old.score, old.source) == (1, "move_above(green_apple)", 9.0, "llm")
        assert memory.search("green apple", k=1) == [old]
        new = memory.add("old", "put the green apple in the white box", "home()", source="repair")
    with InteractionMemory(path) as reopened:  # upgraded once: the column is not added again
        assert [(i.id, i.source) for i in reopened.history("old")] == [(1, "llm"), (new, "repair")]
    with sqlite3.connect(path) as raw:  # SQLite itself refuses a source the schema does not know
        with pytest.raises(sqlite3.IntegrityError):
            raw.execute("INSERT INTO interactions (session_id, request, program, feedback, created_s, source) "
                        "VALUES ('old', 'r', 'p', 'f', 0, 'someone')")  # fmt: skip


_V2_SCHEMA = VERSION_2.split("INSERT INTO sessions")[0]


@settings(max_examples=25, deadline=None)
@given(rows=st.lists(st.tuples(st.sampled_from(TASKS), st.text(max_size=40),
                               st.one_of(st.none(), st.floats(0, 10, allow_nan=False))), max_size=12))  # fmt: skip
def test_upgrading_a_version_2_file_keeps_every_row_as_it_was(tmp_path_factory, rows):
    """Rows written by version 2's own statements read back unchanged after the upgrade, each as the model's."""
    path = tmp_path_factory.mktemp("v2") / "memory.sqlite"
    with sqlite3.connect(path) as raw:
        raw.executescript(_V2_SCHEMA + "PRAGMA user_version = 2;")
        raw.execute("INSERT INTO sessions VALUES ('old', 0)")
        for i, (request, program, score) in enumerate(rows, start=1):
            raw.execute("INSERT INTO interactions (session_id, request, program, feedback, score, created_s, "
                        "request_tokens) VALUES ('old', ?, ?, 'f', ?, ?, 0)",
                        (request, program, score, float(i)))  # fmt: skip
    with InteractionMemory(path) as memory:
        got = memory.history("old")
    assert [(i.request, i.program, i.score, i.created_s) for i in got] == [
        (request, program, score, float(i)) for i, (request, program, score) in enumerate(rows, start=1)
    ]
    assert {i.source for i in got} <= {"llm"}
