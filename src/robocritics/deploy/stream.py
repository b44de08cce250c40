"""Streaming a verified trajectory to a UR arm: resampling to the control rate, the paced servo
stream, fault detection while it runs, and stopping the arm.

:meth:`robocritics.deploy.URArm.deploy` runs the gate (:mod:`robocritics.deploy.gate`)
and then this module's stream; use it through ``URArm``.

**Resampling** (:func:`resample`). The trajectory (physical time axis) is resampled
to ``rate_hz`` (500 Hz: one setpoint per 2 ms control cycle; linear interpolation of
q and the gripper opening for sources at >= 125 Hz, monotone cubic (PCHIP) below).

**Streaming.** The client holds the first setpoint (sequence counter incrementing
every period) and, once the controller echoes the counter (``input_int_register_24``
read back as an output, so the program cannot read zeros), sends
:func:`~robocritics.deploy.urscript.streaming_program` (from a helper thread, so
holding never pauses); it waits until the program reports
STREAMING with this deploy's random session id, then streams with absolute
deadlines ``t0 + k / rate_hz`` (sleep, then spin the last ``spin_s``; a client
more than 5 periods late shifts its schedule rather than bursting the missed
setpoints, which the controller would see as a jump). After the last setpoint it
holds the final one until the arm settles (or ``settle_timeout_s``), sends the
done command and waits for the program to end.

**Faults.** Every data package is checked while streaming; any of these stops
the arm and raises :class:`DeployFault` (a ``DeployError``) with ``cause``,
``sample`` (index of the last *trajectory* sample sent), ``time_s``,
``stopped`` and ``actual_q``:

``protective_stop`` / ``safety_mode`` (safety_mode leaves NORMAL),
``robot_mode``, ``connection_drop`` (RTDE connection failed),
``controller_silent`` (no data package for ``silence_timeout_s``),
``controller_slow`` (fewer packages than ``min_data_rate_fraction`` of the recipe
frequency per second of the controller's own ``timestamp``, over
:data:`STREAM_RATE_WINDOW_S` windows: packages dropped or throttled), ``program_stalled`` / ``program_stopped`` /
``session`` (program state register, runtime_state, session echo),
``start_rejected`` / ``program_not_started`` (start-up), ``tracking_error``
(``actual_q`` farther than ``max_tracking_error_rad`` from every setpoint sent
in the last ``lookahead_time_s + 20 ms``), ``remote_control`` / ``dashboard``
(a monitor thread polls the dashboard every ``monitor_period_s``),
``program_did_not_finish``, ``non_finite`` (a data package carried NaN or ±inf:
the RTDE client's guard, :func:`~robocritics.deploy.rtde.first_non_finite`, names
the field; nothing read after it is trusted, so the stop is confirmed over the
dashboard), ``controller_flood`` (the controller sent more packages nobody asked
for than :data:`~robocritics.deploy.rtde.MAX_UNEXPECTED_PACKAGES`),
``interrupted`` (KeyboardInterrupt etc.; re-raised after the stop), ``stop_requested``
(the caller's ``stop`` event was set, e.g. a Stop button: the same stop path as any fault).

**Progress**: ``progress(DeployProgress)``, when given, is called from the streaming thread at most every
:data:`PROGRESS_PERIOD_S` while streaming (and once at its end); it must return quickly.

**Stopping**: the done command over RTDE (the program ``stopj``'s), confirmed by
``runtime_state``; if RTDE is gone or the program does not stop within
``stop_timeout_s``, the dashboard ``stop``. The controller's own RTDE watchdog
(``watchdog_min_hz``) stops the program as soon as the client stops sending, so
the arm stops even if both channels fail. Every wait has a deadline.
"""

from __future__ import annotations

import math
import statistics
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from robocritics.deploy.connection import URConnection
from robocritics.deploy.dashboard import DashboardClient
from robocritics._text import safe_text
from robocritics.deploy.rtde import (
    MessageLevel,
    RobotMode,
    RTDEFloodError,
    RTDEValueError,
    RuntimeState,
    SafetyMode,
    mode_name,
)
from robocritics.deploy.urscript import INPUT_FIELDS, OUTPUT_FIELDS, ProgramState, send_program, setpoint
from robocritics.errors import DeployError, RTDEError
from robocritics.robot.arms import UR3E
from robocritics.trajectory import Trajectory


__all__ = ["DeployFault", "DeployResult", "StreamPlan", "resample", "STATE_FIELDS", "STILL_RAD_S"]

SEQ_ECHO_FIELD = INPUT_FIELDS[0]
"""The sequence counter input register, read back as an output: the controller has our setpoint."""

STATE_FIELDS: tuple[str, ...] = (
    "timestamp",
    "actual_q",
    "actual_qd",
    "target_q",
    "robot_mode",
    "safety_mode",
    "runtime_state",
    *OUTPUT_FIELDS,
    SEQ_ECHO_FIELD,
)
"""The output recipe :class:`~robocritics.deploy.URArm` sets up (at 500 Hz)."""


def rtde_type(name: str) -> str:
    """The RTDE type of a field :class:`~robocritics.deploy.URArm` uses, as the RTDE specification gives it: a
    controller answering another type for it is refused at connect (a mode field sent as DOUBLE could be NaN)."""
    if name in ("actual_q", "actual_qd", "target_q"):
        return "VECTOR6D"
    if name == "timestamp" or "_double_register_" in name:
        return "DOUBLE"
    if name == "runtime_state":
        return "UINT32"
    return "INT32"  # robot_mode, safety_mode, the int registers

