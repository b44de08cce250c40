"""The exact mesh path's cost: vendor arms from pip packages run bench_vendor_arms' scaled pick-and-place with
their links measured as their own meshes near contact (the default) and as fitted capsules only (the same
robot with ``capsule_meshes`` cleared), CPU per program (simulate + critique, warm, least of the repeats, the
two alternated), how many proximity values were refined (of all the trajectory's values) and the CPU spent in
``refine_near_contact``, beside the built-in UR3e. Also the collision and pinch-point values both ways: where
they differ, the capsules' was the looser reading. CPU time (process_time), not wall time.

Needs the test extra (example-robot-data, rtb-data, airo-models, pybullet).
Run: .venv/bin/python benchmarks/bench_link_meshes.py [REPEATS]
"""

from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path

from robocritics import Robot, critique, simulate
from robocritics.goals import parse_goals
import robocritics.planning.trace as trace

sys.path.insert(0, str(Path(__file__).parent))
from bench_vendor_arms import PROGRAM, arms, scene_for  # noqa: E402

_REFINED = {"values": 0, "cpu": 0.0}
_refine = trace.refine_near_contact


def _counting(rows, *args, **kwargs):
    t0 = time.process_time()
    n = _refine(rows, *args, **kwargs)
    _REFINED["values"] += n
    _REFINED["cpu"] += time.process_time() - t0
    _REFINED["all"] = _REFINED.get("all", 0) + rows.size
    return n


trace.refine_near_contact = _counting  # the hook build_trajectory calls, counted (the same function)


def run(robot: Robot, repeats: int) -> tuple[float, dict, dict[str, float]]:
    """Least CPU of simulate + critique, the refinement counts of one run, and the critics' values (m)."""
    scene = scene_for(robot.reach_m)
    goals = parse_goals(["apple in box"], scene)
    best = math.inf
    for _ in range(repeats):
        _REFINED.update(values=0, cpu=0.0, all=0)
        t0 = time.process_time()
        report = critique(simulate(PROGRAM, scene, robot), goals=goals)
        best = min(best, time.process_time() - t0)
    values = {v.critic: v.value for v in report.verdicts if v.critic in ("collision", "pinch_point")}
    return best, dict(_REFINED), values


def main(repeats: int = 3) -> None:
    warnings.simplefilter("ignore", DeprecationWarning)
    ur3e_cpu = run(Robot.ur3e(), repeats)[0]
    print(f"{'package':<19} {'arm':<16} {'mesh CPU s':>10} {'caps CPU s':>10} {'ratio':>6} {'refine s':>8} "
          f"{'refined':>8} {'of values':>9} {'vs UR3e':>7}  collision / pinch value m: mesh (capsules)")
    print(f"{'(built-in)':<19} {'UR3e':<16} {ur3e_cpu:>10.3f} {ur3e_cpu:>10.3f} {1.0:>6.2f} {0.0:>8.3f} {0:>8} {'-':>9} {1.0:>7.2f}")
    for package, name, path, kwargs in arms():
        if path is None or not Path(path).is_file() or "joint_limits" in kwargs:
            continue
        try:
            robot = Robot.from_urdf(path, **{"tool": "robotiq_2f85", **kwargs})
            simulate(PROGRAM, scene_for(robot.reach_m), robot)
        except Exception as exc:  # an arm that does not load or plan this program: bench_vendor_arms says why
            print(f"{package:<19} {name:<16} (skipped: {type(exc).__name__})")
            continue
        capsules = robot.copy()
        capsules.capsule_meshes = (None,) * len(robot.capsules)
        mesh_cpu = caps_cpu = math.inf
        for _ in range(2):  # alternated: the machine's load drifts
            cpu, counts, mesh_values = run(robot, repeats)
            mesh_cpu = min(mesh_cpu, cpu)
            cpu, _, caps_values = run(capsules, repeats)
            caps_cpu = min(caps_cpu, cpu)
        ref = run(Robot.ur3e(), repeats)[0]
        shown = " / ".join(f"{mesh_values[k]:.4f} ({caps_values[k]:.4f})" for k in ("collision", "pinch_point") if k in mesh_values)
        share = counts["values"] / max(counts["all"], 1)
        print(f"{package:<19} {name:<16} {mesh_cpu:>10.3f} {caps_cpu:>10.3f} {mesh_cpu / caps_cpu:>6.2f} {counts['cpu']:>8.3f} "
              f"{counts['values']:>8} {share:>9.2%} {mesh_cpu / ref:>7.2f}  {shown}")
    print(f"\nreproduce: .venv/bin/python benchmarks/bench_link_meshes.py {repeats}")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:]))
