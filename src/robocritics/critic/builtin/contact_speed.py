r"""Contact speed: power and force limiting, transient contact (ISO/TS 15066:2016, 5.5.5 and Annex A).

For every person in the scene (:mod:`robocritics.humans`: the body regions of Annex A as capsules), every robot
part (the model's capsules) and every carried object (a sphere around it while held), at every sample ``t``:

* ``d_{t,p,k}``: the distance between part ``p`` and body capsule ``k``, m;
* the part is *closing in* on capsule ``k`` when ``d_{t,p,k} < d_{t-1,p,k}`` and ``d_{t,p,k} <= near_m``;
* its contact speed is then its speed ``v_{t,p}`` (the faster end of its segment, m/s). The whole speed,
  not only the component along the line between the closest points: the person's position is known only to
  within ``near_m`` and people move, so the direction in which a closing part would strike is not known;
* the limit is ``v_max = F_max / sqrt(mu k)``, ``mu = (1/m_H + 1/m_R)^-1``, ``m_R = M/2 + m_L``
  (:func:`robocritics.humans.transient_speed_limit`): F_max the transient force of the region (2 x Table
  A.2), k its effective spring constant (Annex A), m_H its effective mass (Table A.3), M the robot's moving
  mass and m_L its tool plus the carried object's ``mass_kg`` at ``t``. Skull and forehead, and face: no contact is permitted (Table A.2: transient contact
  not applicable), so the limit there is 0 m/s.

Flags: ERROR when any contact speed exceeds its limit (or any part closes in on the head); WARNING when one
exceeds ``warn_fraction`` of it; OK otherwise, and OK with "nothing to check" when the scene has no people.
The evidence names the region, the person, the part, the speed and the limit.

It is an on-demand critic: ``requested(execution)`` is true when the scene has people in it, so every run in
such a scene is judged and other runs are not slowed down. Like other critics beside the paper's five, it is
not part of the 0-10 score but counts toward pass/fail.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from ..hookspecs import hookimpl
from .. import CriticParams, Flag, Verdict, fmt_value, make_signal, threshold_verdict
from .cobot import nothing_to_judge, carried_mass, part_body_distances, part_speeds, robot_masses, robot_parts, slow_flagged_moves

__all__ = ["ContactSpeedCritic", "register_critics", "contact_speeds"]

NAME = "contact_speed"


class Params(CriticParams):
    near_m: float = Field(
        0.10,
        gt=0,
        le=1.0,
        description="possible-contact distance, m: a part this close to a body region and closing in could touch "
        "it (the body model's position uncertainty plus body sway; chosen, ISO/TS 15066 gives none)",
    )
    warn_fraction: float = Field(
        0.75,
        gt=0,
        le=1.0,
        description="fraction of the ISO/TS 15066 Annex A speed limit above which a contact speed is a Warning "
        "(a 25 % margin for the body model's and the speed estimate's uncertainty; chosen)",
    )


def requested(execution) -> bool:
    """Whether the run's scene has people in it (then the collaborative-operation critics judge it)."""
    return bool(getattr(execution.scene, "humans", ()))


def contact_speeds(execution, params: Params):
    """Per person: ``(body, speed (T, P, K) m/s, limit (T, K) m/s, parts)``: contact speed of each part on each
    body capsule (0 when not closing in within ``near_m``) and the region's limit at each sample."""
    from ...humans import BODY_REGIONS, scene_bodies, transient_speed_limit  # here: the critic is on demand

    trajectory, robot = execution.trajectory, execution.robot
    parts = robot_parts(execution)
    speed = part_speeds(parts, trajectory.time)  # (T, P)
    moving_kg, tool_kg = robot_masses(robot)
    payload_kg, _ = carried_mass(execution)
    payload_kg = payload_kg + tool_kg  # (T,) m_L: tool and workpiece
    out = []
    for body in scene_bodies(execution.scene):
        d = part_body_distances(parts, body, within_m=params.near_m)  # (T, P, K), exact up to near_m
        closing = np.zeros(d.shape, dtype=bool)
        closing[1:] = d[1:] < d[:-1]
        contact = np.where(closing & (d <= params.near_m), speed[:, :, None], 0.0)
        limit = np.empty((len(trajectory), len(body)))
        for k, region in enumerate(body.regions):
            r = BODY_REGIONS[region]
            for m in np.unique(payload_kg):
                limit[payload_kg == m, k] = transient_speed_limit(r, moving_kg, float(m))
        out.append((body, contact, limit, parts))
    return out


