"""Helpers for the UR protocol tests: the loopback controller in-process (stepped or real-time) or in its
own process, and a streaming client driving it."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator, Sequence

from robocritics.deploy import (
    INPUT_FIELDS,
    OUTPUT_FIELDS,
    DashboardClient,
    RTDEClient,
    send_program,
    setpoint,
    streaming_program,
)
from robocritics.robot.arms import UR3E
from robocritics.testing.ursim import URSim

STATE_FIELDS = ["timestamp", "actual_q", "target_q", "robot_mode", "safety_mode", "runtime_state"] + list(OUTPUT_FIELDS)
DT = UR3E.control_period_s


def sim_kwargs(**kw):
    """Ephemeral ports, short unlock delay (controller time)."""
    base = dict(rtde_port=0, dashboard_port=0, secondary_port=0, unlock_delay_s=0.3)
    base.update(kw)
    return base


def stepped(**kw):
    """:func:`sim_kwargs` for a controller on simulated time (one cycle per input package, plus ``step()``)."""
    return sim_kwargs(clock="stepped", **kw)


class Streamer:
    """Streams setpoints to the loopback controller, one per 2 ms control cycle.

    With a ``clock="stepped"`` controller every :meth:`send` is one cycle and returns once that
    cycle's data package has arrived (lockstep, deterministic); with a real-time controller
    :meth:`pace` keeps absolute 2 ms deadlines.
    """

    def __init__(self, sim: URSim, session: int = 7, timeout_s: float = 1.0) -> None:
        self.sim = sim
        self.session = session
        self.lockstep = sim.clock == "stepped"
        self.client = RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=timeout_s)
        self.client.connect()
        self.client.setup_outputs(STATE_FIELDS, 500.0)
        self.client.setup_inputs(list(INPUT_FIELDS))
        self.client.start()
        if self.lockstep:
            n0 = self.client.packages_received
            sim.step()
            self._await_package(n0)
            self.state = self.client.latest()
        else:
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

    def _await_package(self, n0: int, timeout_s: float = 2.0) -> None:
        deadline = time.monotonic() + timeout_s
        while self.client.packages_received <= n0:
            if not self.client.connected:
                self.client.latest()  # raises the connection's error
            if time.monotonic() > deadline:
                raise AssertionError(f"no data package for the cycle of setpoint {self.seq}; events {self.sim.events()}")
            time.sleep(0.0002)

    def send(self, q: Sequence[float], gripper_m: float | None = None, done: bool = False, bump: bool = True) -> dict:
        """Send one setpoint; in lockstep, return the state after the cycle it clocked."""
        if bump:
            self.seq += 1
        if gripper_m is not None:
            self.gripper_m = gripper_m
        self.q = list(q)
        n0 = self.client.packages_received
        self.client.send(setpoint(self.seq, self.q, self.gripper_m, done=done, session=self.session))
        if self.lockstep:
            self._await_package(n0)
        return self.client.latest()

    def pace(self) -> None:
        if self.lockstep:
            return
        self._next += DT
        delay = self._next - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        elif delay < -0.05:
            self._next = time.perf_counter()

    def hold(self, n: int, **kw) -> dict:
        st: dict = {}
        for _ in range(n):
            st = self.send(self.q, **kw)
            self.pace()
        return st

    def start_program(self, **program_kw) -> dict:
        """Stream hold setpoints, send the program, hold until it reports STREAMING with our session."""
        self._next = time.perf_counter()
        self.hold(5)
        program_kw.setdefault("watchdog_min_hz", 5.0)
        send_program("127.0.0.1", streaming_program(**program_kw), self.sim.secondary_port, timeout_s=1.0)
        for _ in range(1000):
            st = self.hold(1)
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

    def finish(self, max_cycles: int = 2000) -> dict:
        """Send the done command every cycle until the program has ended; the last state."""
        for _ in range(max_cycles):
            st = self.send(self.q, done=True, bump=False)
            self.pace()
            if st["runtime_state"] == 1:
                return st
        raise AssertionError(f"the program did not end within {max_cycles} cycles: {self.client.latest()}")


def powered_dashboard(sim: URSim) -> DashboardClient:
    dash = DashboardClient("127.0.0.1", sim.dashboard_port, timeout_s=1.0)
    dash.connect()
    return dash


# ---------------------------------------------------------------------------- the controller in its own process


@dataclass(frozen=True)
class ControllerProcess:
    """A ``robocritics ursim`` process on ephemeral ports (a real controller runs on its own machine)."""

    proc: subprocess.Popen
    rtde_port: int
    dashboard_port: int
    secondary_port: int

    def ports(self) -> list[str]:
        """The CLI options that reach it."""
        return ["--rtde-port", str(self.rtde_port), "--dashboard-port", str(self.dashboard_port),
                "--secondary-port", str(self.secondary_port)]

    def state(self, fields: Sequence[str] = ("actual_q", "actual_qd", "runtime_state", "safety_mode", *OUTPUT_FIELDS)) -> dict:
        """One fresh RTDE data package, read over the wire."""
        with RTDEClient("127.0.0.1", self.rtde_port, timeout_s=2.0) as probe:
            probe.setup_outputs(list(fields), 125)
            probe.start()
            return probe.wait_next(2.0)


@contextmanager
def controller_process(*args: str, start_timeout_s: float = 30.0) -> Iterator[ControllerProcess]:
    """Run ``python -m robocritics.testing.ursim`` with ``args`` on free ports; Ctrl-C (SIGINT) ends it."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "robocritics.testing.ursim", "--rtde-port", "0", "--dashboard-port", "0",
         "--secondary-port", "0", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        # Ctrl-C as a user sends it: a shell runs background jobs with SIGINT ignored, and that would be
        # inherited (Python then installs no KeyboardInterrupt handler)
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        line = proc.stdout.readline()  # blocks until the controller listens (or exits)
        if not line.startswith("URSim on 127.0.0.1: RTDE "):
            proc.kill()
            raise AssertionError(f"the controller did not start: {line!r} {proc.communicate(timeout=start_timeout_s)[1]}")
        rtde = int(line.split("RTDE ")[1].split(",")[0])
        dash = int(line.split("dashboard ")[1].split(",")[0])
        secondary = int(line.split("secondary ")[1].split(" ")[0])
        yield ControllerProcess(proc, rtde, dash, secondary)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        proc.stdout.close()
        proc.stderr.close()
