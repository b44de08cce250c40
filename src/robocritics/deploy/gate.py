"""The deploy gate: what a trajectory, its report and the arm must satisfy before anything moves.

Plain functions of typed inputs — a :class:`~robocritics.trajectory.Trajectory`,
the :class:`~robocritics.critic.report.Report` that judged it, the resampled
:class:`~robocritics.deploy.stream.StreamPlan` and one RTDE state package — each
returning the ``(cause, explanation)`` reasons it finds (empty: the rule passes).
:meth:`robocritics.deploy.URArm.deploy` runs them and raises :class:`DeployRefused`
with every reason before it sends anything that could move the arm.

===================  ===========================================================
cause                rule
===================  ===========================================================
``no_report``        a :class:`~robocritics.critic.report.Report` is required
``report_errors``    the report has an Error verdict (names each critic and its
                     message); ``allow_errors=True`` overrides this rule only
``hash_mismatch``    ``report.trajectory_hash != trajectory.content_hash()``:
                     the report judged a different motion
``trajectory``       not an Execution or a Trajectory, not 6 joints, non-finite
                     values, or it cannot be resampled
``setpoint_speed``   a setpoint step of the resampled stream asks for more than
                     the trajectory's joint speed limits (the controller would
                     protective-stop); not overridable
``robot_mode``       RTDE ``robot_mode`` is not RUNNING (7)
``safety_mode``      RTDE ``safety_mode`` is not NORMAL (1)
``remote_control``   the dashboard says the controller is in local control (or
                     cannot be asked)
``program_running``  ``runtime_state`` is not STOPPED (another program runs)
``start_mismatch``   the first sample is farther than ``start_tolerance_rad``
                     from ``actual_q`` on some joint
``non_finite``       the robot reported NaN or ±inf in a field (the RTDE
                     guard :func:`~robocritics.deploy.rtde.first_non_finite`);
                     no other robot rule is judged on such a state
``arm_model``        the dashboard's ``get robot model`` is not the arm the
                     trajectory was planned for (found by its
                     ``kinematic_hash``, e.g. a UR10e plan on a UR5e; a chain
                     that is no bundled UR's is refused), or cannot be asked
``secondary_         (dry run only) the secondary interface does not accept
interface``          connections
===================  ===========================================================

The offline rules (:func:`check_report`, :func:`check_trajectory`) are checked
before the robot is asked anything; if one fails, the robot rules
(:func:`check_robot`) are not evaluated.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from robocritics._text import safe_text
from robocritics.deploy.rtde import RobotMode, RuntimeState, SafetyMode, first_non_finite, mode_name
from robocritics.deploy.stream import StreamPlan
from robocritics.errors import DeployError
from robocritics.robot.arms import ARMS
from robocritics.critic.report import Report
from robocritics.execution import Execution
from robocritics.trajectory import Trajectory

__all__ = [
    "DeployRefused",
    "Reason",
    "trajectory_of",
    "check_report",
    "check_trajectory",
    "check_robot",
    "check_model",
    "START_MISMATCH_HINT",
]

Reason = tuple[str, str]
"""``(cause, explanation)``: one rule that failed."""

START_MISMATCH_HINT = (
    "Plan the motion from where the arm is: `robocritics deploy PROGRAM --host HOST` does that (it simulates "
    "from the arm's joints); in Python, `simulate(program, scene, start_q=arm.actual_q())`. Or move to the start "
    "first with a critiqued approach: `approach = arm.approach(execution)`, then "
    "`arm.deploy(approach, critique(approach, execution.scene))`"
)
"""What the ``start_mismatch`` reason tells the user to do."""


class DeployRefused(DeployError):
    """The gate refused to deploy; nothing that moves the arm was sent.

    ``cause`` is the first reason (see the module docstring), ``causes`` all of them,
    ``reasons`` the ``(cause, explanation)`` pairs.
    """

    def __init__(self, reasons: Sequence[Reason]):
        self.reasons = tuple(reasons)
        self.causes = tuple(c for c, _ in self.reasons)
        lines = "\n".join(f"  - [{c}] {text}" for c, text in self.reasons)
        n = len(self.reasons)
        super().__init__(f"deploy refused ({n} reason{'s' if n != 1 else ''}); nothing was sent to the robot:\n{lines}",
                         sample=-1, cause=self.causes[0] if self.causes else "refused")


def trajectory_of(motion: Execution | Trajectory) -> Trajectory:
    """The trajectory to deploy: ``motion`` itself or ``motion.trajectory`` of an Execution.

    Anything else is refused (cause ``trajectory``) naming the type it got.
    """
    if isinstance(motion, Execution):
        motion = motion.trajectory
    if not isinstance(motion, Trajectory):
        raise DeployRefused([(
            "trajectory",
            f"deploy needs a robocritics.Trajectory or the Execution robocritics.simulate() returned, "
            f"got {type(motion).__name__}",
        )])
    return motion


def check_report(trajectory: Trajectory, report: Report | None, *, allow_errors: bool = False) -> list[Reason]:
    """``no_report``, ``report_errors`` (unless ``allow_errors is True``) and ``hash_mismatch``."""
    if not isinstance(report, Report):
        got = "none" if report is None else f"a {type(report).__name__}"
        return [("no_report", f"deploy needs the Report that robocritics.critique() made for this trajectory, got {got}")]
    reasons: list[Reason] = []
    errors = report.errors
    if errors and allow_errors is not True:
        listed = "; ".join(f"{v.critic}: {v.message}" for v in errors)
        reasons.append((
            "report_errors",
            f"the critics' report has {len(errors)} Error(s) — {listed} — fix the program, or pass "
            "allow_errors=True to deploy anyway",
        ))
    actual_hash = trajectory.content_hash(recompute=True)
    if report.trajectory_hash != actual_hash:
        reasons.append((
            "hash_mismatch",
            f"the report judged trajectory {report.trajectory_hash[:12]}… but this trajectory is "
            f"{actual_hash[:12]}…; critique exactly the motion you deploy",
        ))
    return reasons


def check_trajectory(trajectory: Trajectory, plan: StreamPlan) -> list[Reason]:
    """``trajectory`` (6 joints, finite) and ``setpoint_speed``: every step of ``plan`` within
    ``trajectory.limits.velocity_rad_s``."""
    q = trajectory.q
    if q.ndim != 2 or q.shape[1] != 6:
        return [("trajectory", f"a UR arm needs 6 joint values per sample, the trajectory has shape {q.shape}")]
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(trajectory.time))):
        return [("trajectory", "the trajectory has non-finite joint values or times")]
    if len(plan) < 2:
        return []
    vlim = np.asarray(trajectory.limits.velocity_rad_s, dtype=float)
    if vlim.shape != (6,) or not np.all(np.isfinite(vlim) & (vlim > 0)):
        return [("setpoint_speed", f"the trajectory's joint speed limits {safe_text(vlim.tolist(), 200)} rad/s are "
                                   "not 6 finite positive numbers; no speed can be checked against them")]
    speed = np.abs(np.diff(plan.q, axis=0)) * plan.rate_hz
    ratio = speed / vlim
    if np.all(ratio <= 1.0 + 1e-6):  # written so that a NaN fails the rule
        return []
    worst = np.unravel_index(int(np.argmax(np.where(np.isnan(ratio), np.inf, ratio))), ratio.shape)
    k, j = int(worst[0]) + 1, int(worst[1])
    return [(
        "setpoint_speed",
        f"setpoint {k} (trajectory sample {int(plan.source_index[k])}, t = {plan.time[k]:.3f} s) moves joint "
        f"{j} ({trajectory.limits.joint_names[j]}) at {speed[worst]:.3f} rad/s > its limit {vlim[j]:.3f} rad/s; "
        "the controller would protective-stop",
    )]


def check_model(trajectory: Trajectory, reported_model: str | None, *, dashboard_error: str = "") -> list[Reason]:
    """``arm_model``: the controller is the arm ``trajectory`` was planned for.

    ``reported_model`` is the dashboard's answer to ``get robot model`` (``"UR3"``, ``"UR5"``, ``"UR10"``,
    ``"UR16"``; None with ``dashboard_error`` when it could not be asked). The arm is found by the
    trajectory's ``kinematic_hash`` (:attr:`Robot.kinematic_hash`), never by its name: a trajectory whose
    kinematics are none of the bundled UR arms' in UR's base convention (another arm, a ROS-convention UR
    description named "ur3e") or that has no hash is refused: joint angles mean a pose only on the arm they
    were planned for.
    """
    # keyed on what the joint angles mean (Robot.kinematic_hash: flange poses in the base frame), not on the
    # name: a URDF that calls itself "ur3e" in ROS's base convention puts the TCP on the other side of the base
    known = ", ".join(ARMS)
    name = (trajectory.robot_name or "an unnamed robot")[:60]  # a name from a file: clipped (repr escapes it)
    if not trajectory.kinematic_hash:
        return [("arm_model", f"the trajectory planned for {name!r} does not say which kinematics it was planned for "
                              "(no kinematic_hash: written before robocritics recorded it); plan it again")]
    matches = [arm for arm, digest in bundled_kinematic_hashes().items() if digest == trajectory.kinematic_hash]
    if not matches:
        return [("arm_model", f"the trajectory was planned for {name!r}, whose kinematics (hash "
                              f"{trajectory.kinematic_hash[:20]!r}) are none of the UR arms deploy knows ({known}) in UR's "
                              "base convention; plan it with Robot.ur5e() etc.")]
    spec = ARMS[matches[0]]
    if reported_model is None:
        return [("arm_model", f"cannot ask the dashboard which arm this is ('get robot model'): {dashboard_error}")]
    reported = reported_model.strip().upper()
    if reported != spec.dashboard_model:
        other = ARMS_BY_DASHBOARD.get(reported)
        hint = f"plan it for this arm (simulate(..., robot=Robot.{other}()))" if other else "no bundled arm is this one"
        return [("arm_model", f"the trajectory was planned for a {spec.name} but the controller reports "
                              f"{reported_model.strip()!r} (a {spec.name} reports {spec.dashboard_model!r}); {hint}")]
    return []


def bundled_kinematic_hashes() -> dict[str, str]:
    """``Robot.kinematic_hash`` of each bundled UR arm, by name (computed once)."""
    if not _HASHES:
        from robocritics.robot.model import Robot

        _HASHES.update({name: Robot.ur(name).kinematic_hash for name in ARMS})
    return dict(_HASHES)


_HASHES: dict[str, str] = {}

ARMS_BY_DASHBOARD = {spec.dashboard_model: spec.name for spec in ARMS.values()}
"""The bundled arm's name for each dashboard ``get robot model`` answer (``"UR5"`` -> ``"ur5e"``)."""


