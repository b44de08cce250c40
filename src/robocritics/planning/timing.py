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

Sane ranges
-----------
A speed fraction lies in [:data:`MIN_SPEED_FRACTION`, 1] (1 % of full speed up
to full speed) and a sample rate in [:data:`MIN_SAMPLE_RATE_HZ`,
:data:`MAX_SAMPLE_RATE_HZ`] Hz; outside them :class:`PlanningError` says the
range. Timing happens in two stages, so a caller can check the duration of a
move, and the samples it will need, before any sample is made:
:func:`profile_joint_move` / :func:`profile_path_1d` give a :class:`Profile`
(the duration, no samples), and :meth:`Profile.sample` makes the samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import accumulate

import numpy as np
from ruckig import InputParameter, Result, Ruckig, RuckigError, Trajectory as RuckigTrajectory

from ..errors import PlanningError
from ..robot.arms import UR3E

__all__ = [
    "Limits",
    "Segment",
    "Profile",
    "profile_joint_move",
    "profile_path_1d",
    "time_joint_move",
    "time_path_1d",
    "sample_times",
    "sample_count",
    "check_speed_fraction",
    "check_sample_rate",
    "JOINT_SPEED_MARGIN",
    "MIN_SPEED_FRACTION",
    "MIN_SAMPLE_RATE_HZ",
    "MAX_SAMPLE_RATE_HZ",
    "MAX_SEGMENT_SAMPLES",
]

#: Share of the joint speed limit a Cartesian line may use, so finite differences
#: between the dense-IK grid points cannot exceed the limit.
JOINT_SPEED_MARGIN = 0.95

# The slowest speed fraction is part of the skill API's contract (set_speed/reduce_speed refuse below it):
# defined with the Plan, re-exported here for the timing code.
from ..program.plan import MIN_SPEED_FRACTION  # noqa: E402

MIN_SAMPLE_RATE_HZ = 25.0
"""Sparsest sampling the critics can trust [Hz]. They read speeds as finite differences, and the shortest
feature of a planned motion is a 0.1 s jerk ramp (the UR3e's acceleration/jerk limits and PlannerSettings'
lines): at 25 Hz a ramp spans 2.5 samples, and the example programs' verdicts and peak link speeds (to 1 %) are
those at 500 Hz. Sparser sampling averages fast motion away (at 2 Hz an Error of the sorting example vanishes)."""

MAX_SAMPLE_RATE_HZ = UR3E.control_rate_hz
"""Densest sampling [Hz]: the e-series control rate (500 Hz); no controller executes denser setpoints, so
denser samples only cost memory."""

MAX_SEGMENT_SAMPLES = 1_000_000
"""Most samples one timed piece of motion may make (a backstop for direct callers: the planner's motion budget,
PlannerSettings.max_samples, is far smaller and is checked before sampling)."""


def check_speed_fraction(fraction, what: str = "speed fraction") -> float:
    """``fraction`` as a float in [MIN_SPEED_FRACTION, 1]; :class:`PlanningError` naming ``what`` otherwise."""
    try:
        f = float(fraction)
    except (TypeError, ValueError, OverflowError):
        raise PlanningError(f"{what} must be a number in [{MIN_SPEED_FRACTION:g}, 1], got {fraction!r:.40}") from None
    if not MIN_SPEED_FRACTION <= f <= 1:
        raise PlanningError(
            f"{what} must lie in [{MIN_SPEED_FRACTION:g}, 1] ({MIN_SPEED_FRACTION * 100:g} % to 100 % of full speed), "
            f"got {f:g}"
        )
    return f


def check_sample_rate(rate_hz, what: str = "sample_rate_hz") -> float:
    """``rate_hz`` as a float in [MIN_SAMPLE_RATE_HZ, MAX_SAMPLE_RATE_HZ] Hz; :class:`PlanningError` otherwise."""
    span = f"[{MIN_SAMPLE_RATE_HZ:g}, {MAX_SAMPLE_RATE_HZ:g}] Hz"
    try:
        r = float(rate_hz)
    except (TypeError, ValueError, OverflowError):
        raise PlanningError(f"{what} must be a number of Hz in {span}, got {rate_hz!r:.40}") from None
    if not MIN_SAMPLE_RATE_HZ <= r <= MAX_SAMPLE_RATE_HZ:
        if not math.isfinite(r):
            why = "not a finite number"
        elif r < MIN_SAMPLE_RATE_HZ:
            why = "sparser sampling hides fast motion from the critics"
        else:
            why = "no controller executes denser setpoints"
        raise PlanningError(f"{what} must lie in {span} ({why}), got {r:g}")
    return r


