r"""Separation: speed and separation monitoring (ISO/TS 15066:2016, 5.5.4).

At every sample ``t``, for every person in the scene (:mod:`robocritics.humans`):

* ``S(t)``: the separation, m: the least distance between any robot part (capsule, or carried object) and any
  capsule of the person's body model;
* ``v_r(t)``: the robot's speed toward the person, m/s: the fastest rate at which any part's distance to the
  person shrinks (formula 1 of 5.5.4.2.3 takes the robot's speed "in the direction of the operator");
* ``S_p(t) = S_h + S_r + S_s + C + Z_d + Z_r`` (5.5.4.2.3, formula 2), m, with
  ``S_h = v_h (T_r + T_s)`` (the person walks at ``v_h`` = 1.6 m/s, ISO 13855:2010 5.2 and 6.2, while the
  system reacts and the robot stops), ``S_r = v_r T_r`` (the robot keeps moving while the system reacts),
  ``S_s = v_r T_s`` (the robot's stopping distance: no credit is taken for its deceleration, which
  over-states the distance of a uniform deceleration two-fold), ``C`` the intrusion distance of ISO 13855,
  ``Z_d`` and ``Z_r`` the position uncertainties of the person (sensor) and the robot.

``T_s`` is the arm's published stopping time (:attr:`robocritics.robot.arms.ArmSpec.stopping_time_s`): the
worst of its base, shoulder and elbow, measured at full speed, full extension and full payload (so it bounds
slower, shorter and lighter motions); ``Z_r`` is its published pose repeatability. ``T_r``, ``C`` and ``Z_d``
depend on the person-detecting sensor and are parameters.

Speed and separation monitoring lets the robot come closer than ``S_p`` only once it has slowed to a speed at
which contact is acceptable (5.5.4.1: SSM combined with power and force limiting; ``contact_speed`` judges
those contacts). This critic therefore flags the samples where ``S(t) < S_p(t)`` while the robot moves faster
than the reduced speed of ISO 10218-1:2011, 5.6 (0.25 m/s): ERROR there, WARNING where ``S(t)`` is within
``warn_margin_m`` of ``S_p(t)`` at such a speed, OK otherwise (and OK, "nothing to check", with no people).
On demand: requested when the scene has people in it.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from ..hookspecs import hookimpl
from .. import CriticParams, Flag, Verdict, fmt_length, fmt_value, make_signal, threshold_verdict
from ...robot.arms import ARMS, UR3E
from ..chunked import Series, judge_in_chunks
from .cobot import carried_ids, nothing_to_judge, part_body_nearest, part_speeds, robot_parts, slow_flagged_moves
from .contact_speed import requested

__all__ = ["SeparationCritic", "register_critics", "protective_separation"]

NAME = "separation"


class Params(CriticParams):
    human_speed_m_s: float = Field(
        1.6, gt=0, description="speed of the approaching person v_h, m/s (ISO 13855:2010, 5.2: K = 1600 mm/s; "
        "ISO/TS 15066:2016 5.5.4.2.3 refers to it)"
    )
    reaction_time_s: float = Field(
        0.1, ge=0, description="reaction time T_r of the person-detecting sensor and the robot's safety controller "
        "together, s (ISO/TS 15066 5.5.4.2.3; depends on the sensor: a safety laser scanner's response time is "
        "some 60-80 ms, plus the controller's cycles; chosen)"
    )
    intrusion_m: float = Field(
        0.208, ge=0, description="intrusion distance C, m (ISO 13855:2010, 6.2.3: C = 8 (d - 14) mm for a "
        "detection capability d of 40 mm, a sensor that detects hands)"
    )
    human_uncertainty_m: float = Field(
        0.1, ge=0, description="position uncertainty of the person Z_d, m (ISO/TS 15066 5.5.4.2.3; the sensor's "
        "measurement tolerance, e.g. a safety laser scanner's; chosen)"
    )
    reduced_speed_m_s: float = Field(
        0.25, gt=0, description="robot speed at or below which it may be closer than S_p (collaborative operation "
        "by power and force limiting, judged by contact_speed), m/s (ISO 10218-1:2011, 5.6: reduced speed 250 mm/s)"
    )
    warn_margin_m: float = Field(
        0.1, ge=0, description="a separation within this of S_p (robot faster than the reduced speed) is a Warning, m "
        "(chosen)"
    )


def _arm_facts(robot) -> tuple[float, float, str]:
    """``(T_s, Z_r, arm)``: the worst published stopping time of joints 0-2 (s), the repeatability (m), and the
    arm whose data they are: the robot's, or the default arm's (UR3e) for an arm without recorded data."""
    spec = ARMS.get(getattr(robot, "name", ""), None)
    if spec is None or not spec.stopping_time_s:
        spec = UR3E
    return max(spec.stopping_time_s), float(spec.pose_repeatability_m or 0.0), spec.name


def protective_separation(v_r: np.ndarray, params: Params, stopping_time_s: float, robot_uncertainty_m: float):
    """``S_p`` (m) for robot speeds toward the person ``v_r`` (m/s): ISO/TS 15066 5.5.4.2.3, formula 2."""
    t_r, t_s = params.reaction_time_s, stopping_time_s
    s_h = params.human_speed_m_s * (t_r + t_s)
    return s_h + v_r * t_r + v_r * t_s + params.intrusion_m + params.human_uncertainty_m + robot_uncertainty_m


class SeparationCritic:
    name = NAME
    description = "Separation between robot and people against the ISO/TS 15066 protective separation distance."
    Params = Params

    def requested(self, execution) -> bool:
        return requested(execution)

    def check(self, execution, params: Params) -> Verdict:
        return judge_in_chunks(self, execution, params)

    def reduction(self, execution, params: Params) -> "_Separations":
        return _Separations(execution, params)


def _separations(execution, params: Params, carried: list[str], t_s: float, z_r: float):
    """``(speed, sep, s_p, who, v_toward)`` ``(T,)`` of ``execution`` (a chunk of a run, with the run's
    ``carried`` objects): the fastest part's speed (m/s), the separation from the closest person by
    ``S - S_p`` (m), its S_p (m), that person's index and the robot's speed toward them (m/s)."""
    from ...humans import scene_bodies  # here: the critic is on demand (people in the scene)

    trajectory = execution.trajectory
    time = trajectory.time
    parts = robot_parts(execution, carried)
    speed = part_speeds(parts, time).max(axis=1)  # (T,) fastest part, m/s
    T = len(trajectory)
    sep, s_p, who = np.full(T, np.inf), np.zeros(T), np.zeros(T, dtype=np.int64)
    v_toward = np.zeros(T)
    for b, body in enumerate(scene_bodies(execution.scene)):
        d = part_body_nearest(parts, body)  # (T, P) part to person
        closing = np.zeros(d.shape)
        with np.errstate(invalid="ignore"):
            closing[1:] = np.nan_to_num(-(d[1:] - d[:-1]) / np.diff(time)[:, None], nan=0.0, posinf=0.0,
                                        neginf=0.0)  # fmt: skip
        v_r = np.clip(closing, 0.0, None).max(axis=1)
        s = d.min(axis=1)
        sp = protective_separation(v_r, params, t_s, z_r)
        closer = (s - sp) < (sep - s_p)
        sep, s_p, v_toward = np.where(closer, s, sep), np.where(closer, sp, s_p), np.where(closer, v_r, v_toward)
        who[closer] = b
    return speed, sep, s_p, who, v_toward


class _Separations:
    """The separation judgement, chunk by chunk (speeds need the sample before: the chunk's halo): the
    per-sample separation, S_p, closest person and speeds, judged as a whole at the end."""

    def __init__(self, execution, params: Params):
        self.execution, self.params = execution, params
        self.nothing = nothing_to_judge(NAME, execution, "shapes")
        if self.nothing is not None:
            return
        self.facts = _arm_facts(execution.robot)
        self.carried = carried_ids(execution.trajectory)
        T = len(execution.trajectory)
        self.series = [Series(T), Series(T, fill=np.inf), Series(T), Series(T, dtype=np.int64, fill=0), Series(T)]

    def add(self, chunk, execution) -> None:
        if self.nothing is not None:
            return
        t_s, z_r, _ = self.facts
        for series, values in zip(self.series, _separations(execution, self.params, self.carried, t_s, z_r)):
            series.put(chunk.start, values[chunk.own])

    def verdict(self) -> Verdict:
        from ...humans import scene_bodies  # here: the critic is on demand (people in the scene)

        if self.nothing is not None:
            return self.nothing
        params, trajectory = self.params, self.execution.trajectory
        t_s, z_r, stopping_data = self.facts
        time = trajectory.time
        bodies = scene_bodies(self.execution.scene)
        speed, sep, s_p, who, v_toward = (series.values for series in self.series)
        fast = speed > params.reduced_speed_m_s
        err = fast & (sep < s_p)
        warn = fast & (sep < s_p + params.warn_margin_m)
        shortfall = np.where(fast, s_p - sep, -np.inf)
        t = int(np.argmax(shortfall)) if fast.any() else int(np.argmin(sep - s_p))
        body = bodies[int(who[t])]
        signal = make_signal(time, np.where(np.isfinite(sep), sep - s_p, np.nan), label="separation minus "
                             "protective separation distance S_p (closest person)", unit="m", worse="below",
                             warning=params.warn_margin_m, error=0.0)
        details = {"human": body.human, "separation_m": float(sep[t]), "protective_separation_m": float(s_p[t]),
                   "robot_speed_m_s": float(speed[t]), "speed_toward_person_m_s": float(v_toward[t]),
                   "stopping_time_s": t_s, "robot_uncertainty_m": z_r, "stopping_data_of": stopping_data,
                   "reduced_speed_m_s": params.reduced_speed_m_s}
        at = (f"{body.human} is {fmt_length(float(sep[t]))} from the robot at {time[t]:.2f} s while it moves at "
              f"{speed[t]:.2f} m/s ({v_toward[t]:.2f} m/s toward them); the protective separation distance there "
              f"is {fmt_length(float(s_p[t]))}")
        common = dict(worst=t, value=float(sep[t]), threshold=float(s_p[t]), unit="m", signal=signal,
                      details=details)
        hint = (f"Slow the robot to at most {fmt_value(params.reduced_speed_m_s)} m/s{{during}} (lib.reduce_speed) "
                "where it comes near the person, or keep it farther away.")
        if err.any():
            return threshold_verdict(NAME, trajectory, Flag.ERROR, err, hint=hint, message=f"{at}: closer than "
                                     "ISO/TS 15066 speed and separation monitoring allows at that speed.", **common)
        if warn.any():
            return threshold_verdict(NAME, trajectory, Flag.WARNING, warn, hint=hint, message=f"{at}: within "
                                     f"{fmt_length(params.warn_margin_m)} of it.", **common)
        return threshold_verdict(NAME, trajectory, Flag.OK, message="The robot keeps the protective separation "
                                 "distance from every person whenever it moves faster than "
                                 f"{fmt_value(params.reduced_speed_m_s)} m/s (closest: {at}).", **common)


@hookimpl
def register_critics(register):
    register(SeparationCritic())


@hookimpl
def robocritics_repairs(verdict, execution, program):  # type: ignore[no-untyped-def]
    """The flagged moves slowed to the reduced speed, at which the robot may come closer than S_p."""
    speed = (verdict.details or {}).get("robot_speed_m_s") if verdict.critic == NAME else None
    if not speed:
        return []
    reduced = (verdict.details or {}).get("reduced_speed_m_s", Params().reduced_speed_m_s)
    return slow_flagged_moves(verdict, execution, reduced / speed)
