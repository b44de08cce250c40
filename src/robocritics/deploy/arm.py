"""A UR arm to deploy to: the connections, the gate, the stream — and an approach to a trajectory's start.

Only the motion the critics judged may move the robot. Plan it from where the arm
is (this is what ``robocritics deploy PROGRAM --host HOST`` does)::

    with URArm("192.168.1.10") as arm:
        execution = robocritics.simulate(source, scene, start_q=arm.actual_q())
        report = robocritics.critique(execution.trajectory, scene)
        result = arm.deploy(execution, report)      # the gate, then the 500 Hz servo stream
        print(result.summary())

or move the arm to the start of an existing trajectory first, with a slow joint
move that is critiqued and gated like any motion::

    approach = arm.approach(execution)              # a Trajectory from actual_q to the start
    arm.deploy(approach, robocritics.critique(approach, execution.scene))
    arm.deploy(execution, report)

:meth:`URArm.deploy` refuses with :class:`~robocritics.deploy.gate.DeployRefused`
before anything that could move the arm is sent (the rules:
:mod:`robocritics.deploy.gate`) and stops the arm with a
:class:`~robocritics.deploy.stream.DeployFault` when something goes wrong while
streaming (:mod:`robocritics.deploy.stream`).
"""

from __future__ import annotations

import math
import random
import socket
import threading
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from robocritics.deploy.connection import URConnection
from robocritics.deploy.dashboard import DASHBOARD_PORT, DashboardClient
from robocritics.deploy.gate import (
    DeployRefused,
    check_model,
    check_report,
    check_robot,
    check_trajectory,
    trajectory_of,
)
from robocritics._text import safe_text
from robocritics.deploy.rtde import RTDE_PORT, Recipe, RTDEClient, RTDEValueError
from robocritics.deploy.stream import (
    STATE_FIELDS,
    DeployProgress,
    DeployResult,
    StreamPlan,
    _Run,
    _Stream,
    resample,
    rtde_type,
)
from robocritics.deploy.urscript import INPUT_FIELDS, SECONDARY_PORT, streaming_program
from robocritics.errors import DeployError, RTDEError
from robocritics.robot.arms import UR3E
from robocritics.execution import Execution
from robocritics.trajectory import Trajectory

if TYPE_CHECKING:  # pragma: no cover
    from robocritics.robot.model import Robot
    from robocritics.scene import Scene

__all__ = ["URArm", "approach_trajectory"]

CONTROL_RATE_HZ = UR3E.control_rate_hz
"""Control cycles per second of an e-series controller [Hz]; the stream rate must divide it."""


def approach_trajectory(
    robot: Robot,
    scene: Scene,
    start_q,
    goal: Trajectory,
    *,
    speed_fraction: float = 0.1,
) -> Trajectory:
    """A slow joint move from ``start_q`` [rad] to the first sample of ``goal``, as a Trajectory.

    Planned by :func:`robocritics.planning.planner.plan_approach` at ``speed_fraction``
    of the robot's limits and sampled at ``goal``'s rate, with ``goal``'s first
    gripper opening, in ``scene`` (where the objects are when ``goal`` starts).
    Critique it (``robocritics.critique(approach, scene)``) and deploy it with that
    report: it passes the same gate as any motion. Raises :class:`DeployError` if
    ``goal`` starts holding an object (plan that approach in the program instead).
    """
    from robocritics.planning.planner import plan_approach

    if not isinstance(goal, Trajectory):
        raise DeployError(f"approach_trajectory(): goal must be a robocritics.Trajectory, got {type(goal).__name__}")
    held = str(goal.attached[0]) if len(goal.attached) else ""
    if held:
        raise DeployError(f"approach: the trajectory starts holding {held!r}; plan the approach in the program instead")
    dts = np.diff(goal.time)
    sample_rate_hz = float(1.0 / np.median(dts)) if len(dts) else 125.0
    q, t = plan_approach(robot, start_q, goal.q[0], speed_fraction=speed_fraction, sample_rate_hz=sample_rate_hz)
    opening = np.full(len(t), float(goal.gripper_opening_m[0]))
    return robot.trajectory(q, t, scene, gripper_opening_m=opening)


