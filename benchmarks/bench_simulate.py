"""simulate() of the careful sorting program, warm (import and first call excluded).

Run: .venv/bin/python benchmarks/bench_simulate.py
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

from robocritics.critic import BUILTIN_CRITICS
from robocritics import Robot, Scene, critique, simulate

ROOT = Path(__file__).resolve().parents[1]


def main(repeats: int = 15) -> None:
    robot = Robot.ur3e()
    rows = []
    for task in ("sorting", "recycling", "breakfast"):
        source = (ROOT / "examples" / "programs" / f"{task}_careful.py").read_text()
        scene = Scene.builtin(task)
        execution = simulate(source, scene, robot)  # warm-up
        times, crit = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            execution = simulate(source, scene, robot)
            t1 = time.perf_counter()
            critique(execution, critics=BUILTIN_CRITICS)
            times.append(t1 - t0)
            crit.append(time.perf_counter() - t1)
        traj = execution.trajectory
        rows.append(
            (
                f"{task}_careful",
                len(traj),
                f"{traj.duration_s:.1f}",
                statistics.median(times) * 1e3,
                sorted(times)[int(0.9 * (len(times) - 1))] * 1e3,
                statistics.median(crit) * 1e3,
            )
        )
    print(f"{'program':<20} {'samples':>8} {'motion s':>9} {'simulate median ms':>19} {'p90 ms':>8} {'critique ms':>12}")
    for name, n, dur, med, p90, crit_ms in rows:
        print(f"{name:<20} {n:>8} {dur:>9} {med:>19.1f} {p90:>8.1f} {crit_ms:>12.1f}")
    print(f"\nreproduce: {sys.executable} benchmarks/bench_simulate.py")


if __name__ == "__main__":
    main()
