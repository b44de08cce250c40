"""Small inputs, bounded work; tracebacks turned into answers (issue 22, classes 4 and 7, batch and params parts).

Peak memory is measured in a child process (its own VmHWM: ``ru_maxrss`` survives fork and exec, so a child
of a large pytest process would report the parent's size) and bounded, never wall-clock time.
"""

from __future__ import annotations

import json
import multiprocessing
import resource
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.batch import LocalEngine, reward
from robocritics.batch.local import max_workers
from robocritics.batch.rows import error_row
from robocritics.cli import batch as cli_batch
from robocritics.cli.main import main
from robocritics.critic import MAX_PARAM_NAME_CHARS, MAX_PARAM_NAMES, critique, select_critics
from robocritics.errors import CriticError
from robocritics.scene import Scene
from robocritics.pipeline import simulate

CLI = [sys.executable, "-m", "robocritics.cli"]
PROGRAMS = Path(__file__).resolve().parents[1] / "examples" / "programs"
SHORT = "move_above(green_apple)\nhome()\n"
GIB = 1024**3


def _child_peak_rss_mib(code: str, *args: str) -> tuple[str, float]:
    """Run ``code`` in a fresh interpreter; (its stdout without the last line, its peak RSS in MiB)."""
    wrapped = code + "\nprint(int(next(l for l in open(\'/proc/self/status\') if l.startswith(\'VmHWM:\')).split()[1]))\n"
    done = subprocess.run([sys.executable, "-c", wrapped, *args], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    *out, rss_kib = done.stdout.splitlines()
    return "\n".join(out), int(rss_kib) / 1024


# --- params: bounded lists and names -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "params, message",
    [
        ({"joint_speed": {"frames": [f"f{i}" for i in range(10_000)]}}, f"frames: Tuple should have at most {MAX_PARAM_NAMES} items"),
        ({"space_usage": {"frames": ["tcp"] * 10_000}}, "frames: Tuple should have at most"),
        ({"space_usage": {"frames": ["tcp", "tcp"]}}, "frames: names 'tcp' more than once"),
        ({"collision": {"ignore_pairs": ["p" * 900_000]}}, f"ignore_pairs.0: String should have at most {MAX_PARAM_NAME_CHARS} characters"),
        ({"end_effector_pose": {"frame": "f" * 100_000}}, "frame: String should have at most"),
        ({"joint_speed": {"frames": [""]}}, "frames.0: String should have at least 1 character"),
        ({"collision": {"d_warn_m": float("nan")}}, "d_warn_m: Input should be a finite number"),
        ({"joint_speed": {"max_speed_m_s": float("inf")}}, "max_speed_m_s: Input should be a finite number"),
    ],
)  # fmt: skip
def test_oversized_or_repeated_names_are_a_critic_error_naming_the_field_and_short(params, message):
    with pytest.raises(CriticError, match="invalid params for critic") as caught:
        select_critics(None, params)
    assert message in str(caught.value) and len(str(caught.value)) < 400


def test_distinct_names_up_to_the_robots_frames_still_work():
    scene = Scene.builtin("sorting")
    execution = simulate(SHORT, scene)
    frames = execution.trajectory.frame_names
    report = critique(execution, critics=["joint_speed"], params={"joint_speed": {"frames": list(frames)}})
    assert report.verdicts[0].critic == "joint_speed" and len(frames) <= MAX_PARAM_NAMES


def test_check_with_10000_frame_names_is_a_one_line_error_in_little_memory(tmp_path):
    """The reported case cost 5 GB on a 30-s program; now the params are refused before simulating (bound: 400 MiB,
    the interpreter and the check path's imports)."""
    params = tmp_path / "params.json"
    params.write_text(json.dumps({"joint_speed": {"frames": ["tcp"] * 10_000}, "space_usage": {"frames": ["tcp"] * 10_000}}))
    code = textwrap.dedent(f"""
        import sys
        from robocritics.cli.main import main
        print("exit", main(["check", {str(PROGRAMS / 'sorting_careful.py')!r}, "--params", {str(params)!r}]))
    """)
    out, peak_mib = _child_peak_rss_mib(code)
    assert out.splitlines()[-1] == "exit 2"
    assert peak_mib < 400


# --- workers ---------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("workers", [10**6, max_workers() + 1])
def test_reward_with_too_many_workers_is_refused_before_starting_any(workers):
    before = set(multiprocessing.active_children())
    with pytest.raises(ValueError, match=f"at most {max_workers()} on this machine"):
        reward([SHORT], "sorting", workers=workers)
    with pytest.raises(ValueError, match="at most"):
        LocalEngine(workers)
    assert set(multiprocessing.active_children()) == before