class URArm:
    """A UR arm reached over RTDE (30004), the Dashboard Server (29999) and the secondary interface (30002).

    ``with URArm(host) as arm:`` connects RTDE (output recipe
    :data:`~robocritics.deploy.stream.STATE_FIELDS` at ``frequency_hz``, input recipe
    :data:`~robocritics.deploy.urscript.INPUT_FIELDS`, synchronisation started) and
    the dashboard; leaving the block closes both. ``timeout_s`` bounds connecting
    and every request/reply [s]. Connection problems raise
    :class:`~robocritics.errors.RTDEError` (a DeployError).
    """

    def __init__(
        self,
        host: str,
        *,
        rtde_port: int = RTDE_PORT,
        dashboard_port: int = DASHBOARD_PORT,
        secondary_port: int = SECONDARY_PORT,
        timeout_s: float = 2.0,
        frequency_hz: float = CONTROL_RATE_HZ,
    ) -> None:
        if not timeout_s > 0:
            raise DeployError(f"timeout_s must be > 0 s, got {timeout_s}")
        #: The controller's channels and their state, which the stream uses (it never sees this arm).
        self.connection = URConnection(host, int(rtde_port), int(dashboard_port), int(secondary_port),
                                       float(timeout_s), float(frequency_hz))  # fmt: skip

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
        if self.connection.rtde_client is not None:
            if self.connection.rtde_client.connected:
                raise DeployError(f"URArm {self.host} is already connected")
            self.close()
        rtde = RTDEClient(self.host, self.rtde_port, timeout_s=self.timeout_s, buffer_size=4096)
        rtde.connect()
        try:
            recipe = rtde.setup_outputs(list(STATE_FIELDS), self.frequency_hz)
            _check_types(recipe, rtde.address)
            self.connection.out_freq = recipe.frequency_hz
            self.connection.inputs = rtde.setup_inputs(list(INPUT_FIELDS))
            _check_types(self.connection.inputs, rtde.address)
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
        self.connection.rtde_client = rtde
        self.connection.dashboard_client = dash
        self.connection.dashboard_broken = False

    def close(self) -> None:
        """Close both connections (bounded)."""
        rtde, self.connection.rtde_client = self.connection.rtde_client, None
        with self.connection.dash_lock:
            dash, self.connection.dashboard_client = self.connection.dashboard_client, None
        if rtde is not None:
            rtde.close()
        if dash is not None:
            dash.close()

    # where the controller is: the connection's (one source for the stream and the arm)
    host = property(lambda self: self.connection.host)
    rtde_port = property(lambda self: self.connection.rtde_port)
    dashboard_port = property(lambda self: self.connection.dashboard_port)
    secondary_port = property(lambda self: self.connection.secondary_port)
    timeout_s = property(lambda self: self.connection.timeout_s)
    frequency_hz = property(lambda self: self.connection.frequency_hz)

    @property
    def rtde(self) -> RTDEClient:
        """The RTDE client (raises if not connected)."""
        return self.connection.rtde

    @property
    def dashboard(self) -> DashboardClient:
        """The dashboard client, e.g. to power on: ``arm.dashboard.power_on()``."""
        return self.connection.dashboard

    def state(self) -> dict[str, Any]:
        """The next RTDE data package (fresh, waits at most ``timeout_s``)."""
        return self.rtde.wait_next(self.timeout_s)

    def actual_q(self) -> np.ndarray:
        """Actual joint positions [rad] from a fresh data package."""
        return np.asarray(self.state()["actual_q"], dtype=float)

    # ------------------------------------------------------------------ approach

    def approach(self, execution: Execution, speed_fraction: float = 0.1) -> Trajectory:
        """A slow joint move from the arm's ``actual_q`` to the first sample of ``execution``'s trajectory.

        :func:`approach_trajectory` with ``execution.robot`` and ``execution.scene``.
        Not judged yet: critique it (``robocritics.critique(approach, execution.scene)``)
        and deploy it with that report, like any motion.
        """
        if not isinstance(execution, Execution):
            raise DeployError(
                f"approach() needs the Execution robocritics.simulate() returned (its robot and scene), "
                f"got {type(execution).__name__}"
            )
        return approach_trajectory(
            execution.robot, execution.scene, self.actual_q(), execution.trajectory, speed_fraction=speed_fraction
        )

    # ------------------------------------------------------------------ deploy

    def deploy(
        self,
        motion: Execution | Trajectory,
        report: Any,
        *,
        allow_errors: bool = False,
        dry_run: bool = False,
        start_tolerance_rad: float = 0.01,
        max_tracking_error_rad: float = 0.05,
        rate_hz: float = CONTROL_RATE_HZ,
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
        stop: threading.Event | None = None,
        progress: Callable[[DeployProgress], None] | None = None,
    ) -> DeployResult:
        """Check ``motion`` against ``report`` and the arm (the gate), then stream it.

        ``motion``: the :class:`~robocritics.execution.Execution` that
        :func:`robocritics.simulate` returned, or a
        :class:`~robocritics.trajectory.Trajectory` (e.g. :meth:`approach`);
        ``report``: the :class:`~robocritics.critic.report.Report` of exactly that trajectory.
        ``allow_errors`` must be passed explicitly to deploy a report with Errors.
        ``dry_run`` does the gate, the connection checks, the resampling, the
        program text and the pacing schedule, and checks that the secondary
        interface accepts connections, but sends no program and no setpoint.
        ``rate_hz`` must divide the 500 Hz control rate (500, 250, 125, …): each
        setpoint advances the sequence counter by ``500 / rate_hz`` control cycles.
        ``stop``: an Event that stops the arm when set (fault ``stop_requested``, the same stop path as any
        fault); ``progress``: called with a :class:`~robocritics.deploy.stream.DeployProgress` while streaming.
        The other parameters are the thresholds in :mod:`robocritics.deploy.stream`.

        Raises :class:`~robocritics.deploy.gate.DeployRefused` (the gate; nothing
        sent) or :class:`~robocritics.deploy.stream.DeployFault` (a fault stopped
        the arm). Returns a :class:`~robocritics.deploy.stream.DeployResult`.
        """
        steps = _check_options(rate_hz=rate_hz, start_tolerance_rad=start_tolerance_rad,
                               max_tracking_error_rad=max_tracking_error_rad, silence_timeout_s=silence_timeout_s,
                               start_timeout_s=start_timeout_s, settle_tolerance_rad=settle_tolerance_rad,
                               settle_timeout_s=settle_timeout_s, stop_timeout_s=stop_timeout_s,
                               monitor_period_s=monitor_period_s, min_data_rate_fraction=min_data_rate_fraction,
                               spin_s=spin_s)
        traj = trajectory_of(motion)
        self.rtde  # noqa: B018  (not connected: say so before anything else)
        try:
            plan = resample(traj, rate_hz)
        except (DeployError, ValueError) as exc:
            raise DeployRefused([("trajectory", f"cannot resample the trajectory: {exc}")]) from None
        reasons = check_report(traj, report, allow_errors=allow_errors) + check_trajectory(traj, plan)
        if reasons:
            raise DeployRefused(reasons)
        state = self._robot_gate(traj, plan, start_tolerance_rad)
        program = streaming_program(
            lookahead_time_s=lookahead_time_s,
            gain=gain,
            watchdog_min_hz=watchdog_min_hz,
            max_start_deviation_rad=min(0.5, start_tolerance_rad + 0.005),
        )
        trajectory_hash = traj.content_hash(recompute=True)
        if dry_run:
            self._probe_secondary()
            return _dry_run_result(traj, plan, state, trajectory_hash, program)
        window_s = lookahead_time_s + 0.02
        run = _Run(
            plan=plan,
            session=random.randint(1, 2**31 - 1),
            step=int(round(steps)),
            max_tracking_error_rad=float(max_tracking_error_rad),
            window=max(1, int(math.ceil(window_s * rate_hz))),
            stop=stop,
            progress=progress,
        )
        return _Stream(self.connection).run(
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

    def _robot_gate(self, traj: Trajectory, plan: StreamPlan, start_tolerance_rad: float) -> dict[str, Any]:
        """The robot rules of the gate on a fresh data package and the dashboard's answers; that package."""
        rtde = self.rtde
        try:
            state = rtde.wait_next(self.timeout_s)
        except RTDEValueError as exc:
            raise DeployRefused([("non_finite", str(exc))]) from None
        with self.connection.dash_lock:
            try:
                remote, dashboard_error = self.connection.healthy_dashboard().is_in_remote_control(), ""
            except RTDEError as exc:
                remote, dashboard_error = None, str(exc)
            try:  # joint angles mean a pose only on the arm they were planned for
                model, model_error = self.connection.healthy_dashboard().robot_model(), ""
            except RTDEError as exc:
                model, model_error = None, str(exc)
        reasons = check_robot(state, plan.q[0], remote_control=remote, start_tolerance_rad=start_tolerance_rad,
                              dashboard_error=dashboard_error)
        reasons += check_model(traj, model, dashboard_error=model_error)
        if reasons:
            raise DeployRefused(reasons)
        return state

    def _probe_secondary(self) -> None:
        try:
            with socket.create_connection((self.host, self.secondary_port), timeout=self.timeout_s):
                pass
        except (OSError, UnicodeError, OverflowError) as exc:  # also a bad host label or port number
            raise DeployRefused([(
                "secondary_interface",
                f"cannot connect to the secondary interface at {self.host}:{self.secondary_port}: {exc}",
            )]) from None


def _check_options(*, rate_hz: float, start_tolerance_rad: float, min_data_rate_fraction: float, spin_s: float,
                   **limits: float) -> float:
    """Refuse deploy options out of range (a NaN or inf threshold would switch its rule off); the number of
    control cycles per setpoint."""
    steps = CONTROL_RATE_HZ / rate_hz if isinstance(rate_hz, (int, float)) and 0 < rate_hz < math.inf else 0.0
    if not (abs(steps - round(steps)) < 1e-9 and round(steps) >= 1):
        raise DeployError(f"rate_hz must divide {CONTROL_RATE_HZ:g} Hz (500, 250, 125, 100, …), got {safe_text(rate_hz, 40)}")
    if not (isinstance(start_tolerance_rad, (int, float)) and 0 < start_tolerance_rad <= 0.5):
        raise DeployError(f"start_tolerance_rad must be in (0, 0.5] rad, got {safe_text(start_tolerance_rad, 40)}")
    for name, value in limits.items():  # a NaN or inf threshold would switch its rule off
        if not (isinstance(value, (int, float)) and 0 < value < math.inf):
            raise DeployError(f"{name} must be a finite number > 0, got {safe_text(value, 40)}")
    if not (isinstance(min_data_rate_fraction, (int, float)) and 0 < min_data_rate_fraction <= 1):
        raise DeployError(f"min_data_rate_fraction must be in (0, 1], got {safe_text(min_data_rate_fraction, 40)}")
    if not (isinstance(spin_s, (int, float)) and 0 <= spin_s < 0.01):
        raise DeployError(f"spin_s must be in [0, 0.01) s, got {safe_text(spin_s, 40)}")
    return steps


def _check_types(recipe: Recipe, address: str) -> None:
    """Refuse a controller that answers other types than the RTDE specification's for the fields deploy uses."""
    wrong = [f"{n} is {safe_text(t, 20)}, not {rtde_type(n)}" for n, t in zip(recipe.names, recipe.types)
             if t != rtde_type(n)]
    if wrong:
        raise RTDEError(f"RTDE controller at {address} answered unexpected field types: {'; '.join(wrong)}")


def _dry_run_result(traj: Trajectory, plan: StreamPlan, state: dict[str, Any], trajectory_hash: str,
                    program: str) -> DeployResult:
    final_q = tuple(float(v) for v in state["actual_q"])
    nan = float("nan")
    return DeployResult(
        samples_sent=0,
        trajectory_samples=len(traj.q),
        rate_hz=plan.rate_hz,
        duration_s=0.0,
        trajectory_duration_s=float(plan.time[-1]),
        period_error_median_ms=nan,
        period_error_p99_ms=nan,
        period_error_max_ms=nan,
        lateness_p99_ms=nan,
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