@dataclass(frozen=True)
class Limits:
    """Per-joint limits at full speed: rad/s, rad/s^2, rad/s^3."""

    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray

    def scaled(self, speed_fraction: float) -> "Limits":
        """Limits for a speed fraction in [MIN_SPEED_FRACTION, 1] (a time stretch by 1/fraction)."""
        f = check_speed_fraction(speed_fraction)
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
        except (RuckigError, ValueError):  # ValueError: a result code the binding has no name for
            continue
        if result in (Result.Working, Result.Finished):
            return traj
    raise PlanningError(
        f"ruckig could not time the move from {np.round(start, 4).tolist()} to {np.round(goal, 4).tolist()}"
    )


def sample_count(duration_s: float, sample_rate_hz: float) -> int:
    """How many samples :func:`sample_times` makes for ``duration_s`` at ``sample_rate_hz`` (without making them)."""
    if not (math.isfinite(duration_s) and duration_s >= 0):
        raise PlanningError(f"a motion must last a finite, non-negative time, got {duration_s} s")
    return max(1, math.ceil(duration_s / (1.0 / sample_rate_hz) - 1e-9))  # math.ceil: np.ceil's value, no array


def sample_times(duration_s: float, sample_rate_hz: float, max_samples: int = MAX_SEGMENT_SAMPLES) -> np.ndarray:
    """Sample instants ``0, dt, 2 dt, ...`` strictly before ``duration_s`` (s).

    Raises :class:`PlanningError` before allocating when that takes more than ``max_samples`` samples.
    """
    count = sample_count(duration_s, sample_rate_hz)
    if count > max_samples:
        raise PlanningError(
            f"{duration_s:.4g} s of motion at {sample_rate_hz:g} Hz takes {count:,} samples; the limit is {max_samples:,}"
        )
    return np.arange(count) * (1.0 / sample_rate_hz)  # as dt = 1 / rate: the same instants as ever


@dataclass(frozen=True)
class Profile:
    """A timed rest-to-rest move before sampling: its duration is known, no sample has been made.

    ``position(times)`` gives the ``(m, dofs)`` positions at ``times`` (s from the start); ``goal`` is where the
    move ends (the target ruckig was given; None for no move).
    """

    duration_s: float
    start: np.ndarray = field(repr=False, compare=False)
    _traj: RuckigTrajectory | None = field(default=None, repr=False, compare=False)
    goal: np.ndarray | None = field(default=None, repr=False, compare=False)

    def samples_needed(self, sample_rate_hz: float) -> int:
        """Samples :meth:`sample` makes at ``sample_rate_hz`` (the end excluded)."""
        return sample_count(self.duration_s, sample_rate_hz)

    def position(self, times: np.ndarray) -> np.ndarray:
        """Positions ``(m, dofs)`` at ``times`` (s from the start, in ``[0, duration_s]``).

        Ruckig's ``at_time`` without a Python call per sample or per DOF: for every (time, DOF) the phase ``k``
        of the time in that DOF's profile (its cumulative phase ends ``t_sum``: ``k`` counts the ends at or before
        the time, ruckig's ``std::upper_bound``) and ``p_k + dt (v_k + dt (a_k / 2 + dt j_k / 6))`` with ``dt``
        the time into the phase, the same expression in the same order as ruckig's ``integrate`` (past the last
        phase: the final state, ``j = 0``). A rest-to-rest move has no brake pre-phase and ends in its target at
        rest (ruckig's ``pf, vf, af = goal, 0, 0``; ``tests/test_motion.py`` checks both), so only the phase
        durations, jerks and phase-start states are read from ruckig: each read converts an array.
        """
        if self._traj is None:
            return np.repeat(self.start[None, :], len(times), axis=0)
        times = np.asarray(times, dtype=float)
        profiles = self._traj.profiles[0]
        # per DOF: the 7 phase durations, and the state (p, v, a, j) at each phase start followed by the final
        # state (the goal at rest) for times past the last phase: one (dofs * 8, 4) table for all DOFs
        dofs = len(profiles)
        goal = self.goal.tolist()
        starts, ps, vs, accs, js = [], [], [], [], []
        for prof, g in zip(profiles, goal):
            starts.append(0.0)
            starts += accumulate(prof.t)  # np.cumsum's sequential sums: the phase ends
            ps += prof.p[:7]
            ps.append(g)
            vs += prof.v[:7]
            vs.append(0.0)
            accs += prof.a[:7]
            accs.append(0.0)
            js += prof.j
            js.append(0.0)
        states = np.array([ps, vs, accs, js], dtype=float).T  # (dofs * 8, 4): one gather fetches all four
        starts_arr = np.array(starts)  # (dofs * 8): each DOF's phase starts, then its end
        k = np.empty((len(times), dofs), dtype=np.intp)
        for dof in range(dofs):
            # std::upper_bound in the phase ends (non-decreasing); 7: past the end
            k[:, dof] = np.searchsorted(starts_arr[8 * dof + 1 : 8 * dof + 8], times, side="right")
        entry = k + 8 * np.arange(dofs)  # (m, dofs): the (dof, phase) entry of each sample, flattened
        dt = times[:, None] - starts_arr[entry]
        gathered = np.take(states, entry, axis=0)  # (m, dofs, 4)
        p, v, a, j = gathered[..., 0], gathered[..., 1], gathered[..., 2], gathered[..., 3]  # (m, dofs) each
        return p + dt * (v + dt * (a / 2 + dt * j / 6))

    def sample(self, sample_rate_hz: float, max_samples: int = MAX_SEGMENT_SAMPLES) -> Segment:
        """The move sampled at ``1/sample_rate_hz`` from t=0, the end excluded (see :func:`time_joint_move`)."""
        if self._traj is None:
            return Segment(self.start[None, :], np.zeros(1), 0.0)
        times = sample_times(self.duration_s, sample_rate_hz, max_samples)
        return Segment(self.position(times), times, self.duration_s)


