"""Batch evaluation on the local engine and the ``robocritics batch`` command (real worker processes, no mocks).

Workers are real spawn children; crashes are real (the test kills a worker while it works); limits are real
(a tiny timeout against a legal program that plans ~140 s of motion). Engines are shared where a test leaves
them as it found them, since a worker takes a few seconds to start.
"""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from robocritics.batch import BatchError, LocalEngine, evaluate, reward
from robocritics.batch.local import WORKER_ENV
from robocritics.batch.rows import OUTPUT_KEYS
from robocritics.cli.batch import Progress, finished_jsonl
from robocritics.critic import critique
from robocritics.scene import Scene
from robocritics.pipeline import simulate

PROGRAMS = Path(__file__).resolve().parent.parent / "examples" / "programs"
NAIVE = (PROGRAMS / "sorting_naive.py").read_text()
CAREFUL = (PROGRAMS / "sorting_careful.py").read_text()
# Legal and long: 240 distinct targets, ~140 s of motion, ~2 s of planning on an idle core.
LONG = (
    "for i in range(120):\n"
    "    move_to(0.25 + 0.0005 * i, 0.15 - 0.001 * i, 0.25)\n"
    "    move_to(0.3, -0.1 + 0.0005 * i, 0.3)\n"
)
SHORT = "move_above(green_apple)\nhome()\n"
PARENT_ENV = {k: os.environ.get(k) for k in WORKER_ENV}  # before any worker starts
CLI = [sys.executable, "-m", "robocritics.cli"]


@pytest.fixture(scope="module")
def engine():
    with LocalEngine(2) as pool:
        yield pool


def _by_id(rows):
    rows = list(rows)
    ids = [r["id"] for r in rows]
    assert len(ids) == len(set(map(json.dumps, ids))), f"an id came back twice: {ids}"
    return {r["id"]: r for r in rows}


def test_rows_equal_in_process_simulate_and_critique(engine):
    rows = [{"id": p.stem, "scene": p.stem.split("_")[0], "program": p.read_text()} for p in sorted(PROGRAMS.glob("*.py"))]
    out = _by_id(evaluate(rows, engine))
    assert set(out) == {r["id"] for r in rows}
    for row in rows:
        execution = simulate(row["program"], Scene.builtin(row["scene"]))
        report = critique(execution)
        got = out[row["id"]]
        assert tuple(got) == OUTPUT_KEYS
        assert got["error"] is None
        assert got["score"] == report.score
        assert got["flags"] == {v.critic: v.flag.value for v in report.verdicts}
        assert got["passed"] is report.passed
        assert got["samples"] == report.samples == len(execution.trajectory)
        assert got["duration_s"] > 0
    assert out["sorting_careful"]["score"] == 10.0 and out["sorting_naive"]["score"] < 10.0


def test_a_row_names_its_bundled_arm(engine):
    """A row's ``"robot"`` runs it on that bundled arm: the row equals in-process simulate and critique on it,
    a scene made for the UR5e runs on the row that names it and is an error row on the default UR3e, and a
    name that is not a bundled arm is a RowError naming the field."""
    from robocritics import Robot

    made_for_ur5e = {**json.loads(Scene.builtin("sorting").model_dump_json()), "robot": "ur5e"}
    rows = [
        {"id": "ur5e", "scene": "sorting", "program": SHORT, "robot": "ur5e"},
        {"id": "panda", "scene": "sorting", "program": SHORT, "robot": "panda"},
        {"id": "scene-ur5e", "scene": made_for_ur5e, "program": SHORT, "robot": "ur5e"},
        {"id": "scene-ur5e-default", "scene": made_for_ur5e, "program": SHORT},
        {"id": "kuka", "scene": "sorting", "program": SHORT, "robot": "kuka"},
        {"id": "urdf", "scene": "sorting", "program": SHORT, "robot": "arm.urdf"},
        {"id": "number", "scene": "sorting", "program": SHORT, "robot": 5},
        {"id": "list", "scene": "sorting", "program": SHORT, "robot": ["ur5e"]},
    ]
    out = _by_id(evaluate(rows, engine))
    for name in ("ur5e", "panda"):
        execution = simulate(SHORT, Scene.builtin("sorting"), robot=Robot.panda() if name == "panda" else Robot.ur(name))
        report = critique(execution)
        assert out[name]["error"] is None, out[name]["error"]
        assert (out[name]["score"], out[name]["samples"]) == (report.score, report.samples)
        assert out[name]["flags"] == {v.critic: v.flag.value for v in report.verdicts}
    on_ur3e = critique(simulate(SHORT, Scene.builtin("sorting")))
    assert on_ur3e.samples not in (out["ur5e"]["samples"], out["panda"]["samples"])  # not the default arm's run
    assert out["scene-ur5e"]["error"] is None
    assert out["scene-ur5e-default"]["error"]["type"] == "SceneError"
    for key in ("kuka", "urdf", "number", "list"):
        assert out[key]["error"]["type"] == "RowError", key
        assert "'robot' must be a bundled arm's name (ur3e, ur5e, ur10e, ur16e, panda)" in out[key]["error"]["message"]