def test_a_local_ray_cluster_takes_the_same_cap_before_starting():
    pytest.importorskip("ray")
    from robocritics.batch.ray_engine import RayEngine

    with pytest.raises(ValueError, match=f"at most {max_workers()} on this machine"):
        RayEngine(10**6)
    with pytest.raises(ValueError, match="at most"):
        reward([SHORT], "sorting", engine="ray", workers=10**6)


def test_the_cli_and_the_api_share_one_cap(capsys, tmp_path):
    src = tmp_path / "in.jsonl"
    src.write_text("")
    assert main(["batch", str(src), "-o", str(tmp_path / "out.jsonl"), "--workers", str(max_workers() + 1)]) == 2
    assert f"at most {max_workers()} on this machine" in capsys.readouterr().err
    with LocalEngine(max_workers()) as engine:  # the cap itself is allowed (no worker starts before a row)
        assert engine.workers == max_workers()


# --- a hard address-space limit (ulimit -v) below the workers' 3 GiB ------------------------------------------------


def _hard_address_limit(limit_bytes: int):
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))

    return limit


def test_workers_take_the_hard_limit_when_it_is_below_theirs(tmp_path):
    """Every worker died with "not allowed to raise maximum limit" under `ulimit -v` below 3 GiB."""
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    src.write_text("".join(json.dumps({"id": i, "scene": "sorting", "program": SHORT}) + "\n" for i in range(2)))
    limit = int(2.5 * GIB)
    done = subprocess.run([*CLI, "batch", str(src), "-o", str(out), "--workers", "1"], capture_output=True, text=True,
                          timeout=600, preexec_fn=_hard_address_limit(limit))  # fmt: skip
    assert done.returncode == 0, done.stderr
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert sorted(r["id"] for r in rows) == [0, 1] and all(r["error"] is None for r in rows), rows


def test_a_hard_limit_too_small_to_start_a_worker_is_a_one_line_error_naming_it(tmp_path):
    src = tmp_path / "in.jsonl"
    src.write_text(json.dumps({"id": 1, "scene": "sorting", "program": SHORT}) + "\n")
    limit = 200 * 1024**2
    done = subprocess.run([*CLI, "batch", str(src), "-o", str(tmp_path / "out.jsonl"), "--workers", "1"],
                          capture_output=True, text=True, timeout=600, preexec_fn=_hard_address_limit(limit))  # fmt: skip
    assert done.returncode == 2 and "could not start" in done.stderr and f"limit of {limit:,} bytes" in done.stderr
    assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_the_engine_reports_the_limit_its_workers_can_set():
    code = textwrap.dedent("""
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (2 * 1024**3, 2 * 1024**3))
        from robocritics.batch import LocalEngine
        from robocritics.child import address_space_limit
        print(LocalEngine(1).memory_bytes, LocalEngine(1, memory_bytes=1024**3).memory_bytes, address_space_limit(5 * 1024**3))
    """)
    out, _ = _child_peak_rss_mib(code)
    assert out.split() == [str(2 * GIB), str(GIB), str(2 * GIB)]


# --- --resume: the ids, not the rows; nested lines ---------------------------------------------------------------


def test_resume_holds_the_ids_not_the_rows(tmp_path):
    """200,000 earlier rows with 1,500-character error messages (300 MB of text): reading them for --resume must
    cost their ids (bound: 150 MiB over the interpreter's start; measured 23 MiB, where holding the rows took 565 MiB)."""
    out = tmp_path / "out.jsonl"
    message = "m" * 1_500
    with open(out, "w") as f:
        for i in range(200_000):
            f.write(json.dumps(error_row(f"row-{i}", "ProgramError", f"{i} {message}")) + "\n")
        for i in range(2_000):  # unreadable input lines reported earlier: kept as digests
            f.write(json.dumps(error_row(None, "RowError", f"input line {i}: not JSON {message}")) + "\n")
    code = textwrap.dedent("""
        import resource, sys
        from pathlib import Path
        from robocritics.cli.batch import finished_jsonl
        start = int(next(l for l in open('/proc/self/status') if l.startswith('VmHWM:')).split()[1])
        finished = finished_jsonl(Path(sys.argv[1]))
        print(len(finished.keys), len(finished.reported), start)
    """)
    out_text, peak_mib = _child_peak_rss_mib(code, str(out))
    keys, reported, start_kib = map(int, out_text.split())
    assert (keys, reported) == (200_000, 2_000)
    assert peak_mib - start_kib / 1024 < 150