def _allclose(start: np.ndarray, goal: np.ndarray) -> bool:
    """``np.allclose(start, goal, atol=1e-12)``: every ``|start - goal| <= 1e-12 + 1e-5 |goal|`` (infinities
    only equal to themselves), on Python floats: the same comparisons without numpy's per-call overhead."""
    if start.shape != goal.shape:
        return bool(np.allclose(start, goal, atol=1e-12))  # broadcasting: numpy's own rule
    for s, g in zip(start.ravel().tolist(), goal.ravel().tolist()):
        if math.isfinite(s) and math.isfinite(g):
            if not abs(s - g) <= 1e-12 + 1e-5 * abs(g):
                return False
        elif s != g:
            return False
    return True


def profile_joint_move(start, goal, limits: Limits, speed_fraction: float) -> Profile:
    """The time-optimal jerk-limited rest-to-rest joint move from ``start`` to ``goal`` (rad), not yet sampled."""
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    if _allclose(start, goal):
        return Profile(0.0, start)
    traj = _ruckig(start, goal, limits.scaled(speed_fraction))
    return Profile(float(traj.duration), start, traj, goal)


def profile_path_1d(length: float, max_speed: float, max_accel: float, max_jerk: float) -> Profile:
    """The jerk-limited rest-to-rest profile of a path parameter over ``[0, length]``, not yet sampled."""
    if not length > 0:
        return Profile(0.0, np.zeros(1))
    lim = Limits(np.array([max_speed]), np.array([max_accel]), np.array([max_jerk]))
    goal = np.array([length])
    traj = _ruckig(np.zeros(1), goal, lim)
    return Profile(float(traj.duration), np.zeros(1), traj, goal)


def time_joint_move(start, goal, limits: Limits, speed_fraction: float, sample_rate_hz: float) -> Segment:
    """Time a rest-to-rest joint move; samples at ``1/sample_rate_hz`` from t=0 (the end is excluded).

    The end configuration belongs to the next segment (or the final sample), so
    chained segments share no duplicate instant and time stays strictly increasing.
    """
    return profile_joint_move(start, goal, limits, speed_fraction).sample(sample_rate_hz)


def time_path_1d(length: float, max_speed: float, max_accel: float, max_jerk: float, sample_rate_hz: float):
    """Jerk-limited rest-to-rest profile of a path parameter over ``[0, length]``.

    Returns ``(s (m,), times (m,), duration_s)`` with the end excluded like
    :func:`time_joint_move`.
    """
    seg = profile_path_1d(length, max_speed, max_accel, max_jerk).sample(sample_rate_hz)
    return seg.q[:, 0], seg.time, seg.duration_s