def test_goals_critics_params_and_inline_scene(engine):
    scene = json.loads(Scene.builtin("sorting").model_dump_json())
    rows = [
        {"id": "met", "scene": "sorting", "program": CAREFUL, "goal": "green_apple in white_box"},
        {"id": "unmet", "scene": scene, "program": SHORT, "goal": ["green_apple in white_box"]},
        {"id": "two", "scene": "sorting", "program": NAIVE, "critics": "joint_speed,collision"},
        {"id": "strict", "scene": "sorting", "program": CAREFUL, "critics": ["joint_speed"],
         "params": {"joint_speed": {"warn_speed_m_s": 0.01, "max_speed_m_s": 0.02}}},
    ]  # fmt: skip
    out = _by_id(evaluate(rows, engine))
    assert out["met"]["flags"]["task_outcome"] == "OK" and out["met"]["passed"]
    assert out["unmet"]["flags"]["task_outcome"] == "ERROR" and not out["unmet"]["passed"]
    assert list(out["two"]["flags"]) == ["joint_speed", "collision"]
    assert out["strict"]["flags"] == {"joint_speed": "ERROR"}


def test_every_kind_of_bad_input_is_an_error_row_and_the_batch_goes_on(engine):
    rows = [
        {"scene": "sorting", "program": SHORT},  # no id
        {"id": ["a"], "scene": "sorting", "program": SHORT},
        {"id": True, "scene": "sorting", "program": SHORT},
        {"id": "p-int", "scene": "sorting", "program": 42},
        {"id": "s-int", "scene": 7, "program": SHORT},
        {"id": "no-scene", "program": SHORT},
        {"id": "extra", "scene": "sorting", "program": SHORT, "colour": "red"},
        {"id": "goal-int", "scene": "sorting", "program": SHORT, "goal": 3},
        {"id": "params-bad", "scene": "sorting", "program": SHORT, "params": {"joint_speed": 1}},
        "not a row",
        {"id": "syntax", "scene": "sorting", "program": "move_to(0.3,\n"},
        {"id": "runtime", "scene": "sorting", "program": "home()\nmove_above(no_such_object)\n"},
        {"id": "scene-name", "scene": "kitchen", "program": SHORT},
        {"id": "scene-file", "scene": "/nonexistent/scene.json", "program": SHORT},
        {"id": "scene-obj", "scene": {"objects": [{"id": "x", "size": "big"}]}, "program": SHORT},
        {"id": "goal-bad", "scene": "sorting", "program": SHORT, "goal": "green_apple under the table"},
        {"id": "critic-bad", "scene": "sorting", "program": SHORT, "critics": ["no_such_critic"]},
        {"id": "good", "scene": "sorting", "program": SHORT},
        {"id": "good", "scene": "sorting", "program": NAIVE},  # duplicate
    ]
    out = list(evaluate(rows, engine))
    assert len(out) == len(rows)
    errors = [r for r in out if r["error"] is not None]
    assert len(errors) == len(rows) - 1
    for r in errors:
        assert tuple(r) == OUTPUT_KEYS and r["score"] is None and r["flags"] == {} and r["passed"] is False
        assert set(r["error"]) == {"type", "message", "line"} and r["error"]["message"]
    by_id = {}
    for r in out:
        by_id.setdefault(json.dumps(r["id"]), []).append(r)
    assert [r["error"]["type"] for r in by_id["null"]] == ["RowError"] * 4  # no id, list id, bool id, not a mapping
    assert by_id['"syntax"'][0]["error"]["type"] == "ProgramError" and by_id['"syntax"'][0]["error"]["line"] == 1
    assert by_id['"runtime"'][0]["error"]["line"] == 2
    assert "kitchen" in by_id['"scene-name"'][0]["error"]["message"]
    assert {by_id[f'"{k}"'][0]["error"]["type"] for k in ("scene-name", "scene-file", "scene-obj")} == {"SceneError"}
    assert by_id['"goal-bad"'][0]["error"]["type"] == "GoalError"
    assert by_id['"critic-bad"'][0]["error"]["type"] == "CriticError"
    good = sorted(by_id['"good"'], key=lambda r: r["error"] is None)  # rows come back as they finish
    assert [r["error"] is None for r in good] == [False, True]
    assert "duplicate id" in good[0]["error"]["message"] and good[1]["score"] is not None
    for key in ("p-int", "s-int", "no-scene", "extra", "goal-int", "params-bad"):
        assert by_id[f'"{key}"'][0]["error"]["type"] == "RowError", key