@pytest.mark.parametrize(
    "line",
    [
        b"[" * 200_000 + b"]" * 200_000,
        json.dumps({**error_row("x", "E", "m"), "error": "@"}).replace('"@"', "[" * 100_000 + "]" * 100_000).encode(),
        b'{"id": ' + b"9" * 500_000 + b', "score": null, "flags": {}, "passed": false, "duration_s": 0, "samples": 0, "error": null}',
    ],
)
def test_resume_on_a_deeply_nested_line_is_a_usage_error_naming_the_line(capsys, tmp_path, line):
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    src.write_text(json.dumps({"id": "a", "scene": "sorting", "program": SHORT}) + "\n")
    out.write_bytes(json.dumps(error_row("kept", "RowError", "m")).encode() + b"\n" + line + b"\n")
    before = out.read_bytes()
    code = main(["batch", str(src), "-o", str(out), "--resume"])
    err = capsys.readouterr().err
    assert code == 2 and "line 2 of" in err and "is not an output row" in err and "Recursion" not in err, err
    assert out.read_bytes() == before


def test_resume_on_a_parquet_file_with_a_nested_error_cell_is_a_usage_error(capsys, tmp_path):
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    src, out = tmp_path / "in.jsonl", tmp_path / "out.parquet"
    src.write_text(json.dumps({"id": "a", "scene": "sorting", "program": SHORT}) + "\n")
    writer = cli_batch.ParquetWriter(out)
    writer.write(error_row(None, "RowError", "m"))
    writer.close()
    table = pq.read_table(out)
    nested = pa.array(["[" * 100_000 + "]" * 100_000], pa.string())
    pq.write_table(table.set_column(table.column_names.index("error"), "error", nested), out)
    code = main(["batch", str(src), "-o", str(out), "--resume"])
    err = capsys.readouterr().err
    assert code == 2 and "is not an output row" in err and "Recursion" not in err, err


def test_resume_keeps_the_rows_of_a_large_parquet_file_a_row_group_at_a_time(tmp_path):
    pytest.importorskip("pyarrow")
    out = tmp_path / "out.parquet"
    rows = [error_row(i, "ProgramError", f"row {i}") for i in range(1_000)]
    first = cli_batch.ParquetWriter(out)
    for row in rows:
        first.write(row)
    first.close()
    finished = cli_batch.finished_parquet(out)
    assert finished.keys == {json.dumps(i) for i in range(1_000)}
    again = cli_batch.ParquetWriter(out, resume=True)
    again.write(error_row("new", "RowError", "m"))
    again.close()
    assert cli_batch.parquet_rows(out) == [*rows, error_row("new", "RowError", "m")]


def test_resume_counts_outs_ids_missing_from_in_and_skips_a_repeated_id(capsys, tmp_path):
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    src.write_text("".join(json.dumps({"id": i, "scene": "sorting", "program": "home("}) + "\n" for i in ("a", "b", "a")))
    out.write_text("".join(json.dumps(error_row(i, "RowError", "kept")) + "\n" for i in ("a", "z", "y")))
    assert main(["batch", str(src), "-o", str(out), "--resume", "--workers", "1"]) == 0
    err = capsys.readouterr().err
    assert "note: 2 rows of" in err and "(2 kept from OUT)" in err, err
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["id"] for r in rows] == ["a", "z", "y", "b"]


_ids = st.one_of(st.none(), st.integers(-(10**19), 10**19), st.text(min_size=1, max_size=20))


@given(ids=st.lists(_ids, max_size=40), messages=st.lists(st.text(max_size=30), min_size=1, max_size=5))
@settings(max_examples=40, deadline=None)
def test_the_ids_read_for_resume_equal_those_of_every_row_read_whole(tmp_path_factory, ids, messages):
    """The streaming readers (JSONL line by line, Parquet a row group at a time, only three columns) against the
    obvious reference: every row parsed whole, its id's JSON text, or its error's JSON for an id-less row."""
    pytest.importorskip("pyarrow")
    directory = tmp_path_factory.mktemp("resume")
    rows = [error_row(i, "RowError", messages[n % len(messages)]) for n, i in enumerate(ids)]
    jsonl, parquet = directory / "out.jsonl", directory / "out.parquet"
    jsonl.write_text("".join(json.dumps(r) + "\n" for r in rows))
    writer = cli_batch.ParquetWriter(parquet)
    for r in rows:
        writer.write(r)
    writer.close()
    want_keys = {json.dumps(r["id"]) for r in rows if r["id"] is not None}
    want_reported = {cli_batch.error_digest(r["error"]) for r in rows if r["id"] is None}
    for finished in (cli_batch.finished_jsonl(jsonl), cli_batch.finished_parquet(parquet)):
        assert (finished.keys, finished.reported) == (want_keys, want_reported)
