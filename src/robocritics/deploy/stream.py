"""Deploy a verified trajectory to a UR arm: the gate, then a paced 500 Hz servo stream.

Only the motion the critics judged may move the robot::

    execution = robocritics.simulate(source, scene)
    report = robocritics.critique(execution.trajectory, scene)
    with URArm("192.168.1.10") as arm:
        try:
            result = arm.deploy(execution, report)
        except DeployError as exc:
            if exc.cause != "start_mismatch":
                raise
            approach, approach_report = arm.approach(execution)   # slow joint move to the start
            arm.deploy(approach, approach_report)                  # passes the same gate
            result = arm.deploy(execution, report)
        print(result.summary())

**The gate** (:meth:`URArm.deploy` refuses with :class:`DeployRefused`, a
:class:`~robocritics.errors.DeployError`, before anything is sent that could
move the arm; ``exc.cause`` is the first reason, ``exc.causes`` all of them):

===================  ===========================================================
cause                rule
===================  ===========================================================
``no_report``        a :class:`~robocritics.report.Report` is required
``report_errors``    the report has an Error verdict (names each critic and its
                     message); ``allow_errors=True`` overrides this rule only
``hash_mismatch``    ``report.trajectory_hash != trajectory.content_hash()``:
                     the report judged a different motion
``trajectory``       not 6 joints, or non-finite values
``setpoint_speed``   a 2 ms setpoint step of the resampled stream asks for more
                     than the trajectory's joint speed limits (the controller
                     would protective-stop); not overridable
``robot_mode``       RTDE ``robot_mode`` is not RUNNING (7)
``safety_mode``      RTDE ``safety_mode`` is not NORMAL (1)
``remote_control``   the dashboard says the controller is in local control
``program_running``  ``runtime_state`` is not STOPPED (another program runs)
``start_mismatch``   the first sample is farther than ``start_tolerance_rad``
                     from ``actual_q`` on some joint; the message offers
                     ``arm.approach(...)``
``secondary_         (dry run only) the secondary interface does not accept
interface``          connections
===================  ===========================================================

Offline rules (the first five) are checked before the robot is asked anything;
if one fails, the robot rules are not evaluated.

**Streaming.** The trajectory (physical time axis) is resampled to ``rate_hz``
(500 Hz: one setpoint per 2 ms control cycle; linear interpolation of q and the
gripper opening for sources at >= 125 Hz, monotone cubic (PCHIP) below). The
client holds the first setpoint (sequence counter incrementing every period)
*before* sending :func:`~robocritics.deploy.urscript.streaming_program` (from a
helper thread, so holding never pauses), waits until the program reports
STREAMING with this deploy's random session id, then streams with absolute
deadlines ``t0 + k / rate_hz`` (sleep, then spin the last ``spin_s``; a client
more than 5 periods late shifts its schedule rather than bursting the missed
setpoints, which the controller would see as a jump). After the
last setpoint it holds the final one until the arm settles (or
``settle_timeout_s``), sends the done command and waits for the program to end.

**Faults.** Every data package is checked while streaming; any of these stops
the arm and raises :class:`DeployFault` (a ``DeployError``) with ``cause``,
``sample`` (index of the last *trajectory* sample sent), ``time_s``,
``stopped`` and ``actual_q``:

``protective_stop`` / ``safety_mode`` (safety_mode leaves NORMAL),
``robot_mode``, ``connection_drop`` (RTDE connection failed),
``controller_silent`` (no data package for ``silence_timeout_s``),
``controller_slow`` (data rate below ``min_data_rate_fraction`` of the recipe
frequency over a 0.25 s window), ``program_stalled`` / ``program_stopped`` /
``session`` (program state register, runtime_state, session echo),
``start_rejected`` / ``program_not_started`` (start-up), ``tracking_error``
(``actual_q`` farther than ``max_tracking_error_rad`` from every setpoint sent
in the last ``lookahead_time_s + 20 ms``), ``remote_control`` / ``dashboard``
(a monitor thread polls the dashboard every ``monitor_period_s``),
``program_did_not_finish``, ``interrupted`` (KeyboardInterrupt etc.; re-raised
after the stop).

Stopping: the done command over RTDE (the program ``stopj``'s), confirmed by
``runtime_state``; if RTDE is gone or the program does not stop within
``stop_timeout_s``, the dashboard ``stop``. The controller's own RTDE watchdog
(``watchdog_min_hz``) stops the program as soon as the client stops sending, so
the arm stops even if both channels fail. Every wait has a deadline.
"""

from __future__ import annotations

import collections
import math
import random
import statistics
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from robocritics.errors import DeployError, RTDEError
from robocritics.deploy.dashboard import DASHBOARD_PORT, DashboardClient
from robocritics.deploy.rtde import (
    ROBOT_MODES,
    RTDE_PORT,
    RUNTIME_STATES,
    SAFETY_MODES,
    InputRecipe,
    MessageLevel,
    RTDEClient,
    TextMessage,
)
from robocritics.deploy.urscript import (
    INPUT_FIELDS,
    OUTPUT_FIELDS,
    SECONDARY_PORT,
    ProgramState,
    send_program,
    setpoint,
    streaming_program,
)

