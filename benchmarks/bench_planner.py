"""CPU of planning per bundled program (the sandbox interpreter, then Planner.run and finish), this tree against
another, and whether the two plan the same motion.

Each tree runs in its own fresh interpreter (one BLAS thread), the trees alternating over ROUNDS rounds; a child
plans every bundled program whose scene the tree has built in once to warm caches, then REPEATS times, and
reports the least CPU (``time.process_time``) per program of ``run_program`` (parse, check, interpret: the Plan)
and of ``Planner(...).run(plan)`` + ``finish()`` (IK, timing, sampling: the joint samples), and the planned
arrays. The table shows each number's least over the rounds, the mean over the programs both trees have, and the
largest difference between the two trees' joint samples (rad) and times (s), which must be ~0: the planner's
output is to stay the same.

"Before" is the source tree of a commit (default: ``main``), extracted with ``git archive`` into a temporary
directory, or ``--before-src DIR`` (a tree with ``DIR/src``). The robot is the UR3e at 125 Hz.

Run:
    .venv/bin/python benchmarks/bench_planner.py [REPEATS] [ROUNDS] [--before COMMIT | --before-src DIR]
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ROOT / "examples" / "programs"


def child(repeats: int, out_path: str) -> None:
    """Plan every bundled program REPEATS times; write the least CPU per program and the planned arrays."""
    import numpy as np

    from robocritics import Robot, Scene
    from robocritics.errors import SceneError
    from robocritics.program.sandbox import run_program

    try:
        from robocritics.planning.planner import Planner, PlannerSettings
    except ModuleNotFoundError:  # c045a0b kept the planner in robocritics.robot
        from robocritics.robot.planner import Planner, PlannerSettings

    robot = Robot.ur3e()
    result: dict[str, dict] = {}
    arrays = {}
    for path in sorted(PROGRAMS.glob("*.py")):
        try:
            scene = robot.scene_for(Scene.builtin(path.stem.split("_")[0]))
        except SceneError:  # an older tree lacks the newer scenes
            continue
        source = path.read_text()
        best_interp = best_plan = float("inf")
        for i in range(repeats + 1):  # the first round warms caches
            t0 = time.process_time()
            plan = run_program(source, scene)
            t1 = time.process_time()
            planner = Planner(scene, robot, 125.0, PlannerSettings())
            planner.run(plan)
            q, t = planner.finish()[:2]
            t2 = time.process_time()
            if i:
                best_interp, best_plan = min(best_interp, t1 - t0), min(best_plan, t2 - t1)
        result[path.stem] = {"interpreter ms": 1000 * best_interp, "planner ms": 1000 * best_plan}
        arrays[f"{path.stem}.q"], arrays[f"{path.stem}.t"] = q, t
    np.savez(out_path, **arrays)
    print(json.dumps(result))


def measure(src: Path | None, repeats: int, out_path: str) -> dict[str, dict]:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    if src is not None:
        env["PYTHONPATH"] = str(src / "src")
    done = subprocess.run(
        [sys.executable, __file__, "--child", str(repeats), out_path], env=env, cwd=ROOT, capture_output=True,
        text=True, check=True,
    )  # fmt: skip
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    import numpy as np

    args = sys.argv[1:]
    if args[:1] == ["--child"]:
        child(int(args[1]), args[2])
        return
    scratch = tempfile.TemporaryDirectory()
    if "--before-src" in args:
        i = args.index("--before-src")
        before_src, before_name = Path(args[i + 1]), f"the tree in {args[i + 1]}"
        del args[i : i + 2]
    else:
        commit = "main"
        if "--before" in args:
            i = args.index("--before")
            commit = args[i + 1]
            del args[i : i + 2]
        archive = subprocess.run(["git", "archive", commit], cwd=ROOT, capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", scratch.name], input=archive, check=True)
        before_src, before_name = Path(scratch.name), f"commit {commit}"
    repeats = int(args[0]) if args else 7
    rounds = int(args[1]) if len(args) > 1 else 3
    outs = {w: os.path.join(scratch.name, f"{w}.npz") for w in ("before", "now")}
    runs: dict[str, list[dict[str, dict]]] = {"before": [], "now": []}
    for _ in range(rounds):
        runs["before"].append(measure(before_src, repeats, outs["before"]))
        runs["now"].append(measure(None, repeats, outs["now"]))
    best = {w: {p: {k: min(r[p][k] for r in rs) for k in rs[0][p]} for p in rs[0]} for w, rs in runs.items()}
    both = [p for p in best["now"] if p in best["before"]]
    a, b = np.load(outs["before"]), np.load(outs["now"])
    dq = max(float(np.max(np.abs(a[f"{p}.q"] - b[f"{p}.q"]))) for p in both)
    dt = max(float(np.max(np.abs(a[f"{p}.t"] - b[f"{p}.t"]))) for p in both)
    w = max(len(p) for p in best["now"]) + 16
    print(f"bench_planner — least over {rounds} rounds of the least of {repeats}, UR3e at 125 Hz, one BLAS thread")
    print(f"{'':<{w}}  {'before':>8}  {'now':>8}  {'before/now':>10}")
    for part in ("interpreter ms", "planner ms"):
        for p in best["now"]:
            n = best["now"][p][part]
            if p in best["before"]:
                o = best["before"][p][part]
                print(f"{p + ' ' + part:<{w}}  {o:8.3f}  {n:8.3f}  {o / n:10.2f}")
            else:
                print(f"{p + ' ' + part:<{w}}  {'-':>8}  {n:8.3f}")
        o = statistics.fmean(best["before"][p][part] for p in both)
        n = statistics.fmean(best["now"][p][part] for p in both)
        print(f"{'mean ' + part:<{w}}  {o:8.3f}  {n:8.3f}  {o / n:10.2f}")
    print(f"largest difference of the planned motion: {dq:.3g} rad, {dt:.3g} s")
    print(f"before: {before_name}, measured in this run")
    print(f"reproduce: .venv/bin/python benchmarks/bench_planner.py {' '.join(sys.argv[1:])}")


if __name__ == "__main__":
    main()