MAX_KEPT_MESSAGES = 100
"""Controller error/warning messages one deployment keeps (for :attr:`DeployFault.controller_messages`)."""

STILL_RAD_S = 1e-3
"""Joint speeds below this count as standing still [rad/s]."""

STREAM_RATE_WINDOW_S = 0.25
"""The data rate is checked over windows this long [s] (``controller_slow``)."""

MAX_SETPOINTS = 500 * 3600 * 8
"""Most setpoints one stream may have: 8 hours at 500 Hz (about 0.7 GB of setpoints)."""

#: Seconds between two progress reports of a running stream.
PROGRESS_PERIOD_S = 0.1


@dataclass(frozen=True)
class DeployProgress:
    """Where a running stream is: ``phase`` (starting, streaming, settling, finishing), ``setpoints_sent`` of
    ``setpoints_total`` (the resampled plan), ``time_s`` of ``duration_s`` along the trajectory [s], the latest
    ``tracking_error_rad`` and the largest so far ``max_tracking_error_rad`` [rad]."""

    phase: str
    setpoints_sent: int
    setpoints_total: int
    time_s: float
    duration_s: float
    tracking_error_rad: float
    max_tracking_error_rad: float


RESYNC_AFTER_PERIODS = 5
"""A client this many periods late shifts its schedule instead of bursting the missed setpoints."""


# ---------------------------------------------------------------------------- results

class DeployFault(DeployError):
    """A fault stopped a running deployment.

    ``sample`` is the index of the last trajectory sample sent (-1 before any),
    ``cause`` a short cause (see the module docstring), ``time_s`` the trajectory
    time of that sample [s], ``setpoint_index`` the index in the resampled stream,
    ``stopped`` whether the stop was confirmed by the controller (program no longer
    running), ``stop_report`` how the arm was stopped, ``actual_q`` the last joint
    positions received [rad] (None if none), ``controller_messages`` the
    controller's error/warning text messages seen during the deploy.
    """

    def __init__(
        self,
        message: str,
        *,
        sample: int,
        cause: str,
        time_s: float,
        setpoint_index: int,
        stopped: bool,
        stop_report: str,
        actual_q: tuple[float, ...] | None,
        controller_messages: Sequence[str] = (),
    ):
        self.time_s = time_s
        self.setpoint_index = setpoint_index
        self.stopped = stopped
        self.stop_report = stop_report
        self.actual_q = actual_q
        self.controller_messages = tuple(controller_messages)
        super().__init__(message, sample=sample, cause=cause)


@dataclass(frozen=True)
class DeployResult:
    """What a deployment did. Times in s, angles in rad, period errors in ms."""

    samples_sent: int
    """Setpoints streamed from the resampled trajectory (not counting hold setpoints)."""
    trajectory_samples: int
    """Samples of the deployed trajectory (its own rate)."""
    rate_hz: float
    duration_s: float
    """Wall time from the first to the last trajectory setpoint [s]."""
    trajectory_duration_s: float
    """Duration of the trajectory on its physical time axis [s]."""
    period_error_median_ms: float
    """Median of |send interval - 1/rate_hz| [ms]."""
    period_error_p99_ms: float
    period_error_max_ms: float
    lateness_p99_ms: float
    """99th percentile of (send time - deadline) [ms]."""
    max_tracking_error_rad: float
    """Largest distance (max over joints) between actual_q and the nearest setpoint of the lookahead window [rad]."""
    final_q: tuple[float, ...]
    """actual_q after the program ended [rad]."""
    final_error_rad: float
    """max_j |final_q - last trajectory sample| [rad]."""
    settle_s: float
    """Time the final setpoint was held before the done command [s]."""
    resyncs: int
    """Times the client fell more than 5 periods behind and shifted its schedule (the motion ran that much later)."""
    data_packages: int
    """RTDE data packages checked during the deploy."""
    trajectory_hash: str
    session: int
    dry_run: bool = False
    program: str = field(default="", repr=False)
    """The URScript text that was (or, in a dry run, would have been) sent."""

    planned_setpoints: int = 0
    """Setpoints of the resampled stream (also filled in a dry run)."""

    def summary(self) -> str:
        if self.dry_run:
            return (
                f"dry run: {self.trajectory_samples} samples would stream as "
                f"{self.planned_setpoints} setpoints at {self.rate_hz:g} Hz over {self.trajectory_duration_s:.3f} s; "
                "gate passed, nothing sent"
            )
        return (
            f"deployed {self.samples_sent} setpoints at {self.rate_hz:g} Hz in {self.duration_s:.3f} s "
            f"(trajectory {self.trajectory_duration_s:.3f} s); period error median {self.period_error_median_ms:.3f} ms, "
            f"p99 {self.period_error_p99_ms:.3f} ms; max tracking error {self.max_tracking_error_rad:.2e} rad; "
            f"final error {self.final_error_rad:.2e} rad"
        )