def test_workers_run_with_single_threaded_blas_and_malloc_tunables(engine):
    list(evaluate([{"id": 1, "scene": "sorting", "program": SHORT}], engine))
    for w in engine._pool:
        environ = Path(f"/proc/{w.pid}/environ").read_bytes().split(b"\0")
        for name, value in WORKER_ENV.items():
            if name == "GLIBC_TUNABLES":  # glibc rewrites this one in the process's own copy as it parses it
                assert any(e.startswith(b"GLIBC_TUNABLES=glibc.malloc.mmap_threshold=") for e in environ)
            else:
                assert f"{name}={value}".encode() in environ
    assert {k: os.environ.get(k) for k in WORKER_ENV} == PARENT_ENV  # the parent's own environment is restored


def test_a_killed_worker_is_replaced_and_its_row_marked():
    with LocalEngine(1) as pool:
        rows = [{"id": "long", "scene": "sorting", "program": LONG}, {"id": "after", "scene": "sorting", "program": SHORT}]
        killed = []

        def kill_when_running():
            for _ in range(2000):
                running = pool.running()
                if "long" in running.values():
                    pid = next(p for p, i in running.items() if i == "long")
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
                    return
                time.sleep(0.01)

        killer = threading.Thread(target=kill_when_running)
        killer.start()
        out = _by_id(evaluate(rows, pool))
        killer.join(30)
        assert killed
        assert out["long"]["error"]["type"] == "WorkerDied" and "SIGKILL" in out["long"]["error"]["message"]
        assert out["after"]["error"] is None and out["after"]["score"] is not None
        assert pool.restarts == 1 and killed[0] not in [w.pid for w in pool._pool]


def test_a_row_over_its_timeout_is_marked_and_its_worker_replaced():
    with LocalEngine(1, timeout_s=0.05) as pool:
        (row,) = evaluate([{"id": "long", "scene": "sorting", "program": LONG}], pool)
        assert row["error"]["type"] == "WorkerTimeout" and "0.05 s" in row["error"]["message"]
        assert row["duration_s"] >= 0.05 and pool.restarts == 1


def test_a_worker_that_cannot_start_stops_the_batch_with_a_batch_error():
    with pytest.raises(BatchError, match="could not start"):
        list(evaluate([{"id": 1, "scene": "sorting", "program": SHORT}], workers=1, memory_bytes=64 * 1024**2))


