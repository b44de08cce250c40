"""Where critique()'s CPU goes on the 30k-sample trace: each built-in critic's reduction (init, add, verdict),
the trajectory's content hash and the rest, CPU ms (``time.process_time``), least and median of the repeats.

The same synthetic 60 s, 500 Hz UR3e trajectory as ``bench_critics.py`` (``tests/synth.py``). Each phase is
timed by wrapping the method in place, so the phases add up to the total up to the wrappers' own cost.

Reproduce::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/profile_critique.py [--repeats N]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # synth.py lives with the tests
sys.path.insert(0, str(ROOT / "benchmarks"))

from _table import print_table  # noqa: E402
from synth import realistic_trajectory  # noqa: E402

from robocritics.critic import BUILTIN_CRITICS, as_execution, critique, get_critics  # noqa: E402
from robocritics.scene import Scene  # noqa: E402
from robocritics.trajectory import Trajectory  # noqa: E402


def timed_phases(spent: dict[str, float]) -> None:
    """Wrap the content hash and every built-in reduction's methods so their CPU seconds add up in ``spent``."""

    def wrap(cls, method: str, key: str) -> None:
        plain = getattr(cls, method)

        def timed(self, *args, **kwargs):
            t0 = time.process_time()
            try:
                return plain(self, *args, **kwargs)
            finally:
                spent[key] += time.process_time() - t0

        setattr(cls, method, timed)

    wrap(Trajectory, "content_hash", "content_hash")
    critics = get_critics()
    probe = as_execution(realistic_trajectory(duration_s=0.1, rate_hz=500.0), Scene.builtin("sorting"))
    for name in BUILTIN_CRITICS:
        cls = type(critics[name].reduction(probe, critics[name].Params()))
        for method in ("__init__", "add", "verdict"):
            wrap(cls, method, f"{name}.{method.strip('_')}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=15, help="timed critiques (default 15)")
    args = ap.parse_args(argv)
    traj, scene = realistic_trajectory(duration_s=60.0, rate_hz=500.0), Scene.builtin("sorting")
    spent: dict[str, float] = defaultdict(float)
    timed_phases(spent)
    critique(traj, scene, critics=list(BUILTIN_CRITICS))  # warm-up
    runs: dict[str, list[float]] = defaultdict(list)
    for _ in range(args.repeats):
        spent.clear()
        t0 = time.process_time()
        critique(traj, scene, critics=list(BUILTIN_CRITICS))
        total = time.process_time() - t0
        spent["other"] = total - sum(spent.values())
        spent["TOTAL"] = total
        for key, value in spent.items():
            runs[key].append(value)
    rows = [("phase", "least / median CPU ms")]
    for key in sorted(runs, key=lambda k: -min(runs[k])):
        values = sorted(runs[key])
        rows.append((key, f"{1000 * values[0]:.2f} / {1000 * values[len(values) // 2]:.2f}"))
    what = f"critique() of the five critics, {len(traj):,} samples, {args.repeats} repeats"
    print_table("profile_critique", what, rows, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
