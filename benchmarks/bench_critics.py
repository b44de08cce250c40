"""Benchmark: the five vectorised critics against their per-sample reference implementations.

A 60 s trajectory at 500 Hz (30,000 samples) of a synthetic UR3e pick-and-place
motion (DH forward kinematics, 12 frames, 60 tagged proximity pairs, steps
with source lines, a carried object) is judged by each critic's ``check`` and
by the slow per-sample references in ``tests/critic_reference.py`` (the
paper's loops, in plain Python). Both must agree on every flag; the table
reports wall-clock medians (and CPU-time medians, which other processes on
the machine disturb less).

Targets: all five critics together (``critique``) in <= 50 ms median, and
>= 20x faster than the references.

``--before-src DIR`` instead measures ``critique()`` of the five critics (CPU time, least of the repeats, one
BLAS thread, glibc malloc tunables: each tree's ``robocritics.child.WORKER_ENV``, as a batch worker runs) on the
same 30k-sample trajectory in two fresh children: one on the source tree ``DIR`` (e.g. commit
c045a0b extracted with ``git archive c045a0b | tar -x -C DIR``; its own ``tests/synth.py`` builds the trajectory and
its own critic entry points are made visible, as ``bench_pipeline.py`` does) and one on this checkout, and prints
both and their ratio (issue 28's target: >= 3x cheaper than c045a0b).

Reproduce::

    .venv/bin/python benchmarks/bench_critics.py            # default 15 repeats (3 for the references)
    .venv/bin/python benchmarks/bench_critics.py --repeats 31 --ref-repeats 5 --assert-targets
    git archive c045a0b | tar -x -C /tmp/c045a0b && .venv/bin/python benchmarks/bench_critics.py --before-src /tmp/c045a0b
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # synth.py and critic_reference.py live with the tests

CHILD = """
import json, sys, time
sys.path.insert(0, sys.argv[1] + "/tests")
from synth import realistic_trajectory
from robocritics.critic import BUILTIN_CRITICS, critique
from robocritics.scene import Scene
traj, scene = realistic_trajectory(duration_s=float(sys.argv[2]), rate_hz=float(sys.argv[3])), Scene.builtin("sorting")
critics = list(BUILTIN_CRITICS)
report = critique(traj, scene, critics=critics)
cpu = []
for _ in range(int(sys.argv[4])):
    c0 = time.process_time()
    critique(traj, scene, critics=critics)
    cpu.append(time.process_time() - c0)
print(json.dumps({"cpu_ms": 1000 * min(cpu), "samples": len(traj), "flags": [v.flag.value for v in report.verdicts]}))
"""


def before_after(before: Path, duration: float, rate: float, repeats: int) -> int:
    """critique() CPU of tree ``before`` and of this checkout, each in fresh children (three rounds, least)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_pipeline import expose_entry_points, worker_env

    expose_entry_points(before)
    results: dict[str, list[dict]] = {"before": [], "after": []}
    for _ in range(3):  # alternate the trees: the machine's load changes
        for name, tree in (("before", before), ("after", ROOT)):
            env = dict(os.environ, PYTHONPATH=str(tree / "src"))
            env.update(worker_env(tree))  # the tree's own worker environment: one BLAS thread, malloc tunables
            done = subprocess.run(
                [sys.executable, "-c", CHILD, str(tree), str(duration), str(rate), str(repeats)],
                env=env, cwd=tree, capture_output=True, text=True, check=True,
            )  # fmt: skip
            results[name].append(json.loads(done.stdout.strip().splitlines()[-1]))
    b = min(r["cpu_ms"] for r in results["before"])
    a = min(r["cpu_ms"] for r in results["after"])
    samples = results["after"][0]["samples"]
    print(f"critique() of the five critics, {samples:,} samples; CPU ms, least of {repeats} x 3 rounds, each tree's "
          "worker environment (robocritics.child.WORKER_ENV: one BLAS thread, glibc malloc tunables)\n")
    print(f"{'tree':<40} {'CPU ms':>8}  flags")
    print(f"{'before: ' + str(before):<40} {b:>8.2f}  {' '.join(results['before'][0]['flags'])}")
    print(f"{'after: this checkout':<40} {a:>8.2f}  {' '.join(results['after'][0]['flags'])}")
    print(f"\nratio before / after: {b / a:.2f}x (target >= 3x)")
    print(f"reproduce: .venv/bin/python benchmarks/bench_critics.py --before-src {before}")
    return 0


