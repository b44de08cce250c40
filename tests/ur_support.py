"""Helpers for the UR protocol tests: a streaming client driving the loopback controller."""

from __future__ import annotations

import math
import time
from typing import Sequence

from robocritics.testing.ursim import URSim
from robocritics.deploy import (
    INPUT_FIELDS,
    OUTPUT_FIELDS,
    DashboardClient,
    RTDEClient,
    send_program,
    setpoint,
    streaming_program,
)

STATE_FIELDS = ["timestamp", "actual_q", "target_q", "robot_mode", "safety_mode", "runtime_state"] + list(OUTPUT_FIELDS)
DT = 0.002


def sim_kwargs(**kw):
    """Ephemeral ports, robot powered and running, short unlock delay."""
    base = dict(rtde_port=0, dashboard_port=0, secondary_port=0, robot_mode="RUNNING", unlock_delay_s=0.3)
    base.update(kw)
    return base


class Streamer:
    """Streams setpoints at 500 Hz with absolute-deadline pacing."""

    def __init__(self, sim: URSim, session: int = 7, timeout_s: float = 1.0) -> None:
        self.sim = sim
        self.session = session
        self.client = RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=timeout_s)
        self.client.connect()
        self.client.setup_outputs(STATE_FIELDS, 500.0)
        self.client.setup_inputs(list(INPUT_FIELDS))
        self.client.start()
        self.state = self.client.wait_next(1.0)
        self.q = list(self.state["actual_q"])
        self.seq = 0
        self.gripper_m = 0.085
        self._next = time.perf_counter()

    def close(self) -> None:
        self.client.close()

    def __enter__(self) -> "Streamer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def send(self, q: Sequence[float], gripper_m: float | None = None, done: bool = False, bump: bool = True) -> None:
        if bump:
            self.seq += 1
        if gripper_m is not None:
            self.gripper_m = gripper_m
        self.q = list(q)
        self.client.send(setpoint(self.seq, self.q, self.gripper_m, done=done, session=self.session))

    def pace(self) -> None:
        self._next += DT
        delay = self._next - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        elif delay < -0.05:
            self._next = time.perf_counter()

    def hold(self, n: int, **kw) -> None:
        for _ in range(n):
            self.send(self.q, **kw)
            self.pace()

    def start_program(self, **program_kw) -> dict:
        """Stream hold setpoints, send the program, wait until it reports STREAMING."""
        self._next = time.perf_counter()
        self.hold(5)
        program_kw.setdefault("watchdog_min_hz", 5.0)
        send_program("127.0.0.1", streaming_program(**program_kw), self.sim.secondary_port, timeout_s=1.0)
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            self.hold(1)
            st = self.client.latest()
            if st["runtime_state"] == 2 and st["output_int_register_25"] == 1 and st["output_int_register_26"] == self.session:
                return st
        raise AssertionError(f"program did not start: {self.client.latest()} events {self.sim.events()}")

    def move(self, target: Sequence[float], duration_s: float) -> None:
        """A smooth (cosine-blend) joint move to ``target`` [rad] over ``duration_s`` [s]."""
        start = list(self.q)
        n = max(1, round(duration_s / DT))
        for k in range(1, n + 1):
            a = 0.5 * (1 - math.cos(math.pi * k / n))
            self.send([s + a * (t - s) for s, t in zip(start, target)])
            self.pace()

    def finish(self, timeout_s: float = 2.0) -> dict:
        self.send(self.q, done=True, bump=False)
        return self.client.wait_for(lambda s: s["runtime_state"] == 1, timeout_s, "the program to end")


def powered_dashboard(sim: URSim) -> DashboardClient:
    dash = DashboardClient("127.0.0.1", sim.dashboard_port, timeout_s=1.0)
    dash.connect()
    return dash