@dataclass(frozen=True)
class StreamPlan:
    """A trajectory resampled for streaming: one row per setpoint.

    ``q (N, 6)`` rad, ``gripper_opening_m (N,)``, ``time (N,)`` s from the first
    sample, ``source_index (N,)`` the last trajectory sample at or before each
    setpoint's time, ``rate_hz``.
    """

    q: np.ndarray
    gripper_opening_m: np.ndarray
    time: np.ndarray
    source_index: np.ndarray
    rate_hz: float
    interpolation: str

    def __len__(self) -> int:
        return int(self.q.shape[0])




# ---------------------------------------------------------------------------- resampling


def resample(trajectory: Trajectory, rate_hz: float = UR3E.control_rate_hz) -> StreamPlan:
    """Resample ``trajectory`` (physical time axis) to ``rate_hz`` setpoints.

    Setpoint k is at ``k / rate_hz`` s from the first sample; the last setpoint is
    the last sample exactly (added if the duration is not a multiple of the
    period). q and the gripper opening are interpolated linearly when the source
    has samples at least every 8 ms (125 Hz), else with a monotone cubic (PCHIP),
    which never overshoots between samples. Raises :class:`DeployError` for
    anything but a :class:`~robocritics.trajectory.Trajectory` or a rate that is
    not a positive number of Hz.
    """
    if not isinstance(trajectory, Trajectory):
        raise DeployError(f"resample() needs a robocritics.Trajectory, got {type(trajectory).__name__}")
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise DeployError(f"resample(): rate_hz must be a positive number of Hz, got {rate_hz}")
    q_src, t_src, g_src = trajectory.q, trajectory.time, trajectory.gripper_opening_m
    if len(t_src) == 0:
        raise DeployError("resample(): the trajectory has no samples")
    for name, values in (("q", q_src), ("time", t_src), ("gripper_opening_m", g_src)):
        bad = np.flatnonzero(~np.isfinite(np.asarray(values, dtype=float).reshape(len(values), -1)).all(axis=1))
        if len(bad):
            raise DeployError(f"resample(): trajectory {name} is not finite at sample {int(bad[0])}")
    if np.any(np.diff(t_src) < 0):
        raise DeployError("resample(): the trajectory's times are not in order")
    if not float(t_src[-1] - t_src[0]) * rate_hz <= MAX_SETPOINTS:
        raise DeployError(
            f"resample(): {float(t_src[-1] - t_src[0]):.6g} s at {rate_hz:g} Hz is more than {MAX_SETPOINTS:,} setpoints"
        )
    t = t_src - t_src[0]
    period = 1.0 / float(rate_hz)
    end = float(t[-1])
    n = int(math.floor(end / period + 1e-9)) + 1
    ts = np.arange(n) * period
    if end - ts[-1] > 1e-9:
        ts = np.append(ts, end)
    ts[-1] = min(ts[-1], end)
    if len(t) == 1:
        q = np.repeat(q_src, len(ts), axis=0)
        g = np.repeat(g_src, len(ts))
        how = "constant"
    elif float(np.max(np.diff(t))) <= 1.0 / 125.0 + 1e-9:
        q = np.column_stack([np.interp(ts, t, q_src[:, j]) for j in range(q_src.shape[1])])
        g = np.interp(ts, t, g_src)
        how = "linear"
    else:
        from ..planning.spline import pchip

        q = pchip(t, q_src, ts)
        g = np.clip(pchip(t, g_src, ts), g_src.min(), g_src.max())
        how = "pchip"
    q[-1] = q_src[-1]
    g[-1] = g_src[-1]
    src = np.searchsorted(t, ts + 1e-9, side="right") - 1
    return StreamPlan(q=q, gripper_opening_m=g, time=ts, source_index=src.astype(np.int64), rate_hz=float(rate_hz), interpolation=how)


def _holds_ours(echo: Any, first: int, last: int) -> bool:
    """Whether the echoed sequence counter is one this run sent (``first`` … ``last``, int32 wrap-around)."""
    if echo is None:
        return False
    return (int(echo) - first) % 2**32 <= (last - first) % 2**32


def _percentile(values: Sequence[float], p: float) -> float:
    return float(np.percentile(np.asarray(values, dtype=float), p)) if len(values) else float("nan")


# ---------------------------------------------------------------------------- internal fault signal


class _Fault(Exception):
    def __init__(self, cause: str, detail: str):
        self.cause = cause
        self.detail = detail
        super().__init__(detail)


def _rtde_fault(exc: Exception) -> _Fault:
    """The fault for an RTDE error: ``non_finite``, ``controller_flood`` or ``connection_drop``."""
    if isinstance(exc, RTDEValueError):
        return _Fault("non_finite", str(exc))
    if isinstance(exc, RTDEFloodError):
        return _Fault("controller_flood", str(exc))
    return _Fault("connection_drop", f"the RTDE connection failed: {exc}")


def _safety_fault(safety_mode: Any, when: str = "") -> _Fault:
    """The fault for a safety mode other than NORMAL; ``when`` ends the message."""
    cause = "protective_stop" if safety_mode == SafetyMode.PROTECTIVE_STOP else "safety_mode"
    return _Fault(cause, f"the controller's safety mode became {mode_name(SafetyMode, safety_mode)}{when}")