def test_reward_formula_and_goal_gating(engine):
    programs = [CAREFUL, NAIVE, "move_to(0.3,\n", 5]
    scores = {r["id"]: r["score"] for r in evaluate([{"id": i, "scene": "sorting", "program": p} for i, p in enumerate(programs[:2])], engine)}
    assert reward(programs, "sorting", engine=engine) == [1.0, scores[1] / 10, 0.0, 0.0]
    gated = reward([CAREFUL, SHORT], "sorting", goal="green_apple in white_box", engine=engine)
    plain = reward([SHORT], "sorting", engine=engine)
    assert gated == [1.0, 0.0] and plain[0] > 0.0


def test_progress_reports_rate_and_eta_on_an_injected_clock():
    now = [100.0]
    stream = io.StringIO()
    progress = Progress(4, stream, clock=lambda: now[0], every=2)
    for t, row in ((1.0, {"error": None}), (2.0, {"error": {"type": "RowError"}}), (4.0, {"error": None})):
        now[0] = 100.0 + t
        progress.update(row)
    assert stream.getvalue() == "robocritics batch: 2/4 rows (50 %), 1 error rows, 1.00 rows/s, ETA 2 s\n"
    now[0] = 108.0
    progress.update({"error": None})
    progress.finish()
    assert stream.getvalue().splitlines()[1:] == [
        "robocritics batch: 4/4 rows (100 %), 1 error rows, 0.50 rows/s, ETA 0 s",
        "robocritics batch: 4 rows in 8.0 s, 1 error rows",
    ]


# --- the command ------------------------------------------------------------------------------------


def _write_rows(path: Path, rows, extra_lines=()):
    with open(path, "w") as f:
        for row in rows:
            f.write(json.dumps(row) + "\n")
        for line in extra_lines:
            f.write(line + "\n")


def _read_out(path: Path):
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_cli_streams_rows_as_they_finish(tmp_path):
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    _write_rows(src, [{"id": "slow", "scene": "sorting", "program": LONG + LONG}, {"id": "fast", "scene": "sorting", "program": SHORT}])
    proc = subprocess.Popen([*CLI, "batch", str(src), "-o", str(out), "--workers", "2"], stderr=subprocess.PIPE, text=True)
    try:
        seen = []
        for _ in range(6000):
            seen = out.read_text().splitlines() if out.exists() else []
            if seen or proc.poll() is not None:
                break
            time.sleep(0.02)
        still_running = proc.poll() is None
        assert [json.loads(line)["id"] for line in seen] == ["fast"]
        assert still_running, "the batch ended before its first row was read"
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert [r["id"] for r in _read_out(out)] == ["fast", "slow"]
    assert "2/2 rows (100 %)" in err and "rows/s" in err and "ETA" in err