def check_robot(
    state: Mapping[str, Any],
    first_q: np.ndarray,
    *,
    remote_control: bool | None,
    start_tolerance_rad: float,
    dashboard_error: str = "",
) -> list[Reason]:
    """The robot rules on one RTDE state package (``robot_mode``, ``safety_mode``,
    ``runtime_state``, ``actual_q``) and the dashboard's answer to ``is in remote control``
    (``remote_control``; None with ``dashboard_error`` when it could not be asked)."""
    bad = first_non_finite(state)
    if bad is not None:  # the robot says something that is not a number: judge nothing else on it
        name, index, value = bad
        where = name if index is None else f"{name}[{index}]"
        return [("non_finite", f"the controller reported {where} = {safe_text(value, 40)}, not a finite number; "
                               "nothing is sent on a state with a value that is not a number")]
    reasons: list[Reason] = []
    rm, sm, rs = state.get("robot_mode"), state.get("safety_mode"), state.get("runtime_state")
    if rm != RobotMode.RUNNING:
        reasons.append((
            "robot_mode",
            f"robot mode is {mode_name(RobotMode, rm)}, not RUNNING ({RobotMode.RUNNING:d}); power on and release "
            "the brakes (arm.dashboard.power_on(), arm.dashboard.brake_release())",
        ))
    if sm != SafetyMode.NORMAL:
        hint = "; inspect the cause, then arm.dashboard.unlock_protective_stop()" if sm == SafetyMode.PROTECTIVE_STOP else ""
        reasons.append(("safety_mode", f"safety mode is {mode_name(SafetyMode, sm)}, not NORMAL ({SafetyMode.NORMAL:d}){hint}"))
    if remote_control is None:
        reasons.append(("remote_control", f"cannot ask the dashboard whether the robot is in remote control: {dashboard_error}"))
    elif remote_control is False:
        reasons.append((
            "remote_control",
            "the controller is in local control; it would ignore the streaming program — enable remote control on the teach pendant",
        ))
    if rs != RuntimeState.STOPPED:
        reasons.append((
            "program_running",
            f"runtime state is {mode_name(RuntimeState, rs)}, not STOPPED: another program is running; stop it first",
        ))
    actual = np.asarray(state.get("actual_q", ()), dtype=float)
    if actual.shape != (6,):
        reasons.append(("start_mismatch", f"the controller reported actual_q {actual.tolist()}, not 6 joint positions"))
        return reasons
    dev = np.abs(np.asarray(first_q, dtype=float) - actual)
    j = int(np.argmax(np.where(np.isnan(dev), np.inf, dev)))
    if not dev[j] <= start_tolerance_rad:  # a NaN fails the rule too
        reasons.append((
            "start_mismatch",
            f"the trajectory starts {dev[j]:.4f} rad away from the arm on joint {j} (> start_tolerance_rad "
            f"{start_tolerance_rad:g} rad); actual_q = [{', '.join(f'{v:.4f}' for v in actual)}], first sample = "
            f"[{', '.join(f'{v:.4f}' for v in first_q)}]. {START_MISMATCH_HINT}",
        ))
    return reasons