class _DashboardMonitor:
    """Polls ``is in remote control`` while a deployment runs (its own thread)."""

    def __init__(self, conn: URConnection, period_s: float) -> None:
        self.conn = conn
        self.period_s = period_s
        self.fault: _Fault | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="urarm-dashboard-monitor", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self, wait_s: float | None = None) -> None:
        """Ask the thread to end; wait at most ``wait_s`` (default: one dashboard timeout) [s]."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=self.conn.timeout_s + 0.5 if wait_s is None else wait_s)

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            try:
                with self.conn.dash_lock:
                    dash = self.conn.dashboard_client
                    if dash is None:
                        raise RTDEError("the dashboard connection is closed")
                    remote = dash.is_in_remote_control()
            except RTDEError as exc:
                self.conn.dashboard_broken = True
                self.fault = _Fault("dashboard", f"the dashboard server stopped answering, so remote control cannot be confirmed: {exc}")
                return
            if not remote:
                self.fault = _Fault("remote_control", "the controller left remote control (switched to local control on the teach pendant)")
                return


@dataclass
class _Run:
    """Book-keeping of one streaming run."""

    plan: StreamPlan
    session: int
    step: int
    max_tracking_error_rad: float
    window: int
    phase: str = "starting"
    k: int = -1  # index of the last setpoint of the plan sent (-1: hold only)
    sent_any: bool = False
    last_q: np.ndarray | None = None
    last_opening: float = 0.0
    max_err: float = 0.0
    packages: int = 0
    last_state: dict[str, Any] = field(default_factory=dict)
    messages: list[str] = field(default_factory=list)
    rate_ts0: float | None = None
    """Controller timestamp at which the current rate window began [s]."""
    rate_n: int = 0
    """Packages received in the current rate window."""
    last_check: float = 0.0
    """perf_counter of the last check [s] (0: none yet)."""
    awake_since: float = 0.0
    """perf_counter since which this process has been checking without a stall [s]."""
    stop: threading.Event | None = None
    """Set by the caller to stop the arm (fault ``stop_requested``)."""
    progress: Any = None
    """``progress(DeployProgress)`` or None."""
    last_err: float = 0.0
    last_progress: float = 0.0

    def sample(self) -> int:
        if not self.sent_any:
            return -1
        return int(self.plan.source_index[max(self.k, 0)])

    def time_s(self) -> float:
        return float(self.plan.time[max(self.k, 0)]) if self.sent_any else 0.0



def report_progress(run: _Run) -> None:
    """Call ``run.progress`` with where the stream is (its exceptions are the caller's bug: not a fault)."""
    try:
        run.progress(DeployProgress(
            phase=run.phase, setpoints_sent=run.k + 1, setpoints_total=len(run.plan), time_s=run.time_s(),
            duration_s=float(run.plan.time[-1]), tracking_error_rad=run.last_err,
            max_tracking_error_rad=run.max_err,
        ))
    except Exception:  # noqa: BLE001 - a progress display must never stop (or fail to stop) the arm
        pass


def _result(run: _Run, program: str, sent_times: list[float], deadlines: list[float], final: dict[str, Any],
            settle_s: float, resyncs: int, trajectory_hash: str, trajectory_samples: int) -> DeployResult:
    """The :class:`DeployResult` of a run that finished: timing statistics of the sends, the final pose."""
    plan = run.plan
    period = 1.0 / plan.rate_hz
    rate = plan.rate_hz
    intervals = np.diff(np.asarray(sent_times))
    perr = np.abs(intervals - period) * 1e3 if len(intervals) else np.zeros(1)
    late = (np.asarray(sent_times) - np.asarray(deadlines)) * 1e3 if sent_times else np.zeros(1)
    final_q = tuple(float(v) for v in final["actual_q"])
    return DeployResult(
        samples_sent=len(sent_times),
        trajectory_samples=trajectory_samples,
        rate_hz=rate,
        duration_s=float(sent_times[-1] - sent_times[0]) if sent_times else 0.0,
        trajectory_duration_s=float(plan.time[-1]),
        period_error_median_ms=float(statistics.median(perr.tolist())),
        period_error_p99_ms=_percentile(perr.tolist(), 99),
        period_error_max_ms=float(np.max(perr)),
        lateness_p99_ms=_percentile(late.tolist(), 99),
        max_tracking_error_rad=run.max_err,
        final_q=final_q,
        final_error_rad=float(np.max(np.abs(np.asarray(final_q) - plan.q[-1]))),
        settle_s=settle_s,
        resyncs=resyncs,
        data_packages=run.packages,
        trajectory_hash=trajectory_hash,
        session=run.session,
        dry_run=False,
        program=program,
        planned_setpoints=len(plan),
    )


# ---------------------------------------------------------------------------- the stream


class _Stream:
    """One streaming run over a connected :class:`~robocritics.deploy.connection.URConnection` (a
    :class:`~robocritics.deploy.URArm`'s channels and its sequence counter)."""

    def __init__(self, conn: URConnection) -> None:
        self.conn = conn


    def _send(self, run: _Run, q: np.ndarray, opening: float, *, done: bool = False, bump: bool = True) -> None:
        if bump:
            self.conn.seq = ((self.conn.seq + run.step + 2**31) % 2**32) - 2**31
        try:
            self.conn.rtde.send(setpoint(self.conn.seq, q, opening, done=done, session=run.session), self.conn.inputs)
        except RTDEError as exc:
            raise _rtde_fault(exc) from None
        run.sent_any = True
        run.last_q = q
        run.last_opening = opening

    def _collect_messages(self, run: _Run) -> None:
        rtde = self.conn.rtde_client
        if rtde is None:
            return
        for m in rtde.messages():
            self.conn.messages.append(m)
            if m.level <= MessageLevel.WARNING and len(run.messages) < MAX_KEPT_MESSAGES:
                run.messages.append(safe_text(f"{m.level_name} [{m.source}] {m.message}", 600))

    def _check(self, run: _Run, monitor: _DashboardMonitor | None, now: float, silence_timeout_s: float,
               min_rate: float) -> None:
        """Raise _Fault if anything is wrong; process every data package received since the last check."""
        rtde = self.conn.rtde
        if run.stop is not None and run.stop.is_set():
            raise _Fault("stop_requested", "stopped on request (Stop)")
        if monitor is not None and monitor.fault is not None:
            raise monitor.fault
        if not rtde.connected:
            try:
                rtde.latest()
            except RTDEError as exc:
                raise _rtde_fault(exc) from None
            raise _Fault("connection_drop", "the RTDE connection is closed")
        for st in self._drain():
            run.packages += 1
            run.last_state = st
            if st["safety_mode"] != SafetyMode.NORMAL:
                raise _safety_fault(st["safety_mode"])
            if st["robot_mode"] != RobotMode.RUNNING:
                raise _Fault("robot_mode", f"the robot mode became {mode_name(RobotMode, st['robot_mode'])}")
            if run.phase in ("streaming", "settling"):
                pstate = st[OUTPUT_FIELDS[1]]
                if pstate == ProgramState.STALLED:
                    raise _Fault("program_stalled", "the streaming program reported STALLED (it saw the sequence counter stop) and stopped")
                if st[OUTPUT_FIELDS[2]] != run.session:
                    raise _Fault("session", f"the program echoes session {st[OUTPUT_FIELDS[2]]}, not ours ({run.session}); another program took over")
                if st["runtime_state"] != RuntimeState.PLAYING:
                    raise _Fault(
                        "program_stopped",
                        f"the program stopped: runtime state {mode_name(RuntimeState, st['runtime_state'])}, program state "
                        f"{mode_name(ProgramState, pstate)} (controller watchdog, a dashboard stop, or a crash)",
                    )
                if pstate != ProgramState.STREAMING:
                    raise _Fault("program_stopped", f"the program left the STREAMING state: {mode_name(ProgramState, pstate)}")
            # tracking: distance to the nearest setpoint of the lookahead window
            actual = np.asarray(st["actual_q"], dtype=float)
            k = run.k
            if k < 0:
                err = float(np.max(np.abs(actual - run.plan.q[0])))
            else:
                win = run.plan.q[max(0, k - run.window) : k + 1]
                err = float(np.min(np.max(np.abs(win - actual), axis=1)))
            if run.phase != "starting":
                run.max_err = max(run.max_err, err)
                run.last_err = err
            if not err <= run.max_tracking_error_rad:  # NaN fails the rule too
                raise _Fault(
                    "tracking_error",
                    f"tracking error {err:.4f} rad > max_tracking_error_rad {run.max_tracking_error_rad:g}: actual_q is "
                    f"that far from every setpoint sent in the last {run.window} cycles",
                )
            self._count_rate(run, float(st["timestamp"]), min_rate)
        if run.last_check and now - run.last_check > 0.5 * silence_timeout_s:
            # this process was not running (a loaded host): what did not arrive meanwhile is no verdict on the
            # controller; it gets silence_timeout_s from now
            run.awake_since = now
        run.last_check = now
        if run.progress is not None and now - run.last_progress >= PROGRESS_PERIOD_S:
            run.last_progress = now
            report_progress(run)
        age = min(rtde.age_s(), now - run.awake_since)
        if age > silence_timeout_s:
            raise _Fault("controller_silent", f"no RTDE data package for {age:.3f} s (> silence_timeout_s {silence_timeout_s:g})")

    def _drain(self) -> list[dict[str, Any]]:
        """The data packages received since the last call; an RTDE error (non-finite value, flood, drop) is a fault."""
        try:
            return self.conn.rtde.drain()
        except RTDEError as exc:
            raise _rtde_fault(exc) from None

    def _count_rate(self, run: _Run, timestamp_s: float, min_rate: float) -> None:
        """``controller_slow``: packages per second of the controller's own time (its ``timestamp``), over
        windows of :data:`STREAM_RATE_WINDOW_S` — packages it dropped or throttled, not a client that was late."""
        if not math.isfinite(timestamp_s):  # the client's guard drops such packages; never count one
            raise _Fault("non_finite", f"the controller's timestamp is {timestamp_s}")
        if run.rate_ts0 is None or timestamp_s < run.rate_ts0:
            run.rate_ts0, run.rate_n = timestamp_s, 0
            return
        run.rate_n += 1
        span = timestamp_s - run.rate_ts0
        if span < STREAM_RATE_WINDOW_S:
            return
        expected = self.conn.out_freq * span
        if not run.rate_n >= min_rate * expected:
            raise _Fault(
                "controller_slow",
                f"the controller sent {run.rate_n} data packages in {span:.3f} s of its own time "
                f"({run.rate_n / span:.0f} Hz, expected {self.conn.out_freq:g} Hz; minimum {min_rate:.0%}): "
                "it drops packages or is throttled",
            )
        run.rate_ts0, run.rate_n = timestamp_s, 0

    def run(
        self,
        run: _Run,
        program: str,
        *,
        trajectory_hash: str,
        trajectory_samples: int,
        silence_timeout_s: float,
        min_data_rate_fraction: float,
        start_timeout_s: float,
        settle_tolerance_rad: float,
        settle_timeout_s: float,
        stop_timeout_s: float,
        monitor_period_s: float,
        spin_s: float,
    ) -> DeployResult:
        """The stream in its phases: start (hold the first setpoint until the program streams with our session),
        stream (every setpoint on an absolute schedule), settle (hold the last until the arm is there), finish
        (the done command until the program ends); any fault stops the arm (:meth:`_fail`)."""
        rtde = self.conn.rtde
        period = 1.0 / run.plan.rate_hz
        try:
            rtde.drain()
        except RTDEError:
            pass  # the first check below reports it, with the stop path
        self._collect_messages(run)
        run.messages.clear()
        monitor = _DashboardMonitor(self.conn, monitor_period_s)
        monitor.start()

        def check(now: float) -> None:
            self._check(run, monitor, now, silence_timeout_s, min_data_rate_fraction)

        try:
            self._start(run, program, check, period, start_timeout_s)
            sent_times, deadlines, resyncs = self._stream(run, check, period, spin_s)
            settle_s = self._settle(run, check, period, sent_times, settle_tolerance_rad, settle_timeout_s)
            final = self._finish(run, monitor, period, stop_timeout_s, silence_timeout_s)
        except _Fault as fault:
            raise self._fail(run, fault, monitor, stop_timeout_s, silence_timeout_s) from None
        except RTDEError as exc:  # a read outside the checks above: the same stop
            raise self._fail(run, _rtde_fault(exc), monitor, stop_timeout_s, silence_timeout_s) from None
        except BaseException as exc:
            # KeyboardInterrupt, a bug: stop the arm before anything else happens
            self._fail(run, _Fault("interrupted", f"{type(exc).__name__}: {exc}"), monitor, stop_timeout_s, silence_timeout_s)
            raise
        finally:
            monitor.stop(wait_s=0.1)
        return _result(run, program, sent_times, deadlines, final, settle_s, resyncs, trajectory_hash,
                       trajectory_samples)  # fmt: skip

    def _start(self, run: _Run, program: str, check: Callable[[float], None], period: float,
               start_timeout_s: float) -> None:
        """Hold the first setpoint, send the program once the controller echoes it, wait until it streams with
        our session."""
        rtde, plan = self.conn.rtde, run.plan
        # ---- hold the first setpoint, send the program, wait until it streams with our session
        q0, g0 = plan.q[0], float(plan.gripper_opening_m[0])
        if rtde.data_fault is not None:  # nothing is sent after a value that is not a number
            raise _rtde_fault(rtde.data_fault)
        try:
            state_before = rtde.latest().get(OUTPUT_FIELDS[1])
        except RTDEError as exc:
            raise _rtde_fault(exc) from None
        self._send(run, q0, g0)
        first_hold = self.conn.seq
        sender_error: list[BaseException] = []

        def send_it() -> None:
            try:
                send_program(self.conn.host, program, self.conn.secondary_port, timeout_s=self.conn.timeout_s)
            except BaseException as exc:  # reported by the streaming thread
                sender_error.append(exc)

        sender: threading.Thread | None = None
        t_next = time.perf_counter()
        give_up = t_next + start_timeout_s
        while True:
            t_next += period
            delay = t_next - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.05:
                t_next = time.perf_counter()
            self._send(run, q0, g0)
            now = time.perf_counter()
            check(now)
            self._collect_messages(run)
            if sender is None and _holds_ours(run.last_state.get(SEQ_ECHO_FIELD), first_hold, self.conn.seq):
                # the controller has our first setpoint in its registers: the program will read it, not zeros
                sender = threading.Thread(target=send_it, name="urarm-send-program", daemon=True)
                sender.start()
            if sender_error:
                raise _Fault("program_not_started", f"sending the program failed: {sender_error[0]}")
            st = run.last_state
            if st:
                pstate = st[OUTPUT_FIELDS[1]]
                if (
                    st["runtime_state"] == RuntimeState.PLAYING
                    and pstate == ProgramState.STREAMING
                    and st[OUTPUT_FIELDS[2]] == run.session
                ):
                    break
                if pstate == ProgramState.START_REJECTED and state_before != ProgramState.START_REJECTED:
                    raise _Fault("start_rejected", "the program refused to start: the first setpoint is too far from the actual joint positions")
            if sender is not None and not sender.is_alive() and run.messages and any(
                m.startswith(("ERROR", "EXCEPTION")) for m in run.messages
            ):
                raise _Fault("program_not_started", "the controller reported an error after the program was sent")
            if now > give_up:
                if sender is None:
                    raise _Fault(
                        "program_not_started",
                        f"the controller did not echo the held setpoint ({SEQ_ECHO_FIELD}) within start_timeout_s "
                        f"{start_timeout_s:g} s; the program was not sent",
                    )
                raise _Fault(
                    "program_not_started",
                    f"the program did not report STREAMING with session {run.session} within start_timeout_s "
                    f"{start_timeout_s:g} s (last state {st.get(OUTPUT_FIELDS[1]) if st else None}, runtime "
                    f"{st.get('runtime_state') if st else None})",
                )
        if sender is not None:
            sender.join(timeout=self.conn.timeout_s)

    def _stream(self, run: _Run, check: Callable[[float], None], period: float,
                spin_s: float) -> tuple[list[float], list[float], int]:
        """Every setpoint at its absolute deadline: ``(send times, deadlines, resyncs)`` (perf_counter s)."""
        plan = run.plan
        sent_times: list[float] = []
        deadlines: list[float] = []
        resyncs = 0
        resync_after_s = RESYNC_AFTER_PERIODS * period
        # ---- stream with absolute deadlines
        run.phase = "streaming"
        t0 = time.perf_counter() + period
        n = len(plan)
        for k in range(n):
            deadline = t0 + k * period
            remaining = deadline - time.perf_counter()
            if remaining > spin_s:
                time.sleep(remaining - spin_s)
            elif remaining < -resync_after_s:
                # far behind (the host stalled): shift the schedule instead of bursting the missed
                # setpoints, which the controller would see as one jump of the target
                t0 -= remaining
                deadline -= remaining
                resyncs += 1
            while time.perf_counter() < deadline:
                pass
            run.k = k
            self._send(run, plan.q[k], float(plan.gripper_opening_m[k]))
            now = time.perf_counter()
            sent_times.append(now)
            deadlines.append(deadline)
            check(now)
        self._collect_messages(run)
        if run.progress is not None:
            report_progress(run)
        return sent_times, deadlines, resyncs

    def _settle(self, run: _Run, check: Callable[[float], None], period: float, sent_times: list[float],
                settle_tolerance_rad: float, settle_timeout_s: float) -> float:
        """Hold the final setpoint until the arm is within ``settle_tolerance_rad`` of it (or the timeout); the
        time it took [s]."""
        plan = run.plan
        # ---- hold the final setpoint until the arm settles
        run.phase = "settling"
        q_end, g_end = plan.q[-1], float(plan.gripper_opening_m[-1])
        t_settle = time.perf_counter()
        t_next = sent_times[-1] if sent_times else t_settle
        while True:
            t_next += period
            delay = t_next - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            self._send(run, q_end, g_end)
            now = time.perf_counter()
            check(now)
            st = run.last_state
            if st and float(np.max(np.abs(np.asarray(st["actual_q"]) - q_end))) <= settle_tolerance_rad:
                break
            if now - t_settle >= settle_timeout_s:
                break
        settle_s = time.perf_counter() - t_settle
        return settle_s

    def _finish(self, run: _Run, monitor: _DashboardMonitor, period: float, stop_timeout_s: float,
                silence_timeout_s: float) -> dict[str, Any]:
        """Send the done command until the program has ended and the arm stands still; that state package."""
        rtde, plan = self.conn.rtde, run.plan
        q_end, g_end = plan.q[-1], float(plan.gripper_opening_m[-1])
        # ---- done: the program stopj's and ends
        run.phase = "finishing"
        monitor.stop(wait_s=0.0)
        end_by = time.perf_counter() + stop_timeout_s
        final = None
        while True:
            self._send(run, q_end, g_end, done=True)
            time.sleep(period)
            now = time.perf_counter()
            if not rtde.connected:
                raise _Fault("connection_drop", "the RTDE connection failed while the program was finishing")
            packages = self._drain()
            run.packages += len(packages)
            for st in packages:
                if st["safety_mode"] != SafetyMode.NORMAL:
                    raise _safety_fault(st["safety_mode"], " while finishing")
                if st["runtime_state"] == RuntimeState.STOPPED and max(abs(v) for v in st["actual_qd"]) < STILL_RAD_S:
                    final = st
                    break
                run.last_state = st
            if final is not None:
                break
            if rtde.age_s() > silence_timeout_s:
                raise _Fault("controller_silent", f"no RTDE data package for {rtde.age_s():.3f} s while the program was finishing")
            if now > end_by:
                raise _Fault(
                    "program_did_not_finish",
                    f"the program did not end within stop_timeout_s {stop_timeout_s:g} s after the done command",
                )
        self._collect_messages(run)
        return final

    # ------------------------------------------------------------------ stopping

    def _fail(self, run: _Run, fault: _Fault, monitor: _DashboardMonitor, stop_timeout_s: float,
              silence_timeout_s: float) -> DeployFault:
        """Stop the arm (bounded), then build the DeployFault."""
        monitor.stop(wait_s=0.0)  # a monitor stuck in a dashboard call must not delay the stop
        stopped, how = self._stop_arm(run, stop_timeout_s, silence_timeout_s)
        self._collect_messages(run)
        actual = None
        rtde = self.conn.rtde_client
        if rtde is not None:
            try:
                latest = rtde.latest(allow_stale=True)
                if "actual_q" in latest:
                    actual = tuple(float(v) for v in latest["actual_q"])
            except RTDEError:
                pass
        where = (
            f"while {run.phase}"
            + (f" at setpoint {run.k} of {len(run.plan)} (t = {run.time_s():.3f} s)" if run.k >= 0 else "")
        )
        msgs = run.messages[-3:]
        text = f"deploy stopped [{fault.cause}] {where}: {fault.detail}; {how}"
        if msgs:
            text += "; controller said: " + " | ".join(msgs)
        return DeployFault(
            text,
            sample=run.sample(),
            cause=fault.cause,
            time_s=run.time_s(),
            setpoint_index=run.k,
            stopped=stopped,
            stop_report=how,
            actual_q=actual,
            controller_messages=run.messages,
        )

    def _stop_arm(self, run: _Run, stop_timeout_s: float, silence_timeout_s: float) -> tuple[bool, str]:
        """Stop the program and the arm: the done command over RTDE, else the dashboard ``stop``. Bounded."""
        rtde = self.conn.rtde_client
        deadline = time.monotonic() + stop_timeout_s
        steps: list[str] = []
        rtde_ok = rtde is not None and rtde.connected
        if rtde_ok and run.sent_any:
            q = run.last_q if run.last_q is not None else run.plan.q[0]
            try:
                # no data to trust (silent, or a non-finite value seen): send a burst of done commands (the
                # program still reads its inputs) and confirm over the dashboard
                untrusted = rtde.data_fault is not None
                silent = untrusted or rtde.age_s() > silence_timeout_s
                t_end = min(deadline, time.monotonic() + (0.02 if silent else max(0.3, 3 * silence_timeout_s)))
                confirmed = False
                while time.monotonic() < t_end:
                    self._send(run, q, run.last_opening, done=True)
                    time.sleep(UR3E.control_period_s)
                    if untrusted or rtde.age_s() > silence_timeout_s:
                        continue
                    st = rtde.latest()
                    if st.get("runtime_state") != RuntimeState.PLAYING:
                        confirmed = True
                        break
                steps.append("done command sent over RTDE" + (" (program stopped)" if confirmed else " (no confirmation)"))
                if confirmed:
                    stilled = self._wait_still(deadline)
                    return True, "; ".join(steps) + ("; arm standing still" if stilled else "; arm still decelerating")
            except (_Fault, RTDEError) as exc:
                steps.append(f"done command failed ({exc})")
        # the dashboard: stop whatever runs
        reply = self._dashboard_stop(max(0.2, deadline - time.monotonic()))
        steps.append(reply)
        confirmed = self._confirm_stopped(deadline, silence_timeout_s)
        if confirmed is True:
            stilled = self._wait_still(deadline)
            steps.append("program stopped" + ("; arm standing still" if stilled else ""))
            return True, "; ".join(steps)
        steps.append(
            "could not confirm the stop; the controller's RTDE watchdog stops the program once setpoints stop arriving"
            if confirmed is None else "the program still runs"
        )
        return False, "; ".join(steps)

    def _dashboard_stop(self, timeout_s: float) -> str:
        timeout_s = min(timeout_s, self.conn.timeout_s)
        acquired = self.conn.dash_lock.acquire(timeout=min(0.05, timeout_s))  # busy (monitor stuck)? use a fresh connection
        try:
            dash = self.conn.dashboard_client if acquired and not self.conn.dashboard_broken else None
            fresh = None
            if dash is None:
                fresh = DashboardClient(self.conn.host, self.conn.dashboard_port, timeout_s=max(0.1, timeout_s))
                try:
                    fresh.connect()
                except RTDEError as exc:
                    return f"dashboard stop impossible ({exc})"
                dash = fresh
            try:
                ran = dash.stop()
                return "dashboard stop sent" + ("" if ran else " (no program was running)")
            except RTDEError as exc:
                if dash is self.conn.dashboard_client:
                    self.conn.dashboard_broken = True
                return f"dashboard stop failed ({exc})"
            finally:
                if fresh is not None:
                    fresh.close()
        finally:
            if acquired:
                self.conn.dash_lock.release()

    def _confirm_stopped(self, deadline: float, silence_timeout_s: float) -> bool | None:
        """True once runtime_state is not PLAYING (RTDE, else dashboard ``running``); None if unknown."""
        rtde = self.conn.rtde_client
        while time.monotonic() < deadline:
            if rtde is not None and rtde.connected and rtde.data_fault is None and rtde.age_s() <= silence_timeout_s:
                try:
                    playing = rtde.latest().get("runtime_state") == RuntimeState.PLAYING
                except RTDEError:  # dropped or untrusted meanwhile: ask the dashboard
                    break
                if not playing:
                    return True
                time.sleep(0.005)
                continue
            break
        # RTDE is gone or silent: ask the dashboard
        acquired = self.conn.dash_lock.acquire(timeout=max(0.0, min(0.05, deadline - time.monotonic())))
        if not acquired:
            return None
        try:
            dash = self.conn.dashboard_client if not self.conn.dashboard_broken else None
            if dash is None:
                return None
            while time.monotonic() < deadline:
                try:
                    if not dash.running():
                        return True
                except RTDEError:
                    self.conn.dashboard_broken = True
                    return None
                time.sleep(0.02)
            return False
        finally:
            self.conn.dash_lock.release()

    def _wait_still(self, deadline: float) -> bool:
        rtde = self.conn.rtde_client
        if rtde is None or not rtde.connected:
            return False
        while time.monotonic() < deadline:
            try:
                st = rtde.wait_next(max(0.01, min(0.1, deadline - time.monotonic())))
            except RTDEError:
                return False
            if max(abs(v) for v in st.get("actual_qd", (1.0,))) < STILL_RAD_S:
                return True
        return False
