"""Physically timed motion: jerk-limited joint moves (ruckig) and straight Cartesian lines.

Speed scaling
-------------
A speed fraction ``f`` in (0, 1] scales the limits as a pure **time stretch**:
velocity ``f * v``, acceleration ``f**2 * a``, jerk ``f**3 * j``. The
time-optimal profile under the scaled limits is then exactly the full-speed
profile played ``1/f`` times slower, so ``reduce_speed(50)`` doubles the
duration of every move it affects, and every speed the critics read halves.

Joint moves are rest-to-rest ruckig profiles, time-synchronised across joints.
Cartesian lines are exact: the path parameter ``s`` (m along the line) follows a
1-D jerk-limited profile whose speed is capped both by the linear TCP speed
limit and by the joint speed limits through the path's ``|dq/ds|`` (measured by
dense IK before timing), and every sample is solved by IK on the line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from ruckig import InputParameter, Result, Ruckig, RuckigError, Trajectory as RuckigTrajectory

from ..errors import PlanningError

__all__ = ["Limits", "Segment", "time_joint_move", "time_path_1d", "sample_times", "JOINT_SPEED_MARGIN"]

#: Share of the joint speed limit a Cartesian line may use, so finite differences
#: between the dense-IK grid points cannot exceed the limit.
JOINT_SPEED_MARGIN = 0.95


@dataclass(frozen=True)
class Limits:
    """Per-joint limits at full speed: rad/s, rad/s^2, rad/s^3."""

    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray

    def scaled(self, speed_fraction: float) -> "Limits":
        """Limits for a speed fraction in (0, 1] (a time stretch by 1/fraction)."""
        f = float(speed_fraction)
        if not 0 < f <= 1:
            raise PlanningError(f"speed fraction must lie in (0, 1], got {f}")
        return Limits(self.velocity * f, self.acceleration * f**2, self.jerk * f**3)


@dataclass(frozen=True)
class Segment:
    """A timed piece of motion: ``q (m, n)`` rad at ``time (m,)`` s from the segment start."""

    q: np.ndarray
    time: np.ndarray
    duration_s: float


def _ruckig(start: np.ndarray, goal: np.ndarray, limits: Limits) -> RuckigTrajectory:
    dofs = len(start)
    otg = Ruckig(dofs)
    inp = InputParameter(dofs)
    inp.current_position = start.tolist()
    inp.current_velocity = [0.0] * dofs
    inp.current_acceleration = [0.0] * dofs
    inp.target_position = goal.tolist()
    inp.target_velocity = [0.0] * dofs
    inp.target_acceleration = [0.0] * dofs
    inp.max_velocity = limits.velocity.tolist()
    inp.max_acceleration = limits.acceleration.tolist()
    inp.max_jerk = limits.jerk.tolist()
    traj = RuckigTrajectory(dofs)
    # ruckig's profile search can fail on rare numerical edge cases (a limit exactly at a
    # profile boundary); a relative nudge far below any physical significance gets past them
    for nudge in (0.0, 1e-9, 1e-6):
        if nudge:
            inp.max_velocity = (limits.velocity * (1 - nudge)).tolist()
            inp.max_acceleration = (limits.acceleration * (1 - nudge)).tolist()
        try:
            result = otg.calculate(inp, traj)
        except RuckigError:
            continue
        if result in (Result.Working, Result.Finished):
            return traj
    raise PlanningError(
        f"ruckig could not time the move from {np.round(start, 4).tolist()} to {np.round(goal, 4).tolist()}"
    )


def sample_times(duration_s: float, sample_rate_hz: float) -> np.ndarray:
    """Sample instants ``0, dt, 2 dt, ...`` strictly before ``duration_s`` (s)."""
    dt = 1.0 / sample_rate_hz
    count = max(1, int(np.ceil(duration_s / dt - 1e-9)))
    return np.arange(count) * dt


def time_joint_move(start, goal, limits: Limits, speed_fraction: float, sample_rate_hz: float) -> Segment:
    """Time a rest-to-rest joint move; samples at ``1/sample_rate_hz`` from t=0 (the end is excluded).

    The end configuration belongs to the next segment (or the final sample), so
    chained segments share no duplicate instant and time stays strictly increasing.
    """
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    if np.allclose(start, goal, atol=1e-12):
        return Segment(start[None, :], np.zeros(1), 0.0)
    traj = _ruckig(start, goal, limits.scaled(speed_fraction))
    times = sample_times(traj.duration, sample_rate_hz)
    q = np.array([traj.at_time(t)[0] for t in times])
    return Segment(q, times, float(traj.duration))


def time_path_1d(length: float, max_speed: float, max_accel: float, max_jerk: float, sample_rate_hz: float):
    """Jerk-limited rest-to-rest profile of a path parameter over ``[0, length]``.

    Returns ``(s (m,), times (m,), duration_s)`` with the end excluded like
    :func:`time_joint_move`.
    """
    if length <= 0:
        return np.zeros(1), np.zeros(1), 0.0
    lim = Limits(np.array([max_speed]), np.array([max_accel]), np.array([max_jerk]))
    traj = _ruckig(np.zeros(1), np.array([length]), lim)
    times = sample_times(traj.duration, sample_rate_hz)
    s = np.array([traj.at_time(t)[0][0] for t in times])
    return s, times, float(traj.duration)
