"""A hostile user against ``robocritics batch`` and ``robocritics.batch``: bad rows never stop a batch.

Every test feeds input a careless or hostile user sends (malformed lines, broken ids, scenes that are
devices or a gigabyte, programs that loop or allocate, output paths that cannot be written, Ctrl-C) to the
real command and the real worker processes, and checks that each bad row is an error row
``{"type", "message", "line"}`` with a clear message and the batch goes on, or that bad usage is a one-line
error before any work. Workers are real spawn children; tests share one engine where they can.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import pickle
import signal
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.batch import LocalEngine, RowError, evaluate, reward
from robocritics.batch.rows import MAX_MESSAGE_CHARS, OUTPUT_KEYS, SceneCache, check_row, error_row, evaluate_job
from robocritics.cli import batch as cli_batch
from robocritics.cli.batch import Progress, count_rows, finished_jsonl, read_rows
from robocritics.cli.main import main
from robocritics.critic import CriticParams, register, unregister
from robocritics.errors import CriticError, GoalError, SceneError
from robocritics.scene import Scene, parse_json

SHORT = "move_above(green_apple)\nhome()\n"
CLI = [sys.executable, "-m", "robocritics.cli"]


@pytest.fixture(scope="module")
def engine():
    with LocalEngine(1, timeout_s=30) as pool:
        yield pool


def _write(path: Path, lines) -> Path:
    with open(path, "wb") as f:
        for line in lines:
            f.write((line if isinstance(line, bytes) else (line if isinstance(line, str) else json.dumps(line)).encode()) + b"\n")
    return path


def _rows(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def _interruptible():
    # a suite started from a background shell ignores SIGINT, and children inherit that: give Ctrl-C back
    signal.signal(signal.SIGINT, signal.SIG_DFL)


# --- rows, checked in this process ------------------------------------------------------------------


def _row(**fields):
    return {"id": "r", "scene": "sorting", "program": SHORT, **fields}


@pytest.mark.parametrize(
    "row, message",
    [
        (parse_json('{"id": ' + "9" * 5000 + ', "scene": "sorting", "program": "home()"}', "row"), "5000-digit integer"),
        (_row(id="bad\ud800"), "lone surrogate"),
        (_row(id=10**5000), "more than 20 digits"),  # from Python: str() of it would fail in the writer
        (_row(critics=[]), "'critics' is an empty list"),
        (_row(critics=""), "'critics' holds an empty name"),
        (_row(critics=",,"), "'critics' holds an empty name"),
        (_row(critics=["joint_speed", 3]), "a list holding a non-string"),
        (_row(goal=""), "'goal' holds an empty name"),
        (_row(scene="   "), "'scene' is an empty string"),
        (_row(params={"joint_speed": {"warn_speed_m_s": lambda: 1.0}}), "'params' holds something that is not data"),
        (_row(params={"joint_speed": {"frames": (i for i in ())}}), "'params' holds something that is not data"),
    ],
)
def test_check_row_refuses_broken_fields_with_a_message_naming_them(row, message):
    with pytest.raises(RowError, match=message):
        check_row(row)


def test_check_row_refuses_a_scene_nested_too_deep_to_send():
    deep = cur = {}
    for _ in range(100_000):  # built by a Python caller; JSON input is depth-checked before parsing
        cur["a"] = {}
        cur = cur["a"]
    with pytest.raises(RowError, match="nested too deep"):
        check_row(_row(scene=deep))


def test_check_row_accepts_a_scene_object_as_its_data_and_an_empty_goal_list_as_no_goals():
    scene = Scene.builtin("sorting")
    job = check_row(_row(scene=scene, goal=[]))
    assert isinstance(job.scene, dict) and Scene.model_validate(job.scene) == scene
    assert job.goals is None
    pickle.loads(pickle.dumps(job))  # it travels to a worker


def test_numpy_integer_ids_from_a_dataframe_become_plain_integers():
    np = pytest.importorskip("numpy")
    from robocritics.batch.evaluate import jobs_of

    assert type(check_row(_row(id=np.int64(3))).id) is int and check_row(_row(id=np.uint8(4))).id == 4
    with pytest.raises(RowError):
        check_row(_row(id=np.bool_(True)))
    errors = list(jobs_of([_row(id=np.int64(5), program=None)]))
    assert json.dumps(errors[0]["id"]) == "5"  # a writer can take the error row's id


def test_an_error_row_never_echoes_an_over_long_or_broken_id():
    from robocritics.batch.evaluate import jobs_of

    rows = [_row(id="x" * 10_000), _row(id="bad\udcff"), _row(id=-(10**5000), program=5), _row(id=7, critics=[])]
    errors = list(jobs_of(rows))
    assert all(isinstance(e, dict) for e in errors)  # error rows only: no Job
    assert [e["id"] for e in errors] == [None, None, None, 7]
    assert all(len(json.dumps(e)) < 1000 for e in errors)


def test_error_messages_are_bounded_even_from_a_plugin_that_raises_megabytes():
    class Loud:
        name = "loud_attack"
        description = "raises with a megabyte of text"

        class Params(CriticParams):
            pass

        def check(self, trajectory, scene, params):
            raise ValueError("x" * 1_000_000)

    from robocritics.robot.model import Robot

    register(Loud())
    try:
        row = evaluate_job(check_row(_row(critics=["loud_attack"])), Robot.ur3e(), SceneCache())
    finally:
        unregister("loud_attack")
    assert row["error"]["type"] == "CriticError" and "critic 'loud_attack' failed: ValueError: xxx" in row["error"]["message"]
    assert len(row["error"]["message"]) <= MAX_MESSAGE_CHARS and "1,000,0" in row["error"]["message"]  # says it was cut
    assert len(error_row(1, "X", "\ud800" * 10)["error"]["message"].encode("utf-8")) > 0  # encodable: no lone surrogate


def test_evaluate_refuses_one_row_instead_of_a_list_of_rows():
    for rows in (_row(), "rows.jsonl", b"{}"):
        with pytest.raises(TypeError, match="iterable of input rows"):
            next(evaluate(rows))


# --- reward() ---------------------------------------------------------------------------------------


def test_reward_of_no_programs_starts_no_worker():
    with LocalEngine(1) as pool:
        assert reward([], "sorting", engine=pool) == []
        assert pool._pool == []  # run() would have started its worker


@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        ({"scene": "kitchen"}, SceneError, "no built-in scene 'kitchen'"),
        ({"scene": 5}, RowError, "'scene' must be"),
        ({"scene": "sorting", "goal": "blue_apple in white_box"}, GoalError, "no object 'blue_apple'"),
        ({"scene": "sorting", "critics": ["no_such"]}, CriticError, "unknown critic 'no_such'"),
        ({"scene": "sorting", "critics": []}, RowError, "empty list"),
        ({"scene": "sorting", "params": {"joint_speed": {"nope": 1}}}, CriticError, "unknown parameter 'nope'"),
    ],
)
def test_reward_raises_for_the_callers_mistakes_before_any_program_runs(kwargs, error, message):
    with LocalEngine(1) as pool:  # never started: the check comes first
        with pytest.raises(error, match=message):
            reward([SHORT], engine=pool, **kwargs)
        assert pool._pool == []


def test_reward_refuses_one_program_text_and_takes_a_scene_object(engine):
    with pytest.raises(TypeError, match="one text"):
        reward(SHORT, "sorting", engine=engine)
    by_name = reward([SHORT, "home(", 7], "sorting", engine=engine)
    assert reward([SHORT, "home(", 7], Scene.builtin("sorting"), engine=engine) == by_name
    assert by_name[0] > 0 and by_name[1:] == [0.0, 0.0]
    assert reward([SHORT], "sorting", goal="green_apple in white_box", engine=engine) == [0.0]  # never met


def test_unpicklable_and_object_rows_do_not_stop_a_batch(engine):
    rows = [
        _row(id="fn", params={"joint_speed": {"warn_speed_m_s": lambda: 1.0}}),
        _row(id="scene-object", scene=Scene.builtin("sorting")),
        _row(id="surrogate-program", program="move_above(\ud800)\n"),
        _row(id="after"),
    ]
    out = {r["id"]: r for r in evaluate(rows, engine)}
    assert out["fn"]["error"]["type"] == "RowError"
    assert out["scene-object"]["error"] is None and out["after"]["error"] is None
    assert out["surrogate-program"]["error"]["type"] == "ProgramError"
    json.dumps(out["surrogate-program"]).encode("utf-8")


# --- reading input and output files ---------------------------------------------------------------


def test_count_rows_never_holds_a_huge_line(tmp_path):
    path = tmp_path / "in.jsonl"
    with open(path, "wb") as f:
        f.write(b'{"id": 1}\n\n  \n')
        f.write(b"a" * 40_000_000 + b"\n")  # one 40 MB line, as a hostile input holds
        f.write(b'{"id": 2}')  # no final newline
    tracemalloc.start()
    try:
        assert count_rows(str(path)) == 3
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8 * cli_batch.COUNT_CHUNK_BYTES


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from([b"\n", b" ", b"\t", b"\x0b", b"x", b"{}", b"\r\n"]), max_size=40), st.integers(1, 5))
def test_count_rows_equals_the_plain_count_at_any_chunk_size(tmp_path_factory, parts, chunk):
    data = b"".join(parts)
    path = tmp_path_factory.mktemp("count") / "in.jsonl"
    path.write_bytes(data)
    saved, cli_batch.COUNT_CHUNK_BYTES = cli_batch.COUNT_CHUNK_BYTES, chunk
    try:
        got = count_rows(str(path))
    finally:
        cli_batch.COUNT_CHUNK_BYTES = saved
    assert got == sum(1 for line in data.split(b"\n") if line.strip())  # the reference: what read_rows reads
    assert got == sum(1 for _ in read_rows(str(path)))


def test_done_rows_cuts_a_torn_last_line(tmp_path):
    out = tmp_path / "out.jsonl"
    good = [error_row("a", "RowError", "m"), error_row(7, "RowError", "m")]
    kept = "".join(json.dumps(r) + "\n" for r in good)
    out.write_text(kept + '{"id": "torn", "sco')
    assert finished_jsonl(out).keys == {'"a"', "7"} and out.read_text() == kept


@pytest.mark.parametrize(
    "lines, bad",
    [
        ([b"not json"], 2),
        ([b"[1, 2]"], 2),
        ([b'{"id": "a"}'], 2),  # an object, not an output row
        ([b"x" * (3 << 20)], 2),  # over-long
        ([b"2026-12-02 log line", json.dumps(error_row("b", "RowError", "m")).encode()], 2),
    ],
)
def test_resume_refuses_an_output_file_that_is_not_a_batch_output_and_leaves_it_alone(tmp_path, lines, bad):
    out = tmp_path / "app.log"
    out.write_bytes(json.dumps(error_row("a", "RowError", "m")).encode() + b"\n" + b"\n".join(lines) + b"\npartial last line")
    before = out.read_bytes()
    with pytest.raises(cli_batch.UsageError, match=f"line {bad} of .* is not an output row"):
        finished_jsonl(out)
    assert out.read_bytes() == before


def test_parquet_round_trip_equals_the_jsonl_rows(tmp_path):
    pytest.importorskip("pyarrow")
    rows = [
        {"id": 7, "score": 9.0, "flags": {"joint_speed": "OK", "collision": "WARNING"}, "passed": False,
         "duration_s": 0.123456789, "samples": 151, "error": None},
        {"id": "7", "score": 10.0, "flags": {"joint_speed": "OK"}, "passed": True, "duration_s": 1e-9, "samples": 1, "error": None},
        {"id": 12345678901234567890, "score": 0.0, "flags": {}, "passed": False, "duration_s": 0.5, "samples": 2, "error": None},
        {"id": "åpple ✓", "score": 5.0, "flags": {}, "passed": False, "duration_s": 0.0, "samples": 3, "error": None},
        error_row(None, "RowError", "input line 3: not valid JSON"),
        error_row(-3, "ProgramError", "line 2: bad", line=2, duration_s=0.01),
    ]  # fmt: skip
    first = cli_batch.ParquetWriter(tmp_path / "out.parquet")
    for row in rows[:2]:
        first.write(row)
    first.close()
    writer = cli_batch.ParquetWriter(tmp_path / "out.parquet", resume=True)  # copies the first file's rows
    for row in rows[2:]:
        writer.write(row)
    writer.close()
    jsonl = cli_batch.JsonlWriter(tmp_path / "out.jsonl", append=False)
    for row in rows:
        jsonl.write(row)
    jsonl.close()
    back = cli_batch.parquet_rows(tmp_path / "out.parquet")
    assert back == _rows(tmp_path / "out.jsonl") == rows
    assert [type(r["id"]) for r in back] == [int, str, int, str, type(None), int]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.jsonl", "out.parquet"]  # no temporary file left


# --- the command: usage errors before any work ----------------------------------------------------


def _main(capsys, *argv):
    code = main(list(argv))
    return code, capsys.readouterr()


@pytest.mark.parametrize(
    "output, resume, message",
    [
        ("adir", False, "is a directory"),
        ("adir", True, "is a directory"),
        ("in.jsonl", False, "is the input file"),
        ("./in.jsonl", True, "is the input file"),
        ("-", True, "--resume needs an output file"),
        (os.devnull, True, "not a regular file"),
        ("nodir/out.jsonl", False, "does not exist"),
    ],
)
def test_output_that_cannot_work_is_a_one_line_error_and_the_input_is_untouched(capsys, tmp_path, monkeypatch, output, resume, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "adir").mkdir()
    src = _write(tmp_path / "in.jsonl", [_row()])
    before = src.read_bytes()
    code, cap = _main(capsys, "batch", "in.jsonl", "-o", output, *(["--resume"] if resume else []))
    assert code == 2 and message in cap.err and len(cap.err.strip().splitlines()) == 1, cap.err
    assert src.read_bytes() == before and cap.out == ""


def test_parquet_without_pyarrow_stops_before_any_work(capsys, tmp_path, monkeypatch):
    for name in ("pyarrow", "pyarrow.parquet"):
        monkeypatch.setitem(sys.modules, name, None)  # `import pyarrow` raises ImportError, as when it is missing
    src = _write(tmp_path / "in.jsonl", [_row()])
    children = set(multiprocessing.active_children())
    code, cap = _main(capsys, "batch", str(src), "-o", str(tmp_path / "out.parquet"))
    assert code == 2 and "needs pyarrow" in cap.err and "Traceback" not in cap.err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.jsonl"] and set(multiprocessing.active_children()) == children


@pytest.mark.parametrize("content", [b"garbage, not parquet", None])
def test_resume_into_a_parquet_file_that_is_not_a_batch_output_is_a_one_line_error(capsys, tmp_path, content):
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    out = tmp_path / "out.parquet"
    if content is None:
        pq.write_table(pa.table({"x": [1, 2]}), str(out))
    else:
        out.write_bytes(content)
    src = _write(tmp_path / "in.jsonl", [_row()])
    code, cap = _main(capsys, "batch", str(src), "-o", str(out), "--resume")
    assert code == 2 and "--resume" in cap.err and len(cap.err.strip().splitlines()) == 1, cap.err


def _file_size_limit(limit_bytes: int):
    """A preexec_fn: files the child writes may grow to ``limit_bytes`` (RLIMIT_FSIZE); past it a write fails with
    EFBIG (SIGXFSZ ignored), as on a full disk."""

    def limit() -> None:
        import resource

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    return limit


def test_a_full_disk_is_a_one_line_error_naming_the_output(tmp_path):
    src = _write(tmp_path / "in.jsonl", [_row(id=i, program="home(") for i in range(8)])
    out = tmp_path / "out.jsonl"
    done = subprocess.run([*CLI, "batch", str(src), "-o", str(out), "--workers", "1"], capture_output=True, text=True,
                          timeout=300, preexec_fn=_file_size_limit(600))  # fmt: skip
    assert done.returncode == 2 and "File too large" in done.stderr and "--resume" in done.stderr, done.stderr
    assert str(out) in done.stderr and "Traceback" not in done.stderr
    assert 0 < out.read_bytes().count(b"\n") < 8  # some rows were written before the disk "filled"


def test_a_device_at_the_output_path_is_refused_before_any_work(capsys, tmp_path):
    src = _write(tmp_path / "in.jsonl", [_row(id=1, program="home(")])
    code, cap = _main(capsys, "batch", str(src), "-o", "/dev/full", "--workers", "1")
    assert code == 2 and "'/dev/full' is not a regular file" in cap.err and "Traceback" not in cap.err


# --- the command against a hostile input file ------------------------------------------------------


def test_a_hostile_input_file_gives_one_error_row_per_bad_line_and_the_batch_goes_on(tmp_path):
    (tmp_path / "adir").mkdir()
    with open(tmp_path / "huge.json", "wb") as f:
        f.truncate(1 << 30)  # a 1 GB (sparse) scene file
    inline = json.loads(Scene.builtin("sorting").model_dump_json())
    nan_scene = json.dumps(_row(id="nan-scene", scene=inline)).replace(json.dumps(inline["objects"][0]["position"]), "[NaN, 0.1, 0.1]", 1)
    lines = [
        _row(id="first"),
        '{"id": "torn", "scene"',
        "[1, 2, 3]",
        "null",
        '{"id": 1.5, "scene": "sorting", "program": "home()"}',
        '{"id": {"a": 1}, "scene": "sorting", "program": "home()"}',
        '{"id": ' + "9" * 5000 + ', "scene": "sorting", "program": "home()"}',
        '{"id": "surrogate\\ud800", "scene": "sorting", "program": "home()"}',
        b'{"id": "latin1 \xff", "scene": "sorting", "program": "home()"}',
        b'{"id": "huge", "program": "' + b"a" * 4_100_000 + b'"}',
        '{"id": "deep", "scene": ' + "[" * 10_000 + "]" * 10_000 + ', "program": "home()"}',
        _row(id=7),
        _row(id="7"),
        _row(id="dup"),
        _row(id="dup"),
        _row(id="dir", scene=str(tmp_path / "adir")),
        _row(id="devzero", scene="/dev/zero"),
        _row(id="gigabyte", scene=str(tmp_path / "huge.json")),
        nan_scene,
        _row(id="loop", program="while True:\n    pass\n"),
        _row(id="alloc", program="x = [0] * 10**9\n"),
        _row(id="recurse", program="def f(n):\n    return f(n + 1)\nf(0)\n"),
        _row(id="shout", program="move_above(" + "a" * 90_000 + ")\n"),
        _row(id="printer", program="for i in range(200):\n    print('to stdout?', i)\nhome()\n"),
        _row(id="critic", critics=["no_such_critic"]),
        _row(id="params", params={"joint_speed": {"warn_speed_m_s": "fast"}}),
        _row(id="goal", goal="green_apple under the table"),
        _row(id="missing", goal="blue_apple in white_box"),
        _row(id="never", goal="green_apple in white_box"),
        _row(id="last"),
    ]
    src = _write(tmp_path / "in.jsonl", lines)
    out = tmp_path / "out.jsonl"
    result = subprocess.run([*CLI, "batch", str(src), "-o", str(out), "--workers", "1", "--timeout", "30"],
                            capture_output=True, text=True, timeout=600)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert result.stdout == "" and "Traceback" not in result.stderr
    rows = _rows(out)
    assert len(rows) == len(lines)
    for r in rows:
        assert tuple(r) == OUTPUT_KEYS
        if r["error"] is not None:
            assert set(r["error"]) == {"type", "message", "line"} and 0 < len(r["error"]["message"]) <= MAX_MESSAGE_CHARS
    unnamed = sorted(r["error"]["message"].split(":")[0] for r in rows if r["id"] is None)
    assert unnamed == sorted(f"input line {n}" for n in (2, 3, 4, 5, 6, 7, 8, 9, 10, 11))
    by_id = {json.dumps(r["id"]): r for r in rows if r["id"] is not None}
    kind = {k: r["error"]["type"] if r["error"] else None for k, r in by_id.items()}
    assert kind['"first"'] is None and kind['"last"'] is None and kind["7"] is None and kind['"7"'] is None
    assert {kind[f'"{k}"'] for k in ("dir", "devzero", "gigabyte", "nan-scene")} == {"SceneError"}
    assert "finite" in by_id['"nan-scene"']["error"]["message"] and "1,000,000 bytes" in by_id['"gigabyte"']["error"]["message"]
    assert {kind[f'"{k}"'] for k in ("loop", "alloc", "recurse")} == {"BudgetError"}
    assert kind['"shout"'] == "ProgramError" and kind['"printer"'] is None
    assert kind['"critic"'] == kind['"params"'] == "CriticError"
    assert kind['"goal"'] == kind['"missing"'] == "GoalError"
    assert by_id['"never"']["flags"]["task_outcome"] == "ERROR" and not by_id['"never"']["passed"]
    dups = [r for r in rows if r["id"] == "dup"]
    assert sorted(r["error"] is None for r in dups) == [False, True]
    assert "input line 11" in next(r for r in rows if r["id"] is None and "nested" in r["error"]["message"])["error"]["message"]


def test_stdout_output_holds_only_rows_and_progress_goes_to_stderr(tmp_path):
    rows = [_row(id=i, program=f"print('noise {i}')\nhome()\n") for i in range(3)] + ["not json"]
    src = _write(tmp_path / "in.jsonl", rows)
    result = subprocess.run([*CLI, "batch", str(src), "-o", "-", "--workers", "1"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    out = [json.loads(line) for line in result.stdout.splitlines()]  # every stdout line is a row
    assert sorted(json.dumps(r["id"]) for r in out) == ["0", "1", "2", "null"]
    assert "4/4 rows (100 %)" in result.stderr and "rows/s" in result.stderr and "ETA" in result.stderr
    assert not (tmp_path / "-").exists()


def test_stdout_into_a_reader_that_stops_ends_quietly(tmp_path):
    src = _write(tmp_path / "in.jsonl", [_row(id=i, program="home(") for i in range(50)])
    reader = subprocess.Popen(["head", "-n", "1"], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    batch = subprocess.run([*CLI, "batch", str(src), "-o", "-", "--workers", "1"], stdout=reader.stdin, stderr=subprocess.PIPE,
                           text=True, timeout=300)  # fmt: skip
    reader.stdin.close()
    first = reader.stdout.read()
    reader.wait(30)
    assert batch.returncode == 0 and "Traceback" not in batch.stderr, batch.stderr
    assert json.loads(first)["error"]["type"] == "ProgramError"


def test_ctrl_c_leaves_valid_jsonl_with_every_finished_row_and_resume_completes_it(tmp_path):
    slow = "for i in range(60):\n    move_to(0.25 + 0.001 * i, 0.15 - 0.002 * i, 0.25)\n    move_to(0.3, -0.1 + 0.001 * i, 0.3)\n"
    rows = [_row(id=f"r{i}", program=slow if i % 2 else "home(") for i in range(12)]
    src, out = _write(tmp_path / "in.jsonl", rows), tmp_path / "out.jsonl"
    proc = subprocess.Popen([*CLI, "batch", str(src), "-o", str(out), "--workers", "1"], stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=_interruptible)  # fmt: skip
    try:
        for _ in range(3000):
            if (out.exists() and len(out.read_bytes().splitlines()) >= 2) or proc.poll() is not None:
                break
            time.sleep(0.02)
        assert proc.poll() is None, "the batch ended before it could be interrupted"
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole process group
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert "rerun with --resume" in err
    first = _rows(out)  # every line parses
    assert 2 <= len(first) < len(rows)
    assert all(r["error"] is None or r["error"]["type"] == "ProgramError" for r in first)  # no row blamed on the interrupt
    again = subprocess.run([*CLI, "batch", str(src), "-o", str(out), "--resume", "--workers", "1"], capture_output=True,
                           text=True, timeout=600)  # fmt: skip
    assert again.returncode == 0, again.stderr
    final = _rows(out)
    assert sorted(r["id"] for r in final) == sorted(r["id"] for r in rows)  # each exactly once
    assert final[: len(first)] == first
    assert f"{len(rows)}/{len(rows)} rows (100 %), {len(first)} kept from OUT" in again.stderr


def test_resume_with_another_input_keeps_the_old_rows_and_says_so(capsys, tmp_path):
    out = tmp_path / "out.jsonl"
    out.write_text("".join(json.dumps(error_row(i, "ProgramError", "old")) + "\n" for i in ("a", "b")))
    src = _write(tmp_path / "in.jsonl", [_row(id="b"), _row(id="c", program="home(")])
    code, cap = _main(capsys, "batch", str(src), "-o", str(out), "--resume", "--workers", "1")
    assert code == 0, cap.err
    assert [r["id"] for r in _rows(out)] == ["a", "b", "c"]
    assert "1 rows of" in cap.err and "not in" in cap.err


def test_progress_counts_rows_kept_by_resume_as_done_but_not_in_the_rate():
    import io

    now = [0.0]
    stream = io.StringIO()
    progress = Progress(4, stream, clock=lambda: now[0], every=1)
    progress.skip()
    progress.skip()
    now[0] = 2.0
    progress.update({"error": None})
    assert stream.getvalue() == "robocritics batch: 3/4 rows (75 %), 2 kept from OUT, 0 error rows, 0.50 rows/s, ETA 2 s\n"
    progress.finish(interrupted=True)
    assert stream.getvalue().splitlines()[-1] == "robocritics batch: interrupted after 1 rows in 2.0 s, 0 error rows (2 kept from OUT)"


def test_a_byte_order_mark_does_not_spoil_the_first_row(tmp_path):
    path = tmp_path / "in.jsonl"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(_row(id="first")).encode() + b"\n\xef\xbb\xbf" + json.dumps(_row(id="second")).encode() + b"\n")
    first, second = read_rows(str(path))
    assert first["id"] == "first"
    assert isinstance(second, RowError) and "input line 2" in str(second)  # only a file starts with a BOM


def test_a_mistyped_worker_count_is_refused_before_starting_thousands_of_processes(capsys, tmp_path):
    src = _write(tmp_path / "in.jsonl", [_row()])
    children = set(multiprocessing.active_children())
    code, cap = _main(capsys, "batch", str(src), "-o", str(tmp_path / "out.jsonl"), "--workers", "100000")
    assert code == 2 and "--workers 100000: at most" in cap.err
    assert set(multiprocessing.active_children()) == children and not (tmp_path / "out.jsonl").exists()


def test_progress_on_a_stream_that_fails_never_stops_the_batch():
    import io

    stream = io.StringIO()
    stream.close()  # e.g. stderr closed by the caller
    progress = Progress(2, stream, every=1)
    progress.update({"error": None})
    progress.finish()
    assert progress.done == 1 and progress.stream is None


def test_sigterm_completes_the_parquet_file_and_resume_finishes_it_equal_to_jsonl(tmp_path):
    pytest.importorskip("pyarrow")
    slow = "for i in range(40):\n    move_to(0.25 + 0.001 * i, 0.15 - 0.002 * i, 0.25)\n    move_to(0.3, -0.1 + 0.001 * i, 0.3)\n"
    rows = [_row(id=i if i % 3 else f"s{i}", program=slow if i % 2 else SHORT) for i in range(10)] + ["{torn"]
    src, parquet, jsonl = _write(tmp_path / "in.jsonl", rows), tmp_path / "out.parquet", tmp_path / "out.jsonl"
    proc = subprocess.Popen([*CLI, "batch", str(src), "-o", str(parquet), "--workers", "1"], stderr=subprocess.PIPE, text=True)
    try:
        for line in proc.stderr:  # a progress line per row: stop it after two rows
            if line.startswith("robocritics batch: 2/"):
                proc.send_signal(signal.SIGTERM)
                break
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    first = cli_batch.parquet_rows(parquet)  # a complete Parquet file, not a .partial
    assert 2 <= len(first) < len(rows) and not any(p.name.endswith(".partial") for p in tmp_path.iterdir())
    for args in ([str(parquet), "--resume"], [str(jsonl)]):
        done = subprocess.run([*CLI, "batch", str(src), "-o", *args, "--workers", "1"], capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
    got, want = cli_batch.parquet_rows(parquet), _rows(jsonl)
    assert got[: len(first)] == first

    def key(r):
        return json.dumps(r["id"]) + json.dumps(r["error"])

    assert len(got) == len(want) == len(rows)
    for g, w in zip(sorted(got, key=key), sorted(want, key=key)):
        assert {**g, "duration_s": 0} == {**w, "duration_s": 0}  # equal but for the time each took


def test_the_terminal_bar_overwrites_a_longer_earlier_bar():
    import io

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    now = [0.0]
    stream = Terminal()
    progress = Progress(3, stream, clock=lambda: now[0])
    for t in (5.0, 5.1, 5.2):  # ETA 10 s, then 3 s: the second bar is shorter than the first
        now[0] = t
        progress.update({"error": None})
    bars = stream.getvalue().split("\r")[1:]
    assert bars[0].endswith("ETA 10 s") and bars[1].rstrip().endswith("ETA 3 s")
    assert [len(b) for b in bars] == sorted(len(b) for b in bars)  # each covers the one before


def test_bad_rows_stream_through_one_at_a_time_and_are_never_held():
    # 300k bad lines once cost 17 s and 236 MB: every error row was collected (and list.pop(0)-ed) before the
    # next good row; now each is yielded as soon as it is read
    from robocritics.batch.local import LocalEngine

    read: list[int] = []

    def rows():
        for i in range(1000):
            read.append(i)
            yield []

    with LocalEngine(1) as engine:
        out = evaluate(rows(), engine)
        first = next(out)
        assert first["error"]["type"] == "RowError" and read == [0]
        assert next(out)["error"]["type"] == "RowError" and read == [0, 1]
        out.close()
