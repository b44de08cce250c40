"""Peak memory and CPU of simulating and judging a long program: a palletising-like loop at 500 Hz.

One program (``tests/long_program.py``: an apple carried from the table into the brown box and back, over and over, in the
bundled sorting scene with its 14 shapes) is repeated to last about 2, 10 and 30 minutes, and each length is
simulated (``robocritics.simulate``, 500 Hz) and judged by the default critics (``critique``) in a fresh child
interpreter. The table shows the samples, the child's peak resident memory (``VmHWM`` from
``/proc/self/status``, MB), its CPU time (``time.process_time``, s) for simulate and for critique, the bytes per
sample of peak memory above the interpreter's baseline, and the report's size (its JSON, kB). Target (issue 28):
a 30-minute program at 500 Hz within 1.5 GB peak memory.

Reproduce::

    .venv/bin/python benchmarks/bench_long.py             # 2, 10 and 30 minutes
    .venv/bin/python benchmarks/bench_long.py 1 5         # other lengths, minutes
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the program lives with the tests
from long_program import repeated_sorting  # noqa: E402

#: Seconds of motion per repetition of the loop (measured: 15.35 s at speed 0.5).
SECONDS_PER_REPEAT = 15.35
RATE_HZ = 500.0


def vm_hwm_mb() -> float:
    """Peak resident set size of this process, MB (``VmHWM``)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


def child(minutes: float) -> None:
    from robocritics import Robot, Scene, critique, simulate

    robot, scene = Robot.ur3e(), Scene.builtin("sorting")
    critique(simulate("move_to(0.3, 0.1, 0.2)\n", scene, robot))  # imports and caches
    baseline = vm_hwm_mb()
    repeats = max(1, round(minutes * 60 / SECONDS_PER_REPEAT))
    source = repeated_sorting(repeats)
    t0 = time.process_time()
    execution = simulate(source, scene, robot, sample_rate_hz=RATE_HZ)
    t1 = time.process_time()
    report = critique(execution)
    t2 = time.process_time()
    peak = vm_hwm_mb()
    T = len(execution.trajectory)
    print(json.dumps({
        "minutes": execution.duration_s / 60, "samples": T, "compact": execution.trajectory.compact,
        "peak_mb": peak, "baseline_mb": baseline, "bytes_per_sample": (peak - baseline) * 2**20 / T,
        "simulate_s": t1 - t0, "critique_s": t2 - t1, "report_kb": len(report.model_dump_json()) / 1000,
        "flags": " ".join(f"{v.critic}:{v.flag.value}" for v in report.verdicts),
    }))  # fmt: skip


def main(argv: list[str]) -> int:
    if argv[:1] == ["--child"]:
        child(float(argv[1]))
        return 0
    lengths = [float(a) for a in argv] or [2.0, 10.0, 30.0]
    header = (f"{'motion min':>10} {'samples':>9} {'peak MB':>8} {'base MB':>8} {'B/sample':>9} {'simulate s':>10} "
              f"{'critique s':>10} {'report kB':>9}")  # fmt: skip
    print(f"simulate + critique at {RATE_HZ:g} Hz, sorting scene (14 shapes), each length in a fresh child\n")
    print(header)
    print("-" * len(header))
    flags = ""
    for minutes in lengths:
        done = subprocess.run([sys.executable, __file__, "--child", str(minutes)], capture_output=True, text=True)
        if done.returncode:
            print(f"{minutes:>10g} failed: {done.stderr.strip().splitlines()[-1]}")
            continue
        r = json.loads(done.stdout.strip().splitlines()[-1])
        flags = r["flags"]
        print(f"{r['minutes']:>10.1f} {r['samples']:>9,} {r['peak_mb']:>8.0f} {r['baseline_mb']:>8.0f} "
              f"{r['bytes_per_sample']:>9.0f} {r['simulate_s']:>10.1f} {r['critique_s']:>10.1f} {r['report_kb']:>9.1f}")  # fmt: skip
    print(f"\nverdicts (longest): {flags}")
    print("target: a 30-minute program at 500 Hz within 1,500 MB peak memory")
    print(f"reproduce: .venv/bin/python benchmarks/bench_long.py {' '.join(f'{m:g}' for m in lengths)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