from critic_reference import REFERENCES  # noqa: E402
from synth import realistic_trajectory  # noqa: E402

from robocritics.critic import BUILTIN_CRITICS, as_execution, critique, get_critics  # noqa: E402
from robocritics.scene import Scene  # noqa: E402

TARGET_MS = 50.0
TARGET_SPEEDUP = 20.0


def timed(fn, repeats: int) -> tuple[float, float]:
    """Median wall-clock and CPU seconds of ``fn()`` over ``repeats`` runs (after one warm-up)."""
    fn()
    wall, cpu = [], []
    for _ in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return statistics.median(wall), statistics.median(cpu)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=60.0, help="trajectory duration, s (default 60)")
    ap.add_argument("--rate", type=float, default=500.0, help="sample rate, Hz (default 500)")
    ap.add_argument("--repeats", type=int, default=15, help="timed runs of each vectorised critic (median)")
    ap.add_argument("--ref-repeats", type=int, default=3, help="timed runs of each reference (median)")
    ap.add_argument("--assert-targets", action="store_true", help="exit 1 if a target is missed")
    ap.add_argument("--before-src", type=Path, help="a source tree to compare critique() against (see above)")
    args = ap.parse_args(argv)
    if args.before_src is not None:
        return before_after(args.before_src.resolve(), args.duration, args.rate, args.repeats)

    traj = realistic_trajectory(duration_s=args.duration, rate_hz=args.rate)
    scene = Scene.builtin("sorting")
    critics = get_critics()
    print(f"trajectory: {traj}")
    print(f"scene: {scene.name}; repeats: {args.repeats} (references: {args.ref_repeats}); medians\n")

    header = f"{'critic':<19} {'flag':<8} {'vectorised ms':>13} {'(cpu ms)':>9} {'reference ms':>13} {'speed-up':>9}"
    print(header)
    print("-" * len(header))
    total_vec = total_ref = 0.0
    agree = True
    execution = as_execution(traj, scene)  # the run a critic reads: this trajectory in this scene, no plan
    for name in BUILTIN_CRITICS:
        c = critics[name]
        p = c.Params()
        verdict = c.check(execution, p)
        ref = REFERENCES[name](traj, scene, p)
        if verdict.flag is not ref["flag"]:
            agree = False
        wall, cpu = timed(lambda: c.check(execution, p), args.repeats)
        ref_wall, _ = timed(lambda: REFERENCES[name](traj, scene, p), args.ref_repeats)
        total_vec += wall
        total_ref += ref_wall
        mark = "" if verdict.flag is ref["flag"] else f"  MISMATCH (reference {ref['flag'].value})"
        print(
            f"{name:<19} {verdict.flag.value:<8} {wall * 1e3:>13.2f} {cpu * 1e3:>9.2f} {ref_wall * 1e3:>13.1f} "
            f"{ref_wall / wall:>8.0f}x{mark}"
        )
    wall, cpu = timed(lambda: critique(traj, scene, critics=list(BUILTIN_CRITICS)), args.repeats)
    print("-" * len(header))
    print(f"{'sum of the five':<28} {total_vec * 1e3:>13.2f} {'':>9} {total_ref * 1e3:>13.1f} {total_ref / total_vec:>8.0f}x")
    print(f"{'critique() all five':<28} {wall * 1e3:>13.2f} {cpu * 1e3:>9.2f} {total_ref * 1e3:>13.1f} {total_ref / wall:>8.0f}x")
    print()
    ok_time = wall * 1e3 <= TARGET_MS
    ok_speed = total_ref / wall >= TARGET_SPEEDUP
    print(f"target: critique() median <= {TARGET_MS:.0f} ms: {'met' if ok_time else 'MISSED'} ({wall * 1e3:.1f} ms)")
    print(f"target: >= {TARGET_SPEEDUP:.0f}x faster than the references: {'met' if ok_speed else 'MISSED'} ({total_ref / wall:.0f}x)")
    print(f"flags agree with the references: {'yes' if agree else 'NO'}")
    print("\nreproduce: .venv/bin/python benchmarks/bench_critics.py --repeats 15 --ref-repeats 3")
    if args.assert_targets and not (ok_time and ok_speed and agree):
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