__all__ = [
    "URArm",
    "DeployResult",
    "DeployRefused",
    "DeployFault",
    "Approach",
    "StreamPlan",
    "resample",
    "STATE_FIELDS",
]

STATE_FIELDS: tuple[str, ...] = (
    "timestamp",
    "actual_q",
    "actual_qd",
    "target_q",
    "robot_mode",
    "safety_mode",
    "runtime_state",
    *OUTPUT_FIELDS,
)
"""The output recipe :class:`URArm` sets up (at 500 Hz)."""

CONTROL_PERIOD_S = 0.002
"""e-series control period; one sequence step of the streaming program is 2 ms of trajectory [s]."""

ROBOT_MODE_RUNNING = 7
SAFETY_NORMAL = 1
SAFETY_PROTECTIVE_STOP = 3
RUNTIME_STOPPED = 1
RUNTIME_PLAYING = 2
UR3E_VELOCITY_LIMITS = (math.pi, math.pi, math.pi, 2 * math.pi, 2 * math.pi, 2 * math.pi)
"""Joint speed limits used when a trajectory carries none [rad/s]."""
STILL_RAD_S = 1e-3
"""Joint speeds below this count as standing still [rad/s]."""

_PROGRAM_STATES = {s.value: s.name for s in ProgramState}


def _name(table: dict[int, str], value: Any) -> str:
    return f"{table.get(int(value), 'UNKNOWN')} ({int(value)})" if value is not None else "unknown"


# ---------------------------------------------------------------------------- errors and results


class DeployRefused(DeployError):
    """The gate refused to deploy; nothing that moves the arm was sent.

    ``cause`` is the first reason (see the module docstring), ``causes`` all of them,
    ``reasons`` the ``(cause, explanation)`` pairs.
    """

    def __init__(self, reasons: Sequence[tuple[str, str]]):
        self.reasons = tuple(reasons)
        self.causes = tuple(c for c, _ in self.reasons)
        lines = "\n".join(f"  - [{c}] {text}" for c, text in self.reasons)
        n = len(self.reasons)
        super().__init__(f"deploy refused ({n} reason{'s' if n != 1 else ''}); nothing was sent to the robot:\n{lines}",
                         sample=-1, cause=self.causes[0] if self.causes else "refused")


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


@dataclass(frozen=True)
class Approach:
    """A slow joint move from the arm's actual position to a trajectory's start.

    Execution-like (``trajectory``, ``robot``, ``scene``): deploy it with its own report.
    """

    trajectory: Any
    robot: Any
    scene: Any
    start_q: tuple[float, ...]
    """Where the arm was [rad]."""
    goal_q: tuple[float, ...]
    """The first sample of the trajectory to approach [rad]."""
    speed_fraction: float

    @property
    def duration_s(self) -> float:
        return float(self.trajectory.duration_s)


# ---------------------------------------------------------------------------- resampling


def resample(trajectory: Any, rate_hz: float = 500.0) -> StreamPlan:
    """Resample ``trajectory`` (physical time axis) to ``rate_hz`` setpoints.

    Setpoint k is at ``k / rate_hz`` s from the first sample; the last setpoint is
    the last sample exactly (added if the duration is not a multiple of the
    period). q and the gripper opening are interpolated linearly when the source
    has samples at least every 8 ms (125 Hz), else with a monotone cubic (PCHIP),
    which never overshoots between samples.
    """
    q_src = np.asarray(trajectory.q, dtype=float)
    t_src = np.asarray(trajectory.time, dtype=float)
    g_src = np.asarray(trajectory.gripper_opening_m, dtype=float)
    if q_src.ndim != 2 or len(t_src) != q_src.shape[0] or len(t_src) == 0:
        raise DeployError(f"trajectory arrays disagree: q {q_src.shape}, time {t_src.shape}")
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
        from scipy.interpolate import PchipInterpolator

        q = PchipInterpolator(t, q_src, axis=0)(ts)
        g = np.clip(PchipInterpolator(t, g_src)(ts), g_src.min(), g_src.max())
        how = "pchip"
    q[-1] = q_src[-1]
    g[-1] = g_src[-1]
    src = np.searchsorted(t, ts + 1e-9, side="right") - 1
    return StreamPlan(q=q, gripper_opening_m=g, time=ts, source_index=src.astype(np.int64), rate_hz=float(rate_hz), interpolation=how)


def _trajectory_of(execution: Any) -> Any:
    traj = getattr(execution, "trajectory", execution)
    if not (hasattr(traj, "q") and hasattr(traj, "time") and hasattr(traj, "content_hash")):
        raise DeployError(
            f"deploy needs an Execution (from robocritics.simulate), an Approach or a Trajectory, got {type(execution).__name__}"
        )
    return traj


