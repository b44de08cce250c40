"""The streaming program as the loopback controller runs it, statement by statement, once per 2 ms cycle
(servo tracking, the RTDE watchdog, the stall check, the protective-stop rule, ``stopj`` on done), and the
placeholder a dashboard ``play`` starts.

Part of :mod:`robocritics.testing.ursim` (see :mod:`~robocritics.testing.ursim.controller`); a program
drives the controller through its methods (``sim`` is the :class:`~robocritics.testing.ursim.URSim`).
"""

from __future__ import annotations

import math

from robocritics.deploy import urscript
from robocritics.deploy.rtde import MessageLevel, TextMessage
from robocritics.testing.ursim.state import CONTROLLER_STOP_DECEL, DT, _State

# ---------------------------------------------------------------------------- programs


class _StreamProgram:
    """Our streaming program, executed one statement group per control cycle (see module doc)."""

    def __init__(self, sim: "URSim", params: urscript.StreamingProgramParams) -> None:
        self.sim = sim
        self.p = params
        self.name = params.name
        self.phase = "start"
        self.last_seq = 0
        self.stall = 0
        self.applied = [0.0] * 6
        self.v_ff = [0.0] * 6
        self.fresh = False
        self.last_opening = -1.0
        self.tau = max(DT, params.lookahead_time_s * 300.0 / params.gain)
        self.wd_limit_ticks = max(1, math.ceil(1.0 / (params.watchdog_min_hz * DT) - 1e-9))
        self.wd_armed_tick = 0

    def step(self, s: _State) -> None:
        sim = self.sim
        if self.phase == "start":
            s.out_int[urscript.STATE_REGISTER] = urscript.ProgramState.STARTING
            self.wd_armed_tick = s.tick
            q_t = s.in_double[24:30]
            worst = max(range(6), key=lambda j: abs(q_t[j] - s.q[j]))
            if abs(q_t[worst] - s.q[worst]) > self.p.max_start_deviation_rad:
                s.out_int[urscript.STATE_REGISTER] = urscript.ProgramState.START_REJECTED
                sim._end_program(
                    "start_rejected",
                    f"{self.name}: first setpoint of joint {worst} is {q_t[worst]:.4f} rad but the joint is at "
                    f"{s.q[worst]:.4f} rad (> {self.p.max_start_deviation_rad} rad); not starting",
                    CONTROLLER_STOP_DECEL,
                )
                return
            self.last_seq = s.in_int[urscript.SEQ_REGISTER]
            self.applied = list(q_t)
            s.out_int[urscript.APPLIED_SEQ_REGISTER] = self.last_seq
            s.out_int[urscript.SESSION_ECHO_REGISTER] = s.in_int[urscript.SESSION_REGISTER]
            s.out_int[urscript.STATE_REGISTER] = urscript.ProgramState.STREAMING
            self.phase = "run"
            self._gripper(s)
            self._servo(s)
            return
        if self.phase == "stopping":
            if sim._decelerate(s, self.p.stop_deceleration_rad_s2):
                sim._end_program("program_ended", f"{self.name} ended", None)
            return
        # running: the controller's watchdog first
        last_update = max(self.wd_armed_tick, s.input_update_tick.get(urscript.WATCHDOG_VARIABLE, -1))
        if s.tick - last_update > self.wd_limit_ticks:
            sim._end_program(
                "watchdog",
                f"RTDE watchdog: {urscript.WATCHDOG_VARIABLE} not updated for "
                f"{(s.tick - last_update) * DT:.3f} s (> 1/{self.p.watchdog_min_hz:g} Hz); program {self.name} stopped",
                CONTROLLER_STOP_DECEL,
            )
            return
        if s.in_int[urscript.COMMAND_REGISTER] == urscript.Command.DONE:
            s.out_int[urscript.STATE_REGISTER] = urscript.ProgramState.DONE
            sim._event("done", f"{self.name}: done command received, stopj({self.p.stop_deceleration_rad_s2:g})")
            self.phase = "stopping"
            self.step(s)
            return
        seq = s.in_int[urscript.SEQ_REGISTER]
        if seq != self.last_seq:
            new = s.in_double[24:30]
            dseq = (seq - self.last_seq) & 0xFFFFFFFF
            if dseq == 0 or dseq > 0x7FFFFFFF:
                dseq = 1  # counter reset or went backwards: treat as one step
            span = dseq * DT
            for j in range(6):
                speed = abs(new[j] - self.applied[j]) / span
                if speed > sim.jump_margin * sim.speed_limits[j]:
                    sim._protective_stop(
                        f"setpoint jump on joint {j}: {new[j] - self.applied[j]:+.4f} rad in {dseq} step(s) "
                        f"({dseq * DT * 1000:.0f} ms) needs {speed:.2f} rad/s > {sim.jump_margin:g} x limit "
                        f"{sim.speed_limits[j]:.3f} rad/s"
                    )
                    return
            self.v_ff = [(new[j] - self.applied[j]) / span for j in range(6)]
            self.applied = list(new)
            self.fresh = True
            self.last_seq = seq
            self.stall = 0
            s.out_int[urscript.APPLIED_SEQ_REGISTER] = seq
        else:
            self.fresh = False
            self.stall += 1
            if self.stall > self.p.stall_limit_cycles:
                s.out_int[urscript.STATE_REGISTER] = urscript.ProgramState.STALLED
                sim._event(
                    "stalled",
                    f"{self.name}: sequence counter stayed at {seq} for {self.stall} cycles; stopping",
                )
                sim._broadcast(TextMessage("robocritics: sequence counter stalled; stopping", self.name, MessageLevel.WARNING))
                self.phase = "stopping"
                self.step(s)
                return
        self._gripper(s)
        self._servo(s)

    def _gripper(self, s: _State) -> None:
        opening = s.in_double[urscript.GRIPPER_REGISTER]
        if opening != self.last_opening:
            s.gripper_opening_m = opening
            s.out_double[urscript.GRIPPER_APPLIED_REGISTER] = opening
            if self.p.gripper_close_below_m is not None:
                closed = opening < self.p.gripper_close_below_m
                s.digital_out = (s.digital_out & ~(1 << 16)) | ((1 << 16) if closed else 0)
            self.last_opening = opening

    def _servo(self, s: _State) -> None:
        limits = self.sim.speed_limits
        for j in range(6):
            ff = self.v_ff[j] if self.fresh else 0.0
            v = ff + (self.applied[j] - s.q[j]) / self.tau
            lim = limits[j]
            if v > lim:
                v = lim
            elif v < -lim:
                v = -lim
            s.target_qdd[j] = (v - s.qd[j]) / DT
            s.qd[j] = v
            s.q[j] += v * DT
        s.target_q = list(self.applied)
        s.target_qd = list(self.v_ff) if self.fresh else [0.0] * 6


class _HoldProgram:
    """A program started with the dashboard (``load`` + ``play``): it keeps the arm still."""

    def __init__(self, name: str) -> None:
        self.name = name

    def step(self, s: _State) -> None:
        pass
