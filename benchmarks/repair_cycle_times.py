"""Critic-native repairs (no LLM) on every naive program: before/after score, what is left, cycle time.

Reproduce with::

    .venv/bin/python benchmarks/repair_cycle_times.py            # all 26: 3 bundled naive, 20 new, 3 careful
    .venv/bin/python benchmarks/repair_cycle_times.py sorting_dash breakfast_naive   # a few, by name

What is measured
----------------
The naive programs (and, as reference rows, the three careful examples): the three bundled ones (``examples/programs/<task>_naive.py``,
goals from :data:`GOALS`) and the ones in ``examples/programs/naive/`` (each names its
goals in a ``# goals: a in b; c on d`` comment; its scene is the file name's prefix).
Each is repaired by :func:`robocritics.repair.repair` with its goals, no model.
Columns: the score and Errors/Warnings before; after: score, Errors/Warnings left,
every goal met (``goal``), the simulated cycle time (s, the physical time axis the
robot executes), its ratio to the careful example of the same task (the issue's
target: at most 1.5, else the reason is printed below the table), the accepted
changes, and the CPU seconds the repair took (``time.process_time``: the search is
bounded by ``MAX_SIMULATIONS`` re-simulations). The summary line gives the share of
programs that end at ≥ 9/10 with no Error and every goal met (target: ≥ 90 %).
Deterministic apart from the CPU column.
"""

from __future__ import annotations

import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _table import print_table  # noqa: E402

PROGRAMS = Path(__file__).resolve().parents[1] / "examples" / "programs"
GOALS = {
    "sorting": ["green_apple in white_box", "red_apple_1 in brown_box", "red_apple_2 in brown_box"],
    "breakfast": ["fork in trash_bin", "apple on plate", "cupcake on plate"],
    "recycling": ["coffee_cup in trash_bin", "food_container in trash_bin", "water_bottle in trash_bin"],
}
#: The most a repaired program's cycle may take, as a multiple of the careful example's for the same task.
CYCLE_RATIO_TARGET = 1.5


def goals_of(source: str) -> list[str]:
    """The goals a naive program states in its ``# goals: a in b; c on d`` comment."""
    m = re.search(r"^# goals: (.+)$", source, re.MULTILINE)
    return [g.strip() for g in m.group(1).split(";")] if m else []


def naive_programs() -> list[tuple[str, Path, str, list[str]]]:
    """``(name, path, scene, goals)`` of every naive program: the bundled three, then examples/programs/naive."""
    out = [(f"{t}_naive", PROGRAMS / f"{t}_naive.py", t, goals) for t, goals in GOALS.items()]
    for path in sorted((PROGRAMS / "naive").glob("*.py")):
        out.append((path.stem, path, path.stem.split("_")[0], goals_of(path.read_text())))
    return out


@dataclass
class Row:
    name: str
    before: str
    score: float
    errors: int
    warnings: int
    goals_met: bool
    cycle_s: float
    ratio: float
    changes: list
    cpu_s: float
    left: list[str]

    @property
    def finished(self) -> bool:
        """The issue's bar: at least 9/10, no Error, every goal met."""
        return self.score >= 9 and self.errors == 0 and self.goals_met


def _counts(report) -> str:
    e = sum(v.flag.name == "ERROR" for v in report.verdicts)
    w = sum(v.flag.name == "WARNING" for v in report.verdicts)
    return f"{report.score:g}/10 {e}E {w}W"


def careful_cycle_s(task: str) -> float:
    from robocritics import Scene, simulate

    return simulate((PROGRAMS / f"{task}_careful.py").read_text(), Scene.builtin(task)).duration_s


def run_one(name: str, path: Path, task: str, goals: list[str], careful_s: float) -> Row:
    from robocritics.pipeline import check as check_program
    from robocritics.repair import repair
    from robocritics.scene import Scene

    source = path.read_text()
    _, before = check_program(source, Scene.builtin(task), goals=goals)
    t0 = time.process_time()
    result = repair(source, task, goal=goals)
    cpu = time.process_time() - t0
    verdicts = result.report.verdicts
    goal_verdict = next((v for v in verdicts if v.critic == "task_outcome"), None)
    cycle = result.execution.duration_s if result.execution is not None else float("nan")
    return Row(
        name,
        _counts(before),
        result.report.score,
        sum(v.flag.name == "ERROR" for v in verdicts),
        sum(v.flag.name == "WARNING" for v in verdicts),
        goal_verdict is not None and goal_verdict.flag.name == "OK",
        cycle,
        cycle / careful_s,
        result.changes,
        cpu,
        [f"{v.critic} {v.flag.name}: {v.message}" for v in verdicts if v.flag.name != "OK"],
    )


def careful_programs() -> list[tuple[str, Path, str, list[str]]]:
    """The three careful examples: the reference rows (a repair should leave them as they are)."""
    return [(f"{t}_careful", PROGRAMS / f"{t}_careful.py", t, goals) for t, goals in GOALS.items()]


def main(names: list[str]) -> None:
    programs = [p for p in naive_programs() + careful_programs() if not names or p[0] in names]
    careful = {task: careful_cycle_s(task) for task in {p[2] for p in programs}}
    results = [run_one(*p, careful[p[2]]) for p in programs]
    rows = [("program", "before         after          goal  cycle s  x careful  changes  CPU s")]
    for r in results:
        after = f"{r.score:g}/10 {r.errors}E {r.warnings}W"
        rows.append((r.name, f"{r.before:<14} {after:<14} {'yes' if r.goals_met else 'NO':<5} {r.cycle_s:7.2f}  "
                             f"{r.ratio:9.2f}  {len(r.changes):7d}  {r.cpu_s:5.1f}"))  # fmt: skip
    print_table("repair_cycle_times", "naive programs repaired without an LLM", rows, names)
    naive = [r for r in results if not r.name.endswith("_careful")]
    done = sum(r.finished for r in naive)
    if naive:
        print(f"naive programs finished (>= 9/10, no Error, every goal met): {done}/{len(naive)} = "
              f"{100 * done / len(naive):.0f} %")  # fmt: skip
    print(f"careful cycle times, s: {', '.join(f'{t} {s:.2f}' for t, s in sorted(careful.items()))}")
    for r in results:
        print(f"\n{r.name}: {len(r.changes)} change(s)")
        for c in r.changes:
            print(f"  {c}")
        for left in r.left:
            print(f"  left: {left}")
        if r.ratio > CYCLE_RATIO_TARGET:
            slow = sorted(r.changes, key=lambda c: -c.cost_s)[:2]
            why = "; ".join(f"{c.critic} line {c.line} {c.cost_s:+.2f} s ({c.what})" for c in slow)
            print(f"  cycle {r.ratio:.2f}x the careful example's: the costliest changes: {why or 'none'}")


if __name__ == "__main__":
    main(sys.argv[1:])