def _percentile(values: Sequence[float], p: float) -> float:
    return float(np.percentile(np.asarray(values, dtype=float), p)) if len(values) else float("nan")


# ---------------------------------------------------------------------------- internal fault signal


class _Fault(Exception):
    def __init__(self, cause: str, detail: str):
        self.cause = cause
        self.detail = detail
        super().__init__(detail)


def _safety_fault(safety_mode: Any, when: str = "") -> _Fault:
    """The fault for a safety mode other than NORMAL; ``when`` ends the message."""
    cause = "protective_stop" if safety_mode == SAFETY_PROTECTIVE_STOP else "safety_mode"
    return _Fault(cause, f"the controller's safety mode became {_name(SAFETY_MODES, safety_mode)}{when}")


class _DashboardMonitor:
    """Polls ``is in remote control`` while a deployment runs (its own thread)."""

    def __init__(self, arm: "URArm", period_s: float) -> None:
        self.arm = arm
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
            self._thread.join(timeout=self.arm.timeout_s + 0.5 if wait_s is None else wait_s)

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            try:
                with self.arm._dash_lock:
                    dash = self.arm._dashboard
                    if dash is None:
                        raise RTDEError("the dashboard connection is closed")
                    remote = dash.is_in_remote_control()
            except RTDEError as exc:
                self.arm._dashboard_broken = True
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
    rate_t0: float = 0.0
    rate_n0: int = 0

    def sample(self) -> int:
        if not self.sent_any:
            return -1
        return int(self.plan.source_index[max(self.k, 0)])

    def time_s(self) -> float:
        return float(self.plan.time[max(self.k, 0)]) if self.sent_any else 0.0


# ---------------------------------------------------------------------------- the arm


