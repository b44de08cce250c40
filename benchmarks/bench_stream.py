"""Stream a joint trajectory at 500 Hz to the loopback UR controller and measure pacing and tracking.

Reproduce with::

    .venv/bin/python benchmarks/bench_stream.py            # 5 s at 500 Hz
    .venv/bin/python benchmarks/bench_stream.py --duration 10 --spin-us 0

The client paces setpoints with absolute deadlines (``t0 + k * period`` on
``time.perf_counter``): it sleeps until shortly before each deadline and spins
the last ``--spin-us`` microseconds. A late setpoint does not shift the ones
after it. Everything runs on 127.0.0.1 (controller, RTDE client, URScript
program simulated by :class:`robocritics.testing.ursim.URSim`).

Reported:
* period error — |actual send interval − period| [ms], median / p99 / max
* lateness — send time − its deadline [ms], median / p99 / max
* setpoints applied — distinct sequence numbers the controller's program reported
  (output_int_register_24 at 500 Hz) / setpoints sent
* tracking error in motion — max over the run of max_j |actual_q − target_q| [rad]
* final tracking error — max_j |actual_q − last setpoint| after a 0.5 s hold [rad]
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import statistics
import time

from _table import print_table
from robocritics.testing.ursim import URSim
from robocritics.deploy import (
    INPUT_FIELDS,
    OUTPUT_FIELDS,
    RTDEClient,
    send_program,
    setpoint,
    streaming_program,
)

AMPLITUDE_RAD = (0.8, -0.5, 0.6, 1.0, -0.8, 1.5)


def min_jerk(s: float) -> float:
    """Minimum-jerk blend 0 → 1 for s in [0, 1]."""
    s = min(1.0, max(0.0, s))
    return s * s * s * (10 - 15 * s + 6 * s * s)


def percentile(values: list[float], p: float) -> float:
    v = sorted(values)
    k = min(len(v) - 1, max(0, math.ceil(p / 100 * len(v)) - 1))
    return v[k]


def _controller(conn) -> None:
    """Child process: the loopback controller, like a real controller on its own machine."""
    with URSim(rtde_port=0, dashboard_port=0, secondary_port=0) as sim:
        conn.send((sim.rtde_port, sim.secondary_port))
        conn.recv()  # wait for "report"
        conn.send((sim.loop_overruns, [e.message for e in sim.events("protective_stop")]))


def run(duration_s: float, rate_hz: float, spin_us: float, lookahead_s: float, gain: float) -> dict:
    period = 1.0 / rate_hz
    spin = spin_us * 1e-6
    parent, child = mp.get_context("spawn").Pipe()
    proc = mp.get_context("spawn").Process(target=_controller, args=(child,), daemon=True)
    proc.start()
    try:
        if not parent.poll(20):
            raise SystemExit("the loopback controller did not start")
        rtde_port, secondary_port = parent.recv()
        result = _stream(rtde_port, secondary_port, duration_s, rate_hz, period, spin, lookahead_s, gain)
        parent.send("report")
        overruns, protective = parent.recv()
    finally:
        proc.join(timeout=5)
        if proc.is_alive():
            proc.kill()
    result["controller_loop_overruns"] = overruns
    result["protective_stops"] = protective
    return result


def _stream(rtde_port, secondary_port, duration_s, rate_hz, period, spin, lookahead_s, gain) -> dict:
    with RTDEClient("127.0.0.1", rtde_port, timeout_s=1.0, buffer_size=100_000) as rtde:
        rtde.setup_outputs(["timestamp", "actual_q", "target_q", "runtime_state", "safety_mode", *OUTPUT_FIELDS], 500.0)
        rtde.setup_inputs(list(INPUT_FIELDS))
        rtde.start()
        q0 = list(rtde.wait_next(1.0)["actual_q"])
        seq = 0

        def send(q, done=False):
            nonlocal seq
            if not done:
                seq += 1
            rtde.send(setpoint(seq, q, 0.085, done=done, session=42))

        # hold while the program starts (the watchdog needs a live client before it is armed)
        send(q0)
        send_program("127.0.0.1", streaming_program(lookahead_time_s=lookahead_s, gain=gain), secondary_port)
        t_next = time.perf_counter()
        give_up = t_next + 2.0
        while True:
            send(q0)
            t_next += period
            time.sleep(max(0.0, t_next - time.perf_counter()))
            st = rtde.latest()
            if st.get("output_int_register_25") == 1 and st.get("output_int_register_26") == 42:
                break
            if time.perf_counter() > give_up:
                raise SystemExit(f"program did not start: {st}")
        rtde.drain()

        n = round(duration_s * rate_hz)
        target = [a + d for a, d in zip(q0, AMPLITUDE_RAD)]
        deadlines, sent = [], []
        t0 = time.perf_counter() + 0.01
        for k in range(1, n + 1):
            deadline = t0 + k * period
            remaining = deadline - time.perf_counter()
            if remaining > spin:
                time.sleep(remaining - spin)
            while time.perf_counter() < deadline:
                pass
            s = min_jerk(k / n)
            send([a + s * (b - a) for a, b in zip(q0, target)])
            sent.append(time.perf_counter())
            deadlines.append(deadline)
        motion = rtde.drain()
        # hold the final setpoint, then ask the program to finish
        for k in range(1, round(0.5 * rate_hz) + 1):
            deadline = sent[-1] + k * period
            time.sleep(max(0.0, deadline - time.perf_counter()))
            send(target)
        send(target, done=True)
        final = rtde.wait_for(lambda st: st["runtime_state"] == 1, 2.0, "the program to end")

    intervals = [b - a for a, b in zip(sent, sent[1:])]
    period_err_ms = [abs(dt - period) * 1e3 for dt in intervals]
    late_ms = [(s - d) * 1e3 for s, d in zip(sent, deadlines)]
    applied = {p["output_int_register_24"] for p in motion}
    first_seq = seq - n - round(0.5 * rate_hz)
    applied_in_motion = len([a for a in applied if first_seq < a <= first_seq + n])
    track = max(max(abs(a - b) for a, b in zip(p["actual_q"], p["target_q"])) for p in motion)
    final_err = max(abs(a - b) for a, b in zip(final["actual_q"], target))
    return {
        "setpoints": n,
        "duration_s": duration_s,
        "rate_hz": rate_hz,
        "period_error_ms": {"median": statistics.median(period_err_ms), "p99": percentile(period_err_ms, 99), "max": max(period_err_ms)},
        "lateness_ms": {"median": statistics.median(late_ms), "p99": percentile(late_ms, 99), "max": max(late_ms)},
        "applied_setpoints": applied_in_motion,
        "tracking_error_in_motion_rad": track,
        "final_tracking_error_rad": final_err,
        "program_state": final["output_int_register_25"],
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=5.0, help="trajectory duration [s] (default 5)")
    ap.add_argument("--rate", type=float, default=500.0, help="setpoint rate [Hz] (default 500)")
    ap.add_argument("--spin-us", type=float, default=300.0, help="busy-wait before each deadline [us] (default 300)")
    ap.add_argument("--lookahead", type=float, default=0.1, help="servoj lookahead_time [s] (default 0.1)")
    ap.add_argument("--gain", type=float, default=300.0, help="servoj gain (default 300)")
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    args = ap.parse_args(argv)
    r = run(args.duration, args.rate, args.spin_us, args.lookahead, args.gain)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    pe, la = r["period_error_ms"], r["lateness_ms"]
    rows = [
        ("setpoints sent", f"{r['setpoints']} over {r['duration_s']:g} s at {r['rate_hz']:g} Hz"),
        ("period error median / p99 / max", f"{pe['median']:.3f} / {pe['p99']:.3f} / {pe['max']:.3f} ms"),
        ("lateness median / p99 / max", f"{la['median']:.3f} / {la['p99']:.3f} / {la['max']:.3f} ms"),
        ("setpoints applied by the program", f"{r['applied_setpoints']} / {r['setpoints']}"),
        ("tracking error in motion (max)", f"{r['tracking_error_in_motion_rad']:.2e} rad"),
        ("final tracking error", f"{r['final_tracking_error_rad']:.2e} rad"),
        ("program state at end", f"{r['program_state']} (2 = DONE)"),
        ("controller loop overruns", str(r["controller_loop_overruns"])),
        ("protective stops", str(len(r["protective_stops"]))),
    ]
    print_table("bench_stream", "loopback URSim in its own process", rows, argv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
