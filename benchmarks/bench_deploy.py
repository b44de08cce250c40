"""Deploy a verified program to the loopback UR controller through ``URArm.deploy()`` and measure pacing and tracking.

Reproduce with::

    .venv/bin/python benchmarks/bench_deploy.py                        # careful sorting program (about 59 s)
    .venv/bin/python benchmarks/bench_deploy.py --program short        # a 2.1 s motion
    .venv/bin/python benchmarks/bench_deploy.py --program examples/programs/recycling_careful.py --scene recycling

The whole chain runs: ``simulate`` → ``critique`` → the deploy gate → resampling
to 500 Hz → the streaming program started over the secondary interface →
setpoints paced with absolute deadlines over RTDE → done → program ended. The
controller (:class:`robocritics.testing.ursim.URSim`) runs in its own process, as a
real controller runs on its own machine; everything is on 127.0.0.1.

Reported (from :class:`robocritics.deploy.DeployResult`):

* period error — |send interval − 2 ms| [ms], median / p99 / max
* lateness p99 — send time − its deadline [ms]
* tracking error — max over the run of max_j |actual_q − nearest setpoint of the
  lookahead window| [rad]
* final error — max_j |actual_q − last trajectory sample| after the program ended [rad]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import time
from pathlib import Path

from _table import print_table

ROOT = Path(__file__).resolve().parent.parent
SHORT = """
lib.set_speed(0.5)
move_above(red_apple_1, 0.12)
move_above(green_apple, 0.12)
"""


def _controller(conn, initial_q) -> None:
    """Child process: the loopback controller."""
    from robocritics.testing.ursim import URSim

    with URSim(rtde_port=0, dashboard_port=0, secondary_port=0, initial_q=initial_q) as sim:
        conn.send((sim.rtde_port, sim.dashboard_port, sim.secondary_port))
        conn.recv()  # wait for "report"
        conn.send((sim.loop_overruns, [e.message for e in sim.events("protective_stop")], sim.q))


def run(program: str, scene_name: str, spin_us: float, lookahead_s: float, gain: float) -> dict:
    import robocritics as rc
    from robocritics.critic import BUILTIN_CRITICS
    from robocritics.deploy import URArm

    scene = rc.Scene.builtin(scene_name)
    source = SHORT if program == "short" else Path(program).read_text()
    t = time.perf_counter()
    execution = rc.simulate(source, scene)
    report = rc.critique(execution, critics=BUILTIN_CRITICS)
    prep_s = time.perf_counter() - t
    home = tuple(float(v) for v in execution.robot.home_q)
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=_controller, args=(child, home), daemon=True)
    proc.start()
    try:
        if not parent.poll(30):
            raise SystemExit("the loopback controller did not start")
        rtde_port, dashboard_port, secondary_port = parent.recv()
        with URArm("127.0.0.1", rtde_port=rtde_port, dashboard_port=dashboard_port, secondary_port=secondary_port) as arm:
            t = time.perf_counter()
            result = arm.deploy(execution, report, spin_s=spin_us * 1e-6, lookahead_time_s=lookahead_s, gain=gain)
            wall_s = time.perf_counter() - t
        parent.send("report")
        overruns, protective, sim_q = parent.recv()
    finally:
        proc.join(timeout=5)
        if proc.is_alive():
            proc.kill()
    final_sim = max(abs(a - b) for a, b in zip(sim_q, execution.trajectory.q[-1]))
    return {
        "program": program,
        "scene": scene_name,
        "score": report.score,
        "simulate_and_critique_s": prep_s,
        "trajectory_samples": result.trajectory_samples,
        "trajectory_duration_s": result.trajectory_duration_s,
        "setpoints": result.samples_sent,
        "stream_duration_s": result.duration_s,
        "deploy_wall_s": wall_s,
        "period_error_ms": {
            "median": result.period_error_median_ms,
            "p99": result.period_error_p99_ms,
            "max": result.period_error_max_ms,
        },
        "lateness_p99_ms": result.lateness_p99_ms,
        "max_tracking_error_rad": result.max_tracking_error_rad,
        "final_error_rad": result.final_error_rad,
        "final_error_controller_rad": final_sim,
        "settle_s": result.settle_s,
        "resyncs": result.resyncs,
        "data_packages": result.data_packages,
        "controller_loop_overruns": overruns,
        "protective_stops": protective,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--program", default=str(ROOT / "examples" / "programs" / "sorting_careful.py"),
                    help="program file, or 'short' for a 2.1 s motion (default: the careful sorting program)")
    ap.add_argument("--scene", default="sorting", help="built-in scene (default sorting)")
    ap.add_argument("--spin-us", type=float, default=200.0, help="busy-wait before each deadline [us] (default 200)")
    ap.add_argument("--lookahead", type=float, default=0.1, help="servoj lookahead_time [s] (default 0.1)")
    ap.add_argument("--gain", type=float, default=300.0, help="servoj gain (default 300)")
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    args = ap.parse_args(argv)
    r = run(args.program, args.scene, args.spin_us, args.lookahead, args.gain)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    pe = r["period_error_ms"]
    name = "short (2.1 s)" if r["program"] == "short" else os.path.relpath(r["program"], ROOT)
    rows = [
        ("program / scene / score", f"{name} / {r['scene']} / {r['score']:g}/10"),
        ("trajectory", f"{r['trajectory_samples']} samples, {r['trajectory_duration_s']:.3f} s"),
        ("setpoints streamed at 500 Hz", f"{r['setpoints']} in {r['stream_duration_s']:.3f} s"),
        ("period error median / p99 / max", f"{pe['median']:.3f} / {pe['p99']:.3f} / {pe['max']:.3f} ms"),
        ("lateness p99", f"{r['lateness_p99_ms']:.3f} ms"),
        ("tracking error (max)", f"{r['max_tracking_error_rad']:.2e} rad"),
        ("final error (deploy result / controller)", f"{r['final_error_rad']:.2e} / {r['final_error_controller_rad']:.2e} rad"),
        ("settle before done", f"{r['settle_s'] * 1000:.0f} ms"),
        ("schedule resyncs (client > 10 ms late)", str(r["resyncs"])),
        ("deploy() wall time", f"{r['deploy_wall_s']:.3f} s (gate, start, stream, settle, stop)"),
        ("RTDE data packages checked", str(r["data_packages"])),
        ("controller loop overruns", str(r["controller_loop_overruns"])),
        ("protective stops", str(len(r["protective_stops"]))),
    ]
    print_table("bench_deploy", "URArm.deploy() to the loopback URSim in its own process", rows, argv, rule=50)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
