"""CPU time to check a URScript program of a few hundred lines (the issue's target: under a second of CPU).

The program is generated in PolyScope's style: preamble, a step-counter thread, 60 waypoints as globals, and a
main loop of movej/movel with blends, gripper calls, an if/else and a sub-function per pick. Measured: CPU
(process time) of parsing, of interpreting and timing it (IK per movel sample), of the critics, and of the
whole ``robocritics check FILE`` command in a fresh process (imports included).

Run: .venv/bin/python benchmarks/bench_urscript.py
"""

from __future__ import annotations

import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _table import print_table

from robocritics import Robot, Scene, critique
from robocritics.formats.urscript import parse, run_urscript


def program(waypoints: int = 60) -> str:
    lines = [
        "def Benchmark_program():",
        "  set_tcp(p[0.0,0.0,0.15,0.0,0.0,0.0])",
        "  set_payload(0.5)",
        "  step_count = 0.0",
        "  thread Step_Counter_Thread():",
        "    while (True):",
        "      step_count = step_count + 1.0",
        "      sync()",
        "    end",
        "  end",
        "  run Step_Counter_Thread()",
    ]
    for i in range(waypoints):
        x = -0.22 - 0.06 * ((i * 7) % 5) / 4
        y = -0.12 + 0.24 * ((i * 3) % 11) / 10
        lines.append(f"  global Waypoint_{i}_p=p[{x:.6f}, {y:.6f}, .180000, 0.000000, 3.141593, 0.000000]")
    lines += [
        "  def pick_at(target):",
        "    movel(pose_add(target, p[0, 0, -0.06, 0, 0, 0]), a=1.2, v=0.25)",
        "    rq_close_and_wait()",
        "    movel(target, a=1.2, v=0.25)",
        "  end",
        '  $ 1 "Robot Program"',
        "  movej(get_inverse_kin(Waypoint_0_p), a=1.3962634015954636, v=1.0471975511965976)",
        "  while (True):",
    ]
    for i in range(1, waypoints):
        lines += [
            f'    $ {i + 1} "Waypoint_{i}" "breakAfter"',
            "    if (step_count >= 0):",
            f"      movel(Waypoint_{i}_p, a=1.2, v=0.5, r=0.01)",
            "    else:",
            f"      movej(get_inverse_kin(Waypoint_{i}_p), a=1.4, v=1.05)",
            "    end",
        ]
        if i % 10 == 0:
            lines += [f"    pick_at(Waypoint_{i}_p)", "    rq_open_and_wait()"]
    lines += ["  end", "end", ""]
    return "\n".join(lines)


def cpu(fn, repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        t0 = time.process_time()
        result = fn()
        times.append(time.process_time() - t0)
    return statistics.median(times), result


def main(repeats: int = 5) -> None:
    source = program()
    robot, scene = Robot.ur3e(), Scene()
    run_urscript(source, robot, robot.scene_for(scene))  # warm-up (IK tables, FK tables)
    parse_s, _ = cpu(lambda: parse(source), repeats)
    run_s, execution = cpu(lambda: run_urscript(source, robot, robot.scene_for(scene)), repeats)
    critique_s, _ = cpu(lambda: critique(execution), repeats)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "benchmark.script"
        path.write_text(source)
        cold = []
        for _ in range(repeats):
            start = resource.getrusage(resource.RUSAGE_CHILDREN)
            subprocess.run([sys.executable, "-m", "robocritics", "check", str(path)], capture_output=True, check=False)
            end = resource.getrusage(resource.RUSAGE_CHILDREN)
            cold.append(end.ru_utime + end.ru_stime - start.ru_utime - start.ru_stime)
    traj = execution.trajectory
    print_table(
        "bench_urscript",
        "checking a generated PolyScope-style URScript program",
        [
            ("program", f"{len(source.splitlines())} lines, {len(traj.steps)} commands, {len(traj)} samples, {traj.duration_s:.1f} s of motion"),
            ("parse (CPU, median)", f"{parse_s * 1e3:.1f} ms"),
            ("interpret + UR timing + FK/proximity (CPU)", f"{run_s * 1e3:.1f} ms"),
            ("critique, the default critics (CPU)", f"{critique_s * 1e3:.1f} ms"),
            ("`robocritics check FILE`, fresh process (CPU)", f"{statistics.median(cold) * 1e3:.0f} ms (median of {repeats})"),
        ],
        None,
    )


if __name__ == "__main__":
    main()