def test_cli_resume_skips_done_ids_cuts_a_torn_line_and_reports_bad_lines_once(tmp_path):
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    rows = [{"id": f"r{i}", "scene": "sorting", "program": SHORT} for i in range(3)]
    _write_rows(src, rows, extra_lines=["{not json", "", "[1]"])
    first = subprocess.run([*CLI, "batch", str(src), "-o", str(out), "--workers", "1"], capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    done = _read_out(out)
    assert len(done) == 5
    bad = sorted(r["error"]["message"] for r in done if r["id"] is None)
    assert bad[0].startswith("input line 4:") and bad[1].startswith("input line 6:")
    # keep r0 (marked, to see it is not re-evaluated) and the bad-line rows; tear r1's line in the middle
    kept = [dict(r, duration_s=-1.0) if r["id"] == "r0" else r for r in done if r["id"] in ("r0", None)]
    torn = json.dumps(next(r for r in done if r["id"] == "r1"))[:40]
    out.write_text("".join(json.dumps(r) + "\n" for r in kept) + torn)
    second = subprocess.run([*CLI, "batch", str(src), "-o", str(out), "--resume", "--workers", "1"], capture_output=True, text=True, timeout=300)
    assert second.returncode == 0, second.stderr
    final = _read_out(out)  # every line parses: the torn one is gone
    assert sorted(json.dumps(r["id"]) for r in final) == sorted(['"r0"', '"r1"', '"r2"', "null", "null"])
    assert next(r for r in final if r["id"] == "r0")["duration_s"] == -1.0
    assert all(r["error"] is None for r in final if r["id"] in ("r1", "r2"))


@pytest.mark.parametrize(
    "args, message",
    [
        (["missing.jsonl", "-o", "out.jsonl"], "is not a file"),
        (["in.jsonl", "-o", "nodir/out.jsonl"], "does not exist"),
        (["in.jsonl", "-o", "out.jsonl", "--engine", "dask"], "invalid choice"),
        (["in.jsonl", "-o", "out.jsonl", "--workers", "0"], "at least 1"),
        (["in.jsonl"], "-o"),
    ],
)
def test_cli_bad_usage_exits_2_with_one_line(tmp_path, args, message):
    (tmp_path / "in.jsonl").write_text("")
    result = subprocess.run([*CLI, "batch", *args], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 2 and message in result.stderr and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_done_rows_of_a_file_with_only_a_torn_line(tmp_path):
    out = tmp_path / "out.jsonl"
    out.write_text('{"id": "a", "sco')
    assert len(finished_jsonl(out)) == 0 and out.read_text() == ""


def _vm_size_bytes(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmSize")


def test_a_row_over_the_memory_limit_is_marked_and_its_worker_replaced(engine):
    list(evaluate([{"id": 0, "scene": "sorting", "program": SHORT}], engine))
    warm = max(_vm_size_bytes(w.pid) for w in engine._pool)  # a warm worker's address space
    # room for a short program, not for planning 560 s of motion (~80 MB more, judged in chunks)
    with LocalEngine(1, memory_bytes=warm + 30 * 1024**2) as pool:
        rows = [{"id": i, "scene": "sorting", "program": p} for i, p in enumerate((SHORT, LONG + LONG, SHORT))]
        out = {r["id"]: r for r in evaluate(rows, pool)}
        assert out[1]["error"]["type"] == "WorkerMemory" and "address-space limit" in out[1]["error"]["message"]
        assert out[0]["error"] is None and out[2]["error"] is None and pool.restarts == 1


def test_the_ray_engine_without_ray_names_the_extra(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError, as when it is not installed
    with pytest.raises(BatchError, match=r"robocritics\[ray\]"):
        list(evaluate([{"id": 1, "scene": "sorting", "program": SHORT}], "ray"))
    from robocritics.cli.main import main

    src = tmp_path / "in.jsonl"
    _write_rows(src, [{"id": 1, "scene": "sorting", "program": SHORT}])
    assert main(["batch", str(src), "-o", str(tmp_path / "out.jsonl"), "--engine", "ray"]) == 2


def test_a_batch_abandoned_early_does_not_leak_its_rows_into_the_next(engine):
    rows = evaluate([{"id": f"old{i}", "scene": "sorting", "program": LONG} for i in range(4)], engine)
    first = next(rows)
    rows.close()  # the caller stops reading while workers are busy
    assert first["id"].startswith("old")
    out = list(evaluate([{"id": "new", "scene": "sorting", "program": SHORT}], engine))
    assert [r["id"] for r in out] == ["new"] and out[0]["error"] is None


def test_a_worker_is_replaced_by_a_fresh_one_after_max_rows_per_worker_rows():
    # a native library's per-program leak (coal's refused hulls) must not grow without bound in a warm worker
    rows = [{"id": i, "scene": "sorting", "program": SHORT} for i in range(5)]
    with LocalEngine(1, max_rows_per_worker=2) as pool:
        pids = []
        for row in evaluate(rows, pool):
            assert row["error"] is None
            pids.append(pool._pool[0].pid)  # the worker that will take the next row
        assert pool.recycled == 2 and pool.restarts == 0  # after rows 2 and 4; not counted as failures
        assert pids[0] != pids[1] == pids[2] != pids[3] == pids[4] and len(set(pids)) == 3
    with pytest.raises(ValueError, match="max_rows_per_worker"):
        LocalEngine(1, max_rows_per_worker=0)
