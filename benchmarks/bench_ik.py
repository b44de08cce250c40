"""UR3e inverse-kinematics benchmark: closed form vs Pinocchio DLS vs lively-tk.

Reproduce with::

    .venv/bin/python benchmarks/bench_ik.py            # 200 targets, seed 7
    .venv/bin/python benchmarks/bench_ik.py --n 1000 --seed 1
    .venv/bin/python benchmarks/bench_ik.py --lines       # also ur_ik_line along straight lines
    .venv/bin/python benchmarks/bench_ik.py --before-src /tmp/c045a0b   # CPU per solve against another tree
    .venv/bin/python benchmarks/bench_ik.py --all-many    # ur_ik_all_many (n poses in one call) vs ur_ik_all

What is measured
----------------
* 200 reachable targets (fixed seed): joint vectors drawn uniformly in
  [-pi, pi]^6, flange poses by forward kinematics of the UR3e e-series DH.
  Every solver gets the same seed configuration per target: the generating
  configuration plus N(0, 0.2 rad) noise per joint (what a motion planner's
  previous waypoint looks like). Joint limits are the UR3e's +-2 pi.
* Time per solve (wall clock, ``time.perf_counter_ns``), median and 90th
  percentile in microseconds. Only the solve is timed: building models,
  converting the target to each solver's input type and resetting a solver's
  state to the seed happen outside the timed region (which favours lively and
  Pinocchio, not us).
* Accuracy: the returned joints are pushed through ``dh_forward`` (Pinocchio) and compared
  with the target: position error (m) and rotation angle error (rad). Maxima
  over all targets are reported, plus how many targets were solved to 1e-6 m
  and 1e-6 rad.
* Solvers:
  - ``robocritics ur_ik``: closed form searched branch-and-bound for the
    branch nearest to the seed within the limits, FK-verified (closed-form FK,
    or certified exact: no step clipped, a target rotation that is one) (the
    function the planner calls; the search in C, ``robot/_ur_nearest.c``, where it is built).
  - ``robocritics ur_ik_all``: all (up to 8) branches, each FK-verified.
  - ``Pinocchio DLS``: ``robocritics.robot.ik_numeric.numeric_ik`` on a Pinocchio model
    built from a URDF generated from the same DH table (tol 1e-10).
  - ``lively-tk``: the optimisation IK of the paper authors' prototype
    (``lively.Solver`` with a PositionMatch (weight 50) and an
    OrientationMatch (weight 25) objective on ``tool0``, URDF generated from
    the same DH table, state reset to the seed before each target). "1 call"
    is one ``solve`` (how the prototype used it); "converged" repeats
    ``solve`` until the joints move less than 1e-6 rad between calls (at
    most 50 calls) and times all calls.
* ``--before-src DIR``: ``ur_ik`` and ``ur_ik_all`` of this tree against the tree extracted in ``DIR`` (e.g.
  ``mkdir /tmp/c045a0b && git archive c045a0b | tar -x -C /tmp/c045a0b``), CPU time (``time.process_time``) per
  solve over the same targets, the least of 9 passes, each tree in its own fresh interpreter, the trees
  alternating over 5 rounds (least per tree): on this shared machine only numbers measured side by side compare.
* ``--lines``: ``ur_ik_line`` (the planner's dense IK of a straight line, each pose seeded by the previous
  solution) on fingers-down lines of 30 to 1000 poses across the UR3e's workspace, against ``ur_ik`` pose by
  pose: CPU time (``time.process_time``) per pose, the minimum of 7 repeats (the lines of the bundled
  programs have 17-43 poses; from ``ik._VECTORISED_WALK_POSES`` poses on the line is solved vectorised).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Iterator

import numpy as np
import pinocchio as pin

from robocritics.robot.ik import UR3E_DH, dh_forward, dh_urdf, ur_ik, ur_ik_all, ur_ik_line

REPRO = ".venv/bin/python benchmarks/bench_ik.py"
LOWER = np.full(6, -2.0 * math.pi)
UPPER = np.full(6, 2.0 * math.pi)
JOINTS = [f"joint_{i}" for i in range(1, 7)]


@contextlib.contextmanager
def quiet_stdout() -> Iterator[None]:
    """Silence fd 1 (lively's Rust core prints the parsed URDF on construction)."""
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(devnull)
        os.close(saved)


def make_targets(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q_true (n, 6), poses (n, 4, 4), seeds (n, 6))."""
    rng = np.random.default_rng(seed)
    q_true = rng.uniform(-math.pi, math.pi, (n, 6))
    poses = dh_forward(UR3E_DH, q_true)
    seeds = np.clip(q_true + rng.normal(0.0, 0.2, (n, 6)), LOWER, UPPER)
    return q_true, poses, seeds


def pose_error(q: np.ndarray, T: np.ndarray) -> tuple[float, float]:
    F = dh_forward(UR3E_DH, q)
    dp = float(np.linalg.norm(F[:3, 3] - T[:3, 3]))
    dr = float(np.linalg.norm(pin.log3(F[:3, :3].T @ T[:3, :3])))
    return dp, dr


class Result:
    def __init__(self, name: str, times_ns: list[int], errors: list[tuple[float, float]], failed: int):
        self.name = name
        self.times_us = np.array(times_ns, dtype=float) / 1e3
        self.errors = np.array(errors, dtype=float).reshape(-1, 2)
        self.failed = failed

    @property
    def median(self) -> float:
        return float(np.median(self.times_us))

    @property
    def p90(self) -> float:
        return float(np.percentile(self.times_us, 90))


def run(
    name: str,
    n: int,
    prepare: Callable[[int], object],
    solve: Callable[[int, object], np.ndarray],
    poses: np.ndarray,
    warmup: int = 20,
) -> Result:
    """Time ``solve(i, prepare(i))`` for every target; errors computed afterwards."""
    for i in range(min(warmup, n)):
        try:
            solve(i, prepare(i))
        except Exception:
            pass
    times, errors, failed = [], [], 0
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        for i in range(n):
            arg = prepare(i)
            t0 = time.perf_counter_ns()
            try:
                q = solve(i, arg)
            except Exception:
                times.append(time.perf_counter_ns() - t0)
                failed += 1
                errors.append((math.inf, math.inf))
                continue
            times.append(time.perf_counter_ns() - t0)
            errors.append(q)  # type: ignore[arg-type]
    finally:
        if gc_was_enabled:
            gc.enable()
    errs = []
    for i, e in enumerate(errors):
        if isinstance(e, tuple):
            errs.append(e)
        else:
            q = np.asarray(e, dtype=float)
            if q.ndim == 2:  # all branches: worst branch
                per = [pose_error(row, poses[i]) for row in q] or [(math.inf, math.inf)]
                errs.append((max(p for p, _ in per), max(r for _, r in per)))
            else:
                errs.append(pose_error(q, poses[i]))
    return Result(name, times, errs, failed)


def bench_ours(poses: np.ndarray, seeds: np.ndarray) -> list[Result]:
    n = len(poses)
    r1 = run("robocritics ur_ik (analytic)", n, lambda i: None,
             lambda i, _: ur_ik(UR3E_DH, poses[i], seeds[i], LOWER, UPPER), poses)
    r2 = run("robocritics ur_ik_all (8 branches)", n, lambda i: None,
             lambda i, _: ur_ik_all(UR3E_DH, poses[i]), poses)
    return [r1, r2]


def bench_pinocchio(poses: np.ndarray, seeds: np.ndarray) -> Result:
    # imported here: the --before-src child runs this file against an older tree, which may lack the module
    from robocritics.robot.ik_numeric import numeric_ik

    model = pin.buildModelFromXML(dh_urdf(UR3E_DH))
    data = model.createData()
    fid = model.getFrameId("tool0", pin.FrameType.BODY)
    targets = [pin.SE3(T) for T in poses]
    return run("Pinocchio DLS (numeric_ik)", len(poses), lambda i: None,
               lambda i, _: numeric_ik(model, data, fid, targets[i], seeds[i], LOWER, UPPER),
               poses)


def bench_lively(poses: np.ndarray, seeds: np.ndarray) -> list[Result]:
    import lively

    objectives = {
        "position": lively.PositionMatchObjective(name="EE position", link="tool0", weight=50),
        "orientation": lively.OrientationMatchObjective(name="EE orientation", link="tool0", weight=25),
    }
    with quiet_stdout():
        solver = lively.Solver(urdf=dh_urdf(UR3E_DH), objectives=objectives)
    goals = []
    for T in poses:
        quat = pin.Quaternion(T[:3, :3])
        goals.append({
            "position": lively.Translation(float(T[0, 3]), float(T[1, 3]), float(T[2, 3])),
            "orientation": lively.Rotation(x=quat.x, y=quat.y, z=quat.z, w=quat.w),
        })
    states = [lively.State(origin=lively.Transform.identity(), joints=dict(zip(JOINTS, map(float, s))))
              for s in seeds]

    def reset(i: int) -> None:
        with quiet_stdout():
            solver.reset(states[i], {})

    def one_call(i: int, _: object) -> np.ndarray:
        st = solver.solve(goals=goals[i], weights={}, time=0.0)
        j = st.joints
        return np.array([j[n] for n in JOINTS])

    def converged(i: int, _: object) -> np.ndarray:
        prev = None
        for _call in range(50):
            st = solver.solve(goals=goals[i], weights={}, time=0.0)
            j = st.joints
            q = np.array([j[n] for n in JOINTS])
            if prev is not None and np.abs(q - prev).max() < 1e-6:
                break
            prev = q
        return q

    n = len(poses)
    return [
        run("lively-tk Solver.solve (1 call)", n, reset, one_call, poses, warmup=5),
        run("lively-tk Solver.solve (converged)", n, reset, converged, poses, warmup=2),
    ]


def bench_lines(sizes: tuple[int, ...] = (30, 120, 300, 1000), repeats: int = 7) -> str:
    """ur_ik_line vs ur_ik pose by pose on fingers-down straight lines: CPU us per pose (min of ``repeats``)."""
    from robocritics import Robot
    from robocritics.robot.model import fingers_down

    robot = Robot.ur3e()
    lines = [f"{'poses':>6} {'ur_ik per pose us':>18} {'ur_ik_line per pose us':>23} {'ratio':>6}"]
    for n in sizes:
        points = np.array([0.25, -0.1, 0.15]) + np.linspace(0.0, 1.0, n)[:, None] * np.array([0.05, 0.2, 0.1])
        tcp = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        tcp[:, :3, :3], tcp[:, :3, 3] = fingers_down(0.3), points
        flanges = tcp @ robot._flange_in_tcp

        def walk() -> np.ndarray:
            seed, rows = robot.home_q, []
            for F in flanges:
                seed = ur_ik(robot.dh, F, seed, robot.lower, robot.upper)
                rows.append(seed)
            return np.array(rows)

        def line() -> np.ndarray:
            return ur_ik_line(robot.dh, flanges, robot.home_q, robot.lower, robot.upper)[0]

        assert np.max(np.abs(walk() - line())) <= 1e-12
        best = least_cpu((walk, line), repeats)
        a, b = best[walk] / n * 1e6, best[line] / n * 1e6
        lines.append(f"{n:>6} {a:>18.1f} {b:>23.1f} {b / a:>6.2f}")
    return "\n".join(lines)


def least_cpu(functions, repeats: int) -> dict:
    """The least CPU seconds of each of ``functions`` over ``repeats`` rounds, run interleaved so that every
    function sees the same machine load."""
    best = {f: math.inf for f in functions}
    for _ in range(repeats):
        for f in functions:
            t0 = time.process_time()
            f()
            best[f] = min(best[f], time.process_time() - t0)
    return best


def cpu_per_solve(n: int, seed: int, passes: int = 9) -> dict[str, float]:
    """Least CPU us per solve over ``passes`` passes through the targets: ur_ik (seeded) and ur_ik_all."""
    _, poses, seeds = make_targets(n, seed)
    solvers = {
        "ur_ik CPU us": lambda i: ur_ik(UR3E_DH, poses[i], seeds[i], LOWER, UPPER),
        "ur_ik_all CPU us": lambda i: ur_ik_all(UR3E_DH, poses[i]),
    }
    out = {}
    for name, solve in solvers.items():
        best = math.inf
        for _ in range(passes + 1):  # the first pass warms caches (the chain's model)
            t0 = time.process_time()
            for i in range(n):
                solve(i)
            best = min(best, time.process_time() - t0)
        out[name] = best / n * 1e6
    return out


def compare(before_src: str, n: int, seed: int, rounds: int = 5) -> str:
    """:func:`cpu_per_solve` of the tree in ``before_src`` and of this one, alternating fresh interpreters."""
    import json
    import subprocess

    runs: dict[str, list[dict[str, float]]] = {"before": [], "now": []}
    for _ in range(rounds):
        for which, src in (("before", os.path.join(before_src, "src")), ("now", None)):
            env = dict(os.environ)
            if src is not None:
                env["PYTHONPATH"] = src
            cmd = [sys.executable, __file__, "--cpu-child", "--n", str(n), "--seed", str(seed)]
            done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
            runs[which].append(json.loads(done.stdout.strip().splitlines()[-1]))
    lines = [f"{'':<18} {'before':>8} {'now':>8} {'before/now':>10}"]
    for key in runs["now"][0]:
        b, a = (min(r[key] for r in runs[w]) for w in ("before", "now"))
        lines.append(f"{key:<18} {b:>8.2f} {a:>8.2f} {b / a:>10.2f}")
    lines.append(f"before: the tree in {before_src}; least over {rounds} alternating rounds")
    return "\n".join(lines)


def table(results: list[Result], reference: Result | None) -> str:
    head = (f"{'solver':<38} {'median us':>10} {'p90 us':>10} {'max pos err m':>14} "
            f"{'max rot err rad':>16} {'ok 1e-6':>8} {'speed-up vs lively':>19}")
    lines = [head, "-" * len(head)]
    for r in results:
        ok = int(np.sum((r.errors[:, 0] < 1e-6) & (r.errors[:, 1] < 1e-6)))
        ratio = reference.median / r.median if reference is not None else math.nan
        speed = "n/a" if reference is None else (f"{ratio:.0f}x" if ratio >= 10 else f"{ratio:.2f}x")
        lines.append(
            f"{r.name:<38} {r.median:>10.1f} {r.p90:>10.1f} {r.errors[:, 0].max():>14.2e} "
            f"{r.errors[:, 1].max():>16.2e} {ok:>4}/{len(r.errors):<3} {speed:>19}"
        )
    return "\n".join(lines)


def bench_all_many(seed: int, sizes: tuple[int, ...] = (1, 8, 30, 200), repeats: int = 7) -> str:
    """ur_ik_all_many (every branch of n poses in one numpy call) vs ur_ik_all pose by pose, on the random targets:
    CPU us per pose, the least of ``repeats`` (interleaved: the same machine load for both)."""
    from robocritics.robot.ik import ur_ik_all_many

    _, poses, _ = make_targets(max(sizes), seed)
    lines = [f"{'poses':>6} {'ur_ik_all per pose us':>22} {'ur_ik_all_many per pose us':>27} {'ratio':>6}"]
    for n in sizes:
        def scalar() -> None:
            for T in poses[:n]:
                ur_ik_all(UR3E_DH, T)

        def many() -> None:
            ur_ik_all_many(UR3E_DH, poses[:n])

        best = least_cpu((scalar, many), repeats)
        a, b = best[scalar] / n * 1e6, best[many] / n * 1e6
        lines.append(f"{n:>6} {a:>22.1f} {b:>27.1f} {b / a:>6.2f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="number of targets (default 200)")
    ap.add_argument("--seed", type=int, default=7, help="random seed (default 7)")
    ap.add_argument("--no-lively", action="store_true", help="skip lively-tk")
    ap.add_argument("--lines", action="store_true", help="also time ur_ik_line along straight lines")
    ap.add_argument("--all-many", action="store_true", help="only time ur_ik_all_many against ur_ik_all")
    ap.add_argument("--before-src", metavar="DIR", help="compare ur_ik / ur_ik_all CPU with the tree in DIR")
    ap.add_argument("--cpu-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.cpu_child:
        import json

        print(json.dumps(cpu_per_solve(args.n, args.seed)))
        return 0
    if args.all_many:
        print(f"ur_ik_all_many vs ur_ik_all, CPU us per pose (least of 7), random targets (seed {args.seed}):")
        print(bench_all_many(args.seed))
        print(f"reproduce: {REPRO} --all-many")
        return 0
    if args.before_src:
        print(f"UR3e closed-form IK, CPU per solve: {args.n} targets (seed {args.seed}), seed = truth + N(0, 0.2 rad)")
        print(compare(args.before_src, args.n, args.seed))
        print(f"reproduce: {REPRO} --before-src {args.before_src}")
        return 0

    q_true, poses, seeds = make_targets(args.n, args.seed)
    results = bench_ours(poses, seeds)
    results.append(bench_pinocchio(poses, seeds))
    reference = None
    if not args.no_lively:
        try:
            lv = bench_lively(poses, seeds)
        except ImportError:
            print("lively-tk not installed (pip install lively-tk): skipped")
        else:
            results.extend(lv)
            reference = lv[0]

    print(f"UR3e IK benchmark: {args.n} reachable random targets (seed {args.seed}), "
          f"seed configuration = truth + N(0, 0.2 rad)")
    print(f"python {platform.python_version()}, numpy {np.__version__}, pinocchio {pin.__version__}, "
          f"{platform.machine()} {os.cpu_count()} CPUs")
    print()
    print(table(results, reference))
    print()
    if reference is not None:
        print("speed-up = median time of 'lively-tk Solver.solve (1 call)' / median time of the row")
    if args.lines:
        print()
        print("ur_ik_line along fingers-down straight lines vs ur_ik pose by pose (CPU us per pose, min of 7):")
        print(bench_lines())
    print(f"reproduce: {REPRO}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
