"""Benchmark: the collaborative-operation critics (contact_speed, separation, payload) on the workbench runs.

Both example programs of the bundled ``workbench`` scene are simulated once, then each critic's ``check`` is timed
(CPU-time median of ``--repeats`` runs; other processes on a shared machine disturb CPU time less than wall time),
beside the five paper critics for scale. ``--unpruned`` also times contact_speed's and separation's distances
computed for every (sample, part, body capsule) triple, the plain version the pruned one is tested against.

Reproduce::

    .venv/bin/python benchmarks/bench_cobot.py
    .venv/bin/python benchmarks/bench_cobot.py --repeats 9 --unpruned
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from robocritics.critic import get_critics
from robocritics.critic.builtin.cobot import part_body_distances, part_body_nearest, robot_parts
from robocritics.humans import scene_bodies
from robocritics.scene import Scene
from robocritics.pipeline import simulate

ROOT = Path(__file__).resolve().parents[1]
CRITICS = ("joint_speed", "space_usage", "collision", "end_effector_pose", "pinch_point", "contact_speed",
           "separation", "payload")


def cpu_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.process_time()
        fn()
        times.append((time.process_time() - start) * 1000)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--unpruned", action="store_true", help="also time the distances without pruning")
    args = parser.parse_args()
    scene = Scene.builtin("workbench")
    critics = get_critics()
    for program in ("workbench_collaborative", "workbench_naive"):
        run = simulate((ROOT / "examples" / "programs" / f"{program}.py").read_text(), scene)
        print(f"{program}: {len(run.trajectory)} samples, {run.trajectory.duration_s:.1f} s of motion")
        for name in CRITICS:
            critic = critics[name]
            params = critic.Params()
            call = lambda c=critic, p=params: c.check(run, p)  # noqa: E731
            call()
            print(f"  {name:18s} {cpu_ms(call, args.repeats):8.1f} ms CPU")
        if args.unpruned:
            parts, body = robot_parts(run), scene_bodies(scene)[0]
            for label, fn in (("every distance", lambda: part_body_distances(parts, body)),
                              ("pruned at 0.1 m", lambda: part_body_distances(parts, body, within_m=0.1)),
                              ("nearest capsule", lambda: part_body_nearest(parts, body))):
                print(f"  distances, {label:16s} {cpu_ms(fn, args.repeats):8.1f} ms CPU")


if __name__ == "__main__":
    main()