class ContactSpeedCritic:
    name = NAME
    description = "Speed of robot parts closing in on a person's body regions against ISO/TS 15066 Annex A limits."
    Params = Params

    def requested(self, execution) -> bool:
        return requested(execution)

    def check(self, execution, params: Params) -> Verdict:
        from ...humans import BODY_REGIONS, LIMITS_SOURCE  # here: the critic is on demand (people in the scene)

        trajectory = execution.trajectory
        nothing = nothing_to_judge(NAME, execution, "shapes and masses")
        if nothing is not None:
            return nothing
        T = len(trajectory)
        worst = (0.0, 0, 0, 0, None)  # ratio, sample, part, capsule, per-person result
        ratio_series = np.zeros(T)
        over_warn = np.zeros(T, dtype=bool)
        over_err = np.zeros(T, dtype=bool)
        for body, contact, limit, parts in contact_speeds(execution, params):
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(contact > 0, contact / limit[:, None, :], 0.0)  # inf on the head
            per_sample = ratio.max(axis=(1, 2))
            ratio_series = np.maximum(ratio_series, np.where(np.isfinite(per_sample), per_sample, 1e9))
            over_err |= per_sample > 1.0
            over_warn |= per_sample > params.warn_fraction
            flat = int(np.argmax(np.where(np.isfinite(ratio), ratio, 1e9)))
            t, p, k = np.unravel_index(flat, ratio.shape)
            r = float(ratio[t, p, k])
            if r > worst[0]:
                worst = (r, int(t), int(p), int(k), (body, contact, limit, parts))
        signal = make_signal(trajectory.time, np.minimum(ratio_series, 10.0), label="contact speed / ISO/TS 15066 "
                             "limit (worst part and body region)", unit="fraction of limit",
                             warning=params.warn_fraction, error=1.0)
        r, t, p, k, found = worst
        if found is None:
            return threshold_verdict(NAME, trajectory, Flag.OK, worst=0, signal=signal, value=0.0, threshold=1.0,
                                     unit="fraction of limit",
                                     message=f"No robot part closes in on a person within {fmt_value(params.near_m)} m.")
        body, contact, limit, parts = found
        region = BODY_REGIONS[body.regions[k]]
        speed, vmax = float(contact[t, p, k]), float(limit[t, k])
        where = (f"the {parts.names[p]} closes in on {body.human}'s {region.label} ({body.names[k]}) at "
                 f"{speed:.3f} m/s at {trajectory.time[t]:.2f} s")
        details = {"human": body.human, "region": region.name, "body_capsule": body.names[k], "part": parts.names[p],
                   "speed_m_s": speed, "limit_m_s": vmax, "source": LIMITS_SOURCE}
        common = dict(worst=t, links=[parts.names[p]], signal=signal, details=details)
        hint = ("Slow the robot{during} (lib.reduce_speed), or keep it farther from the person's "
                + region.label + ".")
        if not region.contact_permitted:
            return threshold_verdict(NAME, trajectory, Flag.ERROR, over_err, value=speed, threshold=0.0, unit="m/s",
                                     message=f"{where}: ISO/TS 15066 permits no contact with the {region.label}.",
                                     hint="Keep the robot away from the person's head{during}.", **common)
        if r > 1.0:
            flag, samples, said = Flag.ERROR, over_err, "above"
        elif r > params.warn_fraction:
            flag, samples, said = Flag.WARNING, over_warn, f"above {fmt_value(100 * params.warn_fraction)} % of"
        else:
            return threshold_verdict(NAME, trajectory, Flag.OK, value=speed, threshold=vmax, unit="m/s",
                                     message=f"Contact speeds stay within {fmt_value(100 * params.warn_fraction)} % "
                                     f"of the ISO/TS 15066 limits (at most {100 * r:.0f} %: {where}, limit "
                                     f"{vmax:.3f} m/s).", **common)
        return threshold_verdict(NAME, trajectory, flag, samples, value=speed, threshold=vmax, unit="m/s",
                                 message=f"{where}, {said} the ISO/TS 15066 transient-contact limit of {vmax:.3f} m/s "
                                 f"for the {region.label}.", hint=hint, **common)


@hookimpl
def register_critics(register):
    register(ContactSpeedCritic())


@hookimpl
def robocritics_repairs(verdict, execution, program):  # type: ignore[no-untyped-def]
    """The flagged moves slowed under the region's limit (no slowdown makes contact with the head acceptable)."""
    if verdict.critic != NAME or not verdict.value or not verdict.threshold:
        return []
    return slow_flagged_moves(verdict, execution, verdict.threshold / verdict.value)
