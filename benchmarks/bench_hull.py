"""CPU time of the hull (geometry/hull.py): coal's Qhull path, the numpy quickhull, scipy's Qhull, on point sets the
space_usage critic meets (a sphere's worth of vertices, a fan coal refuses, a simulated base sweep's exact hull).

Each time is the best of ``--repeat`` runs of ``time.process_time``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _table import print_table  # noqa: E402


def best(f, P, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.process_time()
        f(P)
        times.append(time.process_time() - t)
    return min(times)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    from scipy.spatial import ConvexHull

    from robocritics import Scene, simulate
    from robocritics.critic.builtin.space_usage import hull_points
    from robocritics.geometry.hull import convex_hull, quickhull

    rng = np.random.default_rng(0)
    sphere = rng.normal(size=(16000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    a = np.linspace(0, 2 * np.pi, 10000, endpoint=False)
    fan = np.r_[np.c_[np.cos(a), np.sin(a), np.zeros(len(a))], [[0, 0, 1.0], [0, 0, -1.0]]]
    program = "lib.set_speed(0.05)\nfor i in range(5):\n    lib.move_to(0.2, 0.2, 0.25)\n    lib.move_to(-0.2, 0.2, 0.25)\n"
    X = simulate(program, Scene.builtin("sorting")).trajectory.positions
    cases = {
        "sphere, 16000 vertices": sphere,
        "fan, a vertex with 10000 neighbours": fan,
        "base sweep, decimated (0.5 mm)": hull_points(X, 0.0005)[0],
        "base sweep, exact hull": hull_points(X, 0.0)[0],
    }
    rows = [("case (points)", "convex_hull / quickhull / scipy ConvexHull, s")]
    for name, P in cases.items():
        t = [best(f, P, args.repeat) for f in (convex_hull, quickhull, ConvexHull)]
        rows.append((f"{name} ({len(P)})", " / ".join(f"{x:.3f}" for x in t)))
    print_table("bench_hull", "convex hull CPU time", rows, argv)


if __name__ == "__main__":
    main()
