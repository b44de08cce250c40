"""Cycle times of the bundled naive programs after critic-native repairs, against the careful examples.

Reproduce with::

    .venv/bin/python benchmarks/repair_cycle_times.py

What is measured
----------------
For each bundled task (sorting, breakfast, recycling): ``robocritics.repair`` on
``examples/programs/<task>_naive.py`` and on ``<task>_careful.py`` with the task's
goals (the ones ``tests/test_repair.py`` checks), no LLM. Reported: the number of
accepted changes, the Errors left, the simulated cycle time (s, on the physical time
axis the robot would execute) of the repaired naive program and of the (repaired)
careful one, and their ratio (the issue asks for at most 1.5). Deterministic: the
numbers depend only on the code, not on the machine (no wall clock is reported).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _table import print_table  # noqa: E402

from robocritics.repair import repair  # noqa: E402

PROGRAMS = Path(__file__).resolve().parents[1] / "examples" / "programs"
GOALS = {
    "sorting": ["green_apple in white_box", "red_apple_1 in brown_box", "red_apple_2 in brown_box"],
    "breakfast": ["fork in trash_bin", "apple on plate", "cupcake on plate"],
    "recycling": ["coffee_cup in trash_bin", "food_container in trash_bin", "water_bottle in trash_bin"],
}


def main() -> None:
    rows = [("task", "changes  Errors left  naive repaired (s)  careful (s)  ratio")]
    for task, goals in GOALS.items():
        naive = repair((PROGRAMS / f"{task}_naive.py").read_text(), task, goal=goals)
        careful = repair((PROGRAMS / f"{task}_careful.py").read_text(), task, goal=goals)
        a, b = naive.execution.duration_s, careful.execution.duration_s
        rows.append((task, f"{len(naive.changes):7d}  {len(naive.errors):11d}  {a:18.2f}  {b:11.2f}  {a / b:5.2f}"))
    print_table("repair_cycle_times", "bundled naive programs repaired without an LLM", rows, [])


if __name__ == "__main__":
    main()
