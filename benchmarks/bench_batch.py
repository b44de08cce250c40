"""Batch throughput: programs/s and per-task overhead of the serial baseline, the local engine and Ray.

The bundled example programs, repeated to ROWS rows (default 60), evaluated:
serial in-process (one warm robot: simulate + critique; one BLAS thread, set before numpy loads, as the command
line does), the local engine at 1 and 2 workers, and Ray at
2 workers (if ray is installed). Workers are started and warmed up before the clock starts (start-up is
reported on its own). CPU is the workers' own (from /proc/<pid>/stat) plus this process's. Per-task
overhead is ``workers * wall / rows - serial wall / rows``: what a row costs beyond doing it in-process.
Run:
    .venv/bin/python benchmarks/bench_batch.py [ROWS]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from robocritics._threads import single_threaded_blas  # noqa: E402 - imports nothing heavy

single_threaded_blas()  # idle OpenBLAS threads would add CPU to the serial row (the workers have one thread)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _table import print_table  # noqa: E402

PROGRAMS = Path(__file__).resolve().parent.parent / "examples" / "programs"


def cpu_of(pids) -> float:
    """utime + stime of the processes ``pids``, s."""
    from robocritics.child import cpu_seconds

    return sum(cpu_seconds(pid) for pid in pids)


def make_rows(n: int) -> list[dict]:
    programs = sorted(PROGRAMS.glob("*.py"))
    return [
        {"id": i, "scene": programs[i % len(programs)].stem.split("_")[0], "program": programs[i % len(programs)].read_text()}
        for i in range(n)
    ]


def serial(rows) -> tuple[float, float]:
    from robocritics.batch.rows import SceneCache, check_row, evaluate_job
    from robocritics.robot.model import Robot

    robot, scenes = Robot.ur3e(), SceneCache()
    for row in rows[:6]:  # warm-up: scenes, collision models, caches
        evaluate_job(check_row(row), robot, scenes)
    wall, cpu = time.perf_counter(), time.process_time()
    for row in rows:
        assert evaluate_job(check_row(row), robot, scenes)["error"] is None
    return time.perf_counter() - wall, time.process_time() - cpu


def engine_run(engine, pids, rows, workers) -> tuple[float, float, float]:
    from robocritics.batch import evaluate

    started = time.perf_counter()
    list(evaluate(rows[: 2 * workers], engine))  # start and warm every worker
    startup = time.perf_counter() - started
    worker_pids = pids()
    wall, cpu, own = time.perf_counter(), cpu_of(worker_pids), time.process_time()
    out = list(evaluate(rows, engine))
    wall = time.perf_counter() - wall
    cpu = cpu_of(worker_pids) - cpu + time.process_time() - own
    assert len(out) == len(rows) and all(r["error"] is None for r in out), [r["error"] for r in out if r["error"]][:3]
    return wall, cpu, startup


def main() -> None:
    from robocritics.batch import LocalEngine

    n = int(sys.argv[1]) if len(sys.argv) > 1 else 60
    rows = make_rows(n)
    table = [("engine", "programs/s  wall s  CPU s  CPU ms/program  overhead ms/task  start-up s")]
    s_wall, s_cpu = serial(rows)
    table.append(("serial in-process", f"{n / s_wall:10.2f}  {s_wall:6.1f}  {s_cpu:5.1f}  {1000 * s_cpu / n:14.0f}  {0:16.0f}  {0:10.1f}"))

    def add(name, workers, wall, cpu, startup):
        overhead = 1000 * (workers * wall / n - s_wall / n)
        table.append((name, f"{n / wall:10.2f}  {wall:6.1f}  {cpu:5.1f}  {1000 * cpu / n:14.0f}  {overhead:16.0f}  {startup:10.1f}"))

    for workers in (1, 2):
        with LocalEngine(workers) as engine:
            add(f"local, {workers} worker{'s' * (workers > 1)}", workers, *engine_run(engine, lambda: [w.pid for w in engine._pool], rows, workers))
    try:
        import ray
    except ImportError:
        table.append(("ray, 2 workers", "skipped: ray is not installed (pip install 'robocritics[ray]')"))
    else:
        from robocritics.batch.ray_engine import RayEngine

        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        try:
            with RayEngine(2) as engine:
                add("ray, 2 workers", 2, *engine_run(engine, engine.pids, rows, 2))
        finally:
            ray.shutdown()
    print_table("bench_batch", f"{n} rows of the 6 bundled programs", table, None)


if __name__ == "__main__":
    main()
