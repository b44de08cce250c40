"""What the 3-D replay costs: replay data CPU time and the size of the offline HTML file, per bundled example.

CPU time (time.process_time) of `replay_data` and of the whole page (`replay_html`), the
frames drawn, and the file size `robocritics check --html` writes. Run:
    .venv/bin/python benchmarks/bench_replay.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _table import print_table  # noqa: E402

import robocritics as rc  # noqa: E402
from robocritics.viz import replay_data, replay_html  # noqa: E402

PROGRAMS = Path(__file__).resolve().parent.parent / "examples" / "programs"


def cpu_ms(fn, repeat: int = 3) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        start = time.process_time()
        out = fn()
        best = min(best, time.process_time() - start)
    return best * 1000, out


def main() -> None:
    rows = [("program", "samples  motion s  frames  replay_data ms CPU  page ms CPU  page kB")]
    for path in sorted(PROGRAMS.glob("*.py")):
        scene = rc.Scene.builtin(path.stem.split("_")[0])
        execution = rc.simulate(path.read_text(), scene)
        report = rc.critique(execution)
        data_ms, data = cpu_ms(lambda: replay_data(execution, report))
        page_ms, page = cpu_ms(lambda: replay_html(execution, report))
        frames = data["time_s"]["shape"][0]
        rows.append((path.stem, f"{len(execution.trajectory):7d}  {execution.duration_s:8.2f}  {frames:6d}  "
                                f"{data_ms:18.1f}  {page_ms:11.1f}  {len(page.encode()) / 1000:7.0f}"))  # fmt: skip
    print_table("bench_replay", "3-D replay data and offline page per bundled example", rows, [])


if __name__ == "__main__":
    main()