class URArm:
    """A UR arm reached over RTDE (30004), the Dashboard Server (29999) and the secondary interface (30002).

    ``with URArm(host) as arm:`` connects RTDE (output recipe :data:`STATE_FIELDS`
    at 500 Hz, input recipe :data:`~robocritics.deploy.urscript.INPUT_FIELDS`,
    synchronisation started) and the dashboard; leaving the block closes both.
    ``timeout_s`` bounds connecting and every request/reply [s]. Connection
    problems raise :class:`~robocritics.errors.RTDEError` (a DeployError).
    """

    def __init__(
        self,
        host: str,
        *,
        rtde_port: int = RTDE_PORT,
        dashboard_port: int = DASHBOARD_PORT,
        secondary_port: int = SECONDARY_PORT,
        timeout_s: float = 2.0,
        frequency_hz: float = 500.0,
    ) -> None:
        if not timeout_s > 0:
            raise DeployError(f"timeout_s must be > 0 s, got {timeout_s}")
        self.host = host
        self.rtde_port = int(rtde_port)
        self.dashboard_port = int(dashboard_port)
        self.secondary_port = int(secondary_port)
        self.timeout_s = float(timeout_s)
        self.frequency_hz = float(frequency_hz)
        self._rtde: RTDEClient | None = None
        self._dashboard: DashboardClient | None = None
        self._dashboard_broken = False
        self._dash_lock = threading.Lock()
        self._inputs: InputRecipe | None = None
        self._seq = 0
        self._out_freq = self.frequency_hz
        self._messages: collections.deque[TextMessage] = collections.deque(maxlen=256)

    # ------------------------------------------------------------------ connection

    def __enter__(self) -> "URArm":
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def connect(self) -> None:
        """Connect RTDE and the dashboard, set up the recipes, start synchronisation, read one package.

        After a dropped connection (``DeployFault.cause == "connection_drop"``) call it again to reconnect.
        """
        if self._rtde is not None:
            if self._rtde.connected:
                raise DeployError(f"URArm {self.host} is already connected")
            self.close()
        rtde = RTDEClient(self.host, self.rtde_port, timeout_s=self.timeout_s, buffer_size=4096)
        rtde.connect()
        try:
            recipe = rtde.setup_outputs(list(STATE_FIELDS), self.frequency_hz)
            self._out_freq = recipe.frequency_hz
            self._inputs = rtde.setup_inputs(list(INPUT_FIELDS))
            rtde.start()
            rtde.wait_next(self.timeout_s)
        except BaseException:
            rtde.close()
            raise
        dash = DashboardClient(self.host, self.dashboard_port, timeout_s=self.timeout_s)
        try:
            dash.connect()
        except BaseException:
            rtde.close()
            raise
        self._rtde = rtde
        self._dashboard = dash
        self._dashboard_broken = False

    def close(self) -> None:
        """Close both connections (bounded)."""
        rtde, self._rtde = self._rtde, None
        with self._dash_lock:
            dash, self._dashboard = self._dashboard, None
        if rtde is not None:
            rtde.close()
        if dash is not None:
            dash.close()

    @property
    def rtde(self) -> RTDEClient:
        """The RTDE client (raises if not connected)."""
        if self._rtde is None:
            raise DeployError(f"URArm {self.host} is not connected; use 'with URArm(...) as arm:' or connect()")
        return self._rtde

    @property
    def dashboard(self) -> DashboardClient:
        """The dashboard client, e.g. to power on: ``arm.dashboard.power_on()``."""
        if self._dashboard is None:
            raise DeployError(f"URArm {self.host} is not connected; use 'with URArm(...) as arm:' or connect()")
        return self._dashboard

    def _healthy_dashboard(self) -> DashboardClient:
        """The dashboard client, reconnected if an earlier exchange failed (caller holds ``_dash_lock``)."""
        dash = self.dashboard
        if self._dashboard_broken:
            dash.close()
            dash = DashboardClient(self.host, self.dashboard_port, timeout_s=self.timeout_s)
            dash.connect()
            self._dashboard = dash
            self._dashboard_broken = False
        return dash

    def state(self) -> dict[str, Any]:
        """The next RTDE data package (fresh, waits at most ``timeout_s``)."""
        return self.rtde.wait_next(self.timeout_s)

    def actual_q(self) -> np.ndarray:
        """Actual joint positions [rad] from a fresh data package."""
        return np.asarray(self.state()["actual_q"], dtype=float)

    # ------------------------------------------------------------------ approach

    def approach(self, execution: Any, speed_fraction: float = 0.1, sample_rate_hz: float | None = None):
        """A slow joint move from ``actual_q`` to the first sample of ``execution``, and its critics' report.

        Timed with :func:`~robocritics.robot.motion.time_joint_move` at
        ``speed_fraction`` of the robot's limits, built with
        ``execution.robot.trajectory(...)`` in ``execution.scene`` (the scene at
        the program's start) and judged by :func:`robocritics.critique`. Returns
        ``(Approach, Report)``; deploy it like any execution — it passes the same
        gate (a report with Errors is refused).
        """
        from robocritics.critic import critique
        from robocritics.robot.motion import Limits, time_joint_move

        robot = getattr(execution, "robot", None)
        scene = getattr(execution, "scene", None)
        if robot is None or scene is None:
            raise DeployError("approach() needs an Execution with .robot and .scene (from robocritics.simulate)")
        traj = _trajectory_of(execution)
        if len(traj.attached) and str(traj.attached[0]):
            raise DeployError(
                f"approach(): the trajectory starts holding {traj.attached[0]!r}; plan the approach in the program instead"
            )
        goal = np.asarray(traj.q[0], dtype=float)
        start = self.actual_q()
        if start.shape != goal.shape:
            raise DeployError(f"approach(): the arm has {start.size} joints, the trajectory {goal.size}")
        if sample_rate_hz is None:
            dts = np.diff(np.asarray(traj.time, float))
            sample_rate_hz = float(1.0 / np.median(dts)) if len(dts) else 125.0
        limits = Limits(
            np.asarray(robot.velocity_limits, float),
            np.asarray(robot.acceleration_limits, float),
            np.asarray(robot.jerk_limits, float),
        )
        seg = time_joint_move(start, goal, limits, speed_fraction, sample_rate_hz)
        dt = 1.0 / sample_rate_hz
        end_t = max(seg.duration_s, float(seg.time[-1]) + (dt if seg.duration_s == 0 else 1e-6))
        if seg.duration_s - float(seg.time[-1]) < 1e-6 and seg.duration_s > 0:
            q = np.vstack([seg.q[:-1], goal])
            t = np.append(seg.time[:-1], seg.duration_s)
        else:
            q = np.vstack([seg.q, goal])
            t = np.append(seg.time, end_t)
        opening = float(traj.gripper_opening_m[0])
        trajectory = robot.trajectory(q, t, scene, gripper_opening_m=np.full(len(t), opening))
        report = critique(trajectory, scene)
        app = Approach(
            trajectory=trajectory,
            robot=robot,
            scene=scene,
            start_q=tuple(float(v) for v in start),
            goal_q=tuple(float(v) for v in goal),
            speed_fraction=float(speed_fraction),
        )
        return app, report

    # ------------------------------------------------------------------ the gate

    def _offline_gate(self, traj: Any, report: Any, allow_errors: bool, plan: StreamPlan | None) -> list[tuple[str, str]]:
        reasons: list[tuple[str, str]] = []
        if report is None or not hasattr(report, "trajectory_hash"):
            reasons.append(("no_report", "deploy needs the Report that robocritics.critique() made for this trajectory"))
        else:
            errors = list(getattr(report, "errors", []))
            if errors and allow_errors is not True:
                listed = "; ".join(f"{v.critic}: {v.message}" for v in errors)
                reasons.append((
                    "report_errors",
                    f"the critics' report has {len(errors)} Error(s) — {listed} — fix the program, or pass "
                    "allow_errors=True to deploy anyway",
                ))
            actual_hash = traj.content_hash()
            if report.trajectory_hash != actual_hash:
                reasons.append((
                    "hash_mismatch",
                    f"the report judged trajectory {str(report.trajectory_hash)[:12]}… but this trajectory is "
                    f"{actual_hash[:12]}…; critique exactly the motion you deploy",
                ))
        q = np.asarray(traj.q, dtype=float)
        if q.ndim != 2 or q.shape[1] != 6:
            reasons.append(("trajectory", f"a UR arm needs 6 joint values per sample, the trajectory has shape {q.shape}"))
        elif not (np.all(np.isfinite(q)) and np.all(np.isfinite(np.asarray(traj.time, float)))):
            reasons.append(("trajectory", "the trajectory has non-finite joint values or times"))
        elif plan is not None and len(plan) > 1:
            limits = getattr(traj, "limits", None)
            vlim = np.asarray(getattr(limits, "velocity_rad_s", UR3E_VELOCITY_LIMITS), dtype=float)
            speed = np.abs(np.diff(plan.q, axis=0)) * plan.rate_hz
            ratio = speed / vlim
            worst = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
            if ratio[worst] > 1.0 + 1e-6:
                k, j = int(worst[0]) + 1, int(worst[1])
                reasons.append((
                    "setpoint_speed",
                    f"setpoint {k} (trajectory sample {int(plan.source_index[k])}, t = {plan.time[k]:.3f} s) moves joint "
                    f"{j} ({getattr(limits, 'joint_names', [''] * 6)[j]}) at "
                    f"{speed[worst]:.3f} rad/s > its limit {vlim[j]:.3f} rad/s; the controller would protective-stop",
                ))
        return reasons

    def _online_gate(self, state: dict[str, Any], q_first: np.ndarray, start_tolerance_rad: float) -> list[tuple[str, str]]:
        reasons: list[tuple[str, str]] = []
        rm, sm, rs = state.get("robot_mode"), state.get("safety_mode"), state.get("runtime_state")
        if rm != ROBOT_MODE_RUNNING:
            reasons.append((
                "robot_mode",
                f"robot mode is {_name(ROBOT_MODES, rm)}, not RUNNING (7); power on and release the brakes "
                "(arm.dashboard.power_on(), arm.dashboard.brake_release())",
            ))
        if sm != SAFETY_NORMAL:
            hint = "; inspect the cause, then arm.dashboard.unlock_protective_stop()" if sm == SAFETY_PROTECTIVE_STOP else ""
            reasons.append(("safety_mode", f"safety mode is {_name(SAFETY_MODES, sm)}, not NORMAL (1){hint}"))
        with self._dash_lock:
            try:
                remote = self._healthy_dashboard().is_in_remote_control()
            except RTDEError as exc:
                remote = None
                reasons.append(("remote_control", f"cannot ask the dashboard whether the robot is in remote control: {exc}"))
        if remote is False:
            reasons.append((
                "remote_control",
                "the controller is in local control; it would ignore the streaming program — enable remote control on the teach pendant",
            ))
        if rs != RUNTIME_STOPPED:
            reasons.append((
                "program_running",
                f"runtime state is {_name(RUNTIME_STATES, rs)}, not STOPPED: another program is running; stop it first",
            ))
        actual = np.asarray(state.get("actual_q", ()), dtype=float)
        if actual.shape != (6,):
            reasons.append(("start_mismatch", f"the controller reported actual_q {actual.tolist()}, not 6 joint positions"))
        else:
            dev = np.abs(q_first - actual)
            j = int(np.argmax(dev))
            if dev[j] > start_tolerance_rad:
                reasons.append((
                    "start_mismatch",
                    f"the trajectory starts {dev[j]:.4f} rad away from the arm on joint {j} (> start_tolerance_rad "
                    f"{start_tolerance_rad:g}); actual_q = [{', '.join(f'{v:.4f}' for v in actual)}], first sample = "
                    f"[{', '.join(f'{v:.4f}' for v in q_first)}]. Move there first: "
                    "approach, approach_report = arm.approach(execution); arm.deploy(approach, approach_report)",
                ))
        return reasons

    # ------------------------------------------------------------------ deploy

    def deploy(
        self,
        execution: Any,
        report: Any,
        *,
        allow_errors: bool = False,
        dry_run: bool = False,
        start_tolerance_rad: float = 0.01,
        max_tracking_error_rad: float = 0.05,
        rate_hz: float = 500.0,
        lookahead_time_s: float = 0.1,
        gain: float = 300.0,
        watchdog_min_hz: float = 10.0,
        silence_timeout_s: float = 0.2,
        min_data_rate_fraction: float = 0.5,
        start_timeout_s: float = 3.0,
        settle_tolerance_rad: float = 1e-4,
        settle_timeout_s: float = 1.0,
        stop_timeout_s: float = 2.0,
        monitor_period_s: float = 0.1,
        spin_s: float = 2e-4,
    ) -> DeployResult:
        """Check ``execution`` against ``report`` and the arm (the gate), then stream it.

        ``execution``: an :class:`~robocritics.simulate.Execution`, an
        :class:`Approach` or a Trajectory; ``report``: the
        :class:`~robocritics.report.Report` of exactly that trajectory.
        ``allow_errors`` must be passed explicitly to deploy a report with Errors.
        ``dry_run`` does the gate, the connection checks, the resampling, the
        program text and the pacing schedule, and checks that the secondary
        interface accepts connections, but sends no program and no setpoint.
        ``rate_hz`` must divide 500 (500, 250, 125, …): each setpoint advances the
        sequence counter by ``500 / rate_hz`` control cycles.
        The other parameters are the thresholds in the module docstring.

        Raises :class:`DeployRefused` (gate, nothing sent) or :class:`DeployFault`
        (a fault stopped the arm). Returns a :class:`DeployResult`.
        """
        traj = _trajectory_of(execution)
        steps = 500.0 / float(rate_hz)
        if not (rate_hz > 0 and abs(steps - round(steps)) < 1e-9 and round(steps) >= 1):
            raise DeployError(f"rate_hz must divide 500 Hz (500, 250, 125, 100, …), got {rate_hz}")
        if not (0 < start_tolerance_rad <= 0.5):
            raise DeployError(f"start_tolerance_rad must be in (0, 0.5] rad, got {start_tolerance_rad}")
        if not max_tracking_error_rad > 0:
            raise DeployError(f"max_tracking_error_rad must be > 0 rad, got {max_tracking_error_rad}")
        rtde = self.rtde
        plan: StreamPlan | None = None
        try:
            plan = resample(traj, rate_hz)
        except (DeployError, ValueError) as exc:
            raise DeployRefused([("trajectory", f"cannot resample the trajectory: {exc}")]) from None
        reasons = self._offline_gate(traj, report, allow_errors, plan)
        if reasons:
            raise DeployRefused(reasons)
        state = rtde.wait_next(self.timeout_s)
        reasons = self._online_gate(state, plan.q[0], start_tolerance_rad)
        if reasons:
            raise DeployRefused(reasons)
        program = streaming_program(
            lookahead_time_s=lookahead_time_s,
            gain=gain,
            watchdog_min_hz=watchdog_min_hz,
            max_start_deviation_rad=min(0.5, start_tolerance_rad + 0.005),
        )
        trajectory_hash = traj.content_hash()
        if dry_run:
            self._probe_secondary()
            final_q = tuple(float(v) for v in state["actual_q"])
            return DeployResult(
                samples_sent=0,
                trajectory_samples=len(traj.q),
                rate_hz=float(rate_hz),
                duration_s=0.0,
                trajectory_duration_s=float(plan.time[-1]),
                period_error_median_ms=float("nan"),
                period_error_p99_ms=float("nan"),
                period_error_max_ms=float("nan"),
                lateness_p99_ms=float("nan"),
                max_tracking_error_rad=0.0,
                final_q=final_q,
                final_error_rad=float(np.max(np.abs(np.asarray(final_q) - plan.q[-1]))),
                settle_s=0.0,
                resyncs=0,
                data_packages=1,
                trajectory_hash=trajectory_hash,
                session=0,
                dry_run=True,
                program=program,
                planned_setpoints=len(plan),
            )
        window_s = lookahead_time_s + 0.02
        run = _Run(
            plan=plan,
            session=random.randint(1, 2**31 - 1),
            step=int(round(steps)),
            max_tracking_error_rad=float(max_tracking_error_rad),
            window=max(1, int(math.ceil(window_s * rate_hz))),
        )
        return self._stream(
            run,
            program,
            trajectory_hash=trajectory_hash,
            trajectory_samples=len(traj.q),
            silence_timeout_s=silence_timeout_s,
            min_data_rate_fraction=min_data_rate_fraction,
            start_timeout_s=start_timeout_s,
            settle_tolerance_rad=settle_tolerance_rad,
            settle_timeout_s=settle_timeout_s,
            stop_timeout_s=stop_timeout_s,
            monitor_period_s=monitor_period_s,
            spin_s=spin_s,
        )

    def _probe_secondary(self) -> None:
        import socket

        try:
            with socket.create_connection((self.host, self.secondary_port), timeout=self.timeout_s):
                pass
        except OSError as exc:
            raise DeployRefused([(
                "secondary_interface",
                f"cannot connect to the secondary interface at {self.host}:{self.secondary_port}: {exc}",
            )]) from None

    # ------------------------------------------------------------------ streaming

    def _send(self, run: _Run, q: np.ndarray, opening: float, *, done: bool = False, bump: bool = True) -> None:
        if bump:
            self._seq = ((self._seq + run.step + 2**31) % 2**32) - 2**31
        try:
            self.rtde.send(setpoint(self._seq, q, opening, done=done, session=run.session), self._inputs)
        except RTDEError as exc:
            raise _Fault("connection_drop", f"the RTDE connection failed: {exc}") from None
        run.sent_any = True
        run.last_q = q
        run.last_opening = opening

    def _collect_messages(self, run: _Run) -> None:
        rtde = self._rtde
        if rtde is None:
            return
        for m in rtde.messages():
            self._messages.append(m)
            if m.level <= MessageLevel.WARNING:
                run.messages.append(f"{m.level_name} [{m.source}] {m.message}")

    def _check(self, run: _Run, monitor: _DashboardMonitor | None, now: float, rate_hz: float,
               silence_timeout_s: float, min_rate: float) -> None:
        """Raise _Fault if anything is wrong; process every data package received since the last check."""
        rtde = self.rtde
        if monitor is not None and monitor.fault is not None:
            raise monitor.fault
        if not rtde.connected:
            try:
                rtde.latest()
            except RTDEError as exc:
                raise _Fault("connection_drop", f"the RTDE connection failed: {exc}") from None
            raise _Fault("connection_drop", "the RTDE connection is closed")
        packages = rtde.drain()
        for st in packages:
            run.packages += 1
            run.last_state = st
            if st["safety_mode"] != SAFETY_NORMAL:
                raise _safety_fault(st["safety_mode"])
            if st["robot_mode"] != ROBOT_MODE_RUNNING:
                raise _Fault("robot_mode", f"the robot mode became {_name(ROBOT_MODES, st['robot_mode'])}")
            if run.phase in ("streaming", "settling"):
                pstate = st[OUTPUT_FIELDS[1]]
                if pstate == ProgramState.STALLED:
                    raise _Fault("program_stalled", "the streaming program reported STALLED (it saw the sequence counter stop) and stopped")
                if st[OUTPUT_FIELDS[2]] != run.session:
                    raise _Fault("session", f"the program echoes session {st[OUTPUT_FIELDS[2]]}, not ours ({run.session}); another program took over")
                if st["runtime_state"] != RUNTIME_PLAYING:
                    raise _Fault(
                        "program_stopped",
                        f"the program stopped: runtime state {_name(RUNTIME_STATES, st['runtime_state'])}, program state "
                        f"{_name(_PROGRAM_STATES, pstate)} (controller watchdog, a dashboard stop, or a crash)",
                    )
                if pstate != ProgramState.STREAMING:
                    raise _Fault("program_stopped", f"the program left the STREAMING state: {_name(_PROGRAM_STATES, pstate)}")
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
            if err > run.max_tracking_error_rad:
                raise _Fault(
                    "tracking_error",
                    f"tracking error {err:.4f} rad > max_tracking_error_rad {run.max_tracking_error_rad:g}: actual_q is "
                    f"that far from every setpoint sent in the last {run.window} cycles",
                )
        age = rtde.age_s()
        if age > silence_timeout_s:
            raise _Fault("controller_silent", f"no RTDE data package for {age:.3f} s (> silence_timeout_s {silence_timeout_s:g})")
        elapsed = now - run.rate_t0
        if elapsed >= 0.25:
            n = rtde.packages_received - run.rate_n0
            expected = self._out_freq * elapsed
            if n < min_rate * expected:
                raise _Fault(
                    "controller_slow",
                    f"the controller sent {n} data packages in {elapsed:.3f} s ({n / elapsed:.0f} Hz, expected "
                    f"{self._out_freq:g} Hz; minimum {min_rate:.0%}): it is overloaded or throttled",
                )
            run.rate_t0, run.rate_n0 = now, rtde.packages_received

    def _stream(
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
        rtde = self.rtde
        plan = run.plan
        period = 1.0 / plan.rate_hz
        rate = plan.rate_hz
        rtde.drain()
        self._collect_messages(run)
        run.messages.clear()
        monitor = _DashboardMonitor(self, monitor_period_s)
        monitor.start()
        sent_times: list[float] = []
        deadlines: list[float] = []
        settle_s = 0.0
        resyncs = 0
        resync_after_s = 5 * period

        def check(now: float) -> None:
            self._check(run, monitor, now, rate, silence_timeout_s, min_data_rate_fraction)

        try:
            # ---- hold the first setpoint, send the program, wait until it streams with our session
            q0, g0 = plan.q[0], float(plan.gripper_opening_m[0])
            run.rate_t0, run.rate_n0 = time.perf_counter(), rtde.packages_received
            state_before = rtde.latest().get(OUTPUT_FIELDS[1])
            self._send(run, q0, g0)
            sender_error: list[BaseException] = []

            def send_it() -> None:
                try:
                    send_program(self.host, program, self.secondary_port, timeout_s=self.timeout_s)
                except BaseException as exc:  # reported by the streaming thread
                    sender_error.append(exc)

            sender = threading.Thread(target=send_it, name="urarm-send-program", daemon=True)
            sender.start()
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
                if sender_error:
                    raise _Fault("program_not_started", f"sending the program failed: {sender_error[0]}")
                st = run.last_state
                if st:
                    pstate = st[OUTPUT_FIELDS[1]]
                    if (
                        st["runtime_state"] == RUNTIME_PLAYING
                        and pstate == ProgramState.STREAMING
                        and st[OUTPUT_FIELDS[2]] == run.session
                    ):
                        break
                    if pstate == ProgramState.START_REJECTED and state_before != ProgramState.START_REJECTED:
                        raise _Fault("start_rejected", "the program refused to start: the first setpoint is too far from the actual joint positions")
                if not sender.is_alive() and run.messages and any(m.startswith(("ERROR", "EXCEPTION")) for m in run.messages):
                    raise _Fault("program_not_started", "the controller reported an error after the program was sent")
                if now > give_up:
                    raise _Fault(
                        "program_not_started",
                        f"the program did not report STREAMING with session {run.session} within start_timeout_s "
                        f"{start_timeout_s:g} s (last state {st.get(OUTPUT_FIELDS[1]) if st else None}, runtime "
                        f"{st.get('runtime_state') if st else None})",
                    )
            sender.join(timeout=self.timeout_s)

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
                packages = rtde.drain()
                run.packages += len(packages)
                for st in packages:
                    if st["safety_mode"] != SAFETY_NORMAL:
                        raise _safety_fault(st["safety_mode"], " while finishing")
                    if st["runtime_state"] == RUNTIME_STOPPED and max(abs(v) for v in st["actual_qd"]) < STILL_RAD_S:
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
        except _Fault as fault:
            raise self._fail(run, fault, monitor, stop_timeout_s, silence_timeout_s) from None
        except BaseException as exc:
            # KeyboardInterrupt, a bug: stop the arm before anything else happens
            self._fail(run, _Fault("interrupted", f"{type(exc).__name__}: {exc}"), monitor, stop_timeout_s, silence_timeout_s)
            raise
        finally:
            monitor.stop(wait_s=0.1)

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

    # ------------------------------------------------------------------ stopping

    def _fail(self, run: _Run, fault: _Fault, monitor: _DashboardMonitor, stop_timeout_s: float,
              silence_timeout_s: float) -> DeployFault:
        """Stop the arm (bounded), then build the DeployFault."""
        monitor.stop(wait_s=0.0)  # a monitor stuck in a dashboard call must not delay the stop
        stopped, how = self._stop_arm(run, stop_timeout_s, silence_timeout_s)
        self._collect_messages(run)
        actual = None
        rtde = self._rtde
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
        rtde = self._rtde
        deadline = time.monotonic() + stop_timeout_s
        steps: list[str] = []
        rtde_ok = rtde is not None and rtde.connected
        if rtde_ok and run.sent_any:
            q = run.last_q if run.last_q is not None else run.plan.q[0]
            try:
                silent = rtde.age_s() > silence_timeout_s
                # silent: send a burst of done commands (the program still reads its inputs) and go on
                t_end = min(deadline, time.monotonic() + (0.02 if silent else max(0.3, 3 * silence_timeout_s)))
                confirmed = False
                while time.monotonic() < t_end:
                    self._send(run, q, run.last_opening, done=True)
                    time.sleep(0.002)
                    if rtde.age_s() > silence_timeout_s:
                        continue
                    st = rtde.latest()
                    if st.get("runtime_state") != RUNTIME_PLAYING:
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
        timeout_s = min(timeout_s, self.timeout_s)
        acquired = self._dash_lock.acquire(timeout=min(0.05, timeout_s))  # busy (monitor stuck)? use a fresh connection
        try:
            dash = self._dashboard if acquired and not self._dashboard_broken else None
            fresh = None
            if dash is None:
                fresh = DashboardClient(self.host, self.dashboard_port, timeout_s=max(0.1, timeout_s))
                try:
                    fresh.connect()
                except RTDEError as exc:
                    return f"dashboard stop impossible ({exc})"
                dash = fresh
            try:
                ran = dash.stop()
                return "dashboard stop sent" + ("" if ran else " (no program was running)")
            except RTDEError as exc:
                if dash is self._dashboard:
                    self._dashboard_broken = True
                return f"dashboard stop failed ({exc})"
            finally:
                if fresh is not None:
                    fresh.close()
        finally:
            if acquired:
                self._dash_lock.release()

    def _confirm_stopped(self, deadline: float, silence_timeout_s: float) -> bool | None:
        """True once runtime_state is not PLAYING (RTDE, else dashboard ``running``); None if unknown."""
        rtde = self._rtde
        while time.monotonic() < deadline:
            if rtde is not None and rtde.connected and rtde.age_s() <= silence_timeout_s:
                if rtde.latest().get("runtime_state") != RUNTIME_PLAYING:
                    return True
                time.sleep(0.005)
                continue
            break
        # RTDE is gone or silent: ask the dashboard
        acquired = self._dash_lock.acquire(timeout=max(0.0, min(0.05, deadline - time.monotonic())))
        if not acquired:
            return None
        try:
            dash = self._dashboard if not self._dashboard_broken else None
            if dash is None:
                return None
            while time.monotonic() < deadline:
                try:
                    if not dash.running():
                        return True
                except RTDEError:
                    self._dashboard_broken = True
                    return None
                time.sleep(0.02)
            return False
        finally:
            self._dash_lock.release()

    def _wait_still(self, deadline: float) -> bool:
        rtde = self._rtde
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
