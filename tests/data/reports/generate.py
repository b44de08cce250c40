"""Write the stored reports that tests/test_stored_reports.py compares against.

Run with the tree to record on the path, e.g. the reports of commit c045a0b:

    git worktree add --detach /tmp/c045 c045a0b
    PYTHONPATH=/tmp/c045/src .venv/bin/python tests/data/reports/generate.py

Each bundled example program (examples/programs/*.py) is simulated in its scene (the first word of its name) on
the UR3e at 125 Hz and critiqued by the five built-in critics plus task_outcome with the task's natural goals.
"""

from __future__ import annotations

import json
from pathlib import Path

from robocritics import Scene, critique, simulate

ROOT = Path(__file__).resolve().parents[3]
PROGRAMS = ROOT / "examples" / "programs"
OUT = Path(__file__).resolve().parent

#: the natural goals of each bundled task (as in tests/test_critics_task_outcome.py)
TASK_GOALS = {
    "breakfast": ["fork in trash_bin", "cupcake on plate", "apple on plate"],
    "recycling": ["coffee_cup in trash_bin", "food_container in trash_bin", "water_bottle in trash_bin"],
    "sorting": ["red_apple_1 in brown_box", "red_apple_2 in brown_box", "green_apple in white_box"],
}
CRITICS = ["joint_speed", "space_usage", "collision", "end_effector_pose", "pinch_point", "task_outcome"]


def main() -> None:
    for path in sorted(PROGRAMS.glob("*.py")):
        task = path.stem.split("_")[0]
        execution = simulate(path.read_text(), Scene.builtin(task))
        report = critique(execution, critics=CRITICS, goals=TASK_GOALS[task])
        (OUT / f"{path.stem}.json").write_text(json.dumps(json.loads(report.to_json()), indent=1) + "\n")
        print(path.stem, report.score, [v.flag.name for v in report.verdicts])


if __name__ == "__main__":
    main()
