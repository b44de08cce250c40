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
from ..chunked import Extreme, judge_in_chunks
from .cobot import (
    carried_ids,
    carried_mass,
    nothing_to_judge,
    part_body_near,
    part_speeds,
    robot_masses,
    robot_parts,
    slow_flagged_moves,
)

__all__ = ["ContactSpeedCritic", "register_critics", "contact_cells", "contact_speeds"]

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


def contact_cells(execution, params: Params, carried: list[str] | None = None, payload_kg=None):
    """Per person: ``(body, (rows, p, k), speed (n,) m/s, limit (T, K) m/s, parts)``: the (sample, part, body
    capsule) triples, in C order of ``(T, P, K)``, where a moving part closes in within ``near_m`` and its
    speed there (> 0), and the region's limit at each sample. ``carried`` and ``payload_kg`` (the carried parts
    and the tool and workpiece mass ``(T,)`` kg) are a chunk's of the whole run's (default: ``execution``'s own).

    A triple closes in when its exact distance is ``<= near_m`` and below the sample before's
    (:func:`~.cobot.part_body_near` holds both); a part with a speed is present at both samples.
    """
    from ...humans import BODY_REGIONS, scene_bodies, transient_speed_limit  # here: the critic is on demand

    trajectory, robot = execution.trajectory, execution.robot
    parts = robot_parts(execution, carried)
    speed = part_speeds(parts, trajectory.time)  # (T, P)
    moving_kg, tool_kg = robot_masses(robot)
    if payload_kg is None:
        payload_kg = carried_mass(execution)[0] + tool_kg  # (T,) m_L: tool and workpiece
    P = len(parts.names)
    out = []
    for body in scene_bodies(execution.scene):
        rows, p, k, d = part_body_near(parts, body, params.near_m)
        key = (rows * P + p) * len(body) + k  # sorted: C order
        before = np.minimum(np.searchsorted(key, key - P * len(body)), len(key) - 1)  # (t - 1, p, k), held
        hit = (rows > 0) & (d <= params.near_m)
        hit[hit] = d[hit] < d[before[hit]]
        hit[hit] = speed[rows[hit], p[hit]] > 0
        limit = np.empty((len(trajectory), len(body)))
        for j, region in enumerate(body.regions):
            r = BODY_REGIONS[region]
            for m in np.unique(payload_kg):
                limit[payload_kg == m, j] = transient_speed_limit(r, moving_kg, float(m))
        cells = (rows[hit], p[hit], k[hit])
        out.append((body, cells, speed[cells[0], cells[1]], limit, parts))
    return out


def contact_speeds(execution, params: Params, carried: list[str] | None = None, payload_kg=None):
    """Per person: ``(body, speed (T, P, K) m/s, limit (T, K) m/s, parts)``: contact speed of each part on each
    body capsule (0 when not closing in within ``near_m``) and the region's limit at each sample: the dense form
    of :func:`contact_cells` (same arguments)."""
    out = []
    for body, cells, speed, limit, parts in contact_cells(execution, params, carried, payload_kg):
        contact = np.zeros((len(limit), len(parts.names), len(body)))
        contact[cells] = speed
        out.append((body, contact, limit, parts))
    return out


class ContactSpeedCritic:
    name = NAME
    description = "Speed of robot parts closing in on a person's body regions against ISO/TS 15066 Annex A limits."
    Params = Params

    def requested(self, execution) -> bool:
        return requested(execution)

    def check(self, execution, params: Params) -> Verdict:
        return judge_in_chunks(self, execution, params)

    def reduction(self, execution, params: Params) -> "_Contacts":
        return _Contacts(execution, params)


class _Contacts:
    """The contact-speed judgement, chunk by chunk (closing in needs the sample before: the chunk's halo): the
    worst ratio to its limit per sample, which samples pass either threshold, and per person the worst
    (sample, part, body capsule) with its speed and limit."""

    def __init__(self, execution, params: Params):
        self.execution, self.params = execution, params
        self.nothing = nothing_to_judge(NAME, execution, "shapes and masses")
        if self.nothing is not None:
            return
        trajectory = execution.trajectory
        T = len(trajectory)
        self.carried = carried_ids(trajectory)
        self.payload_kg = carried_mass(execution)[0] + robot_masses(execution.robot)[1]  # (T,) m_L
        self.ratio_series = np.zeros(T)
        self.over_warn = np.zeros(T, dtype=bool)
        self.over_err = np.zeros(T, dtype=bool)
        self.worst_of: list[Extreme] = []  # per person: the worst (sample, part, capsule) of the flattened ratio
        self.parts: tuple[str, ...] = ()

    def add(self, chunk, execution) -> None:
        if self.nothing is not None:
            return
        lo = chunk.lo
        payload = self.payload_kg[lo : lo + len(chunk.trajectory)]
        results = contact_cells(execution, self.params, self.carried, payload)
        if not self.worst_of:
            self.worst_of = [Extreme("max") for _ in results]
        first, stop = chunk.start - lo, chunk.stop - lo  # the own rows
        for b, (body, (rows, p, k), contact, limit, parts) in enumerate(results):
            self.parts = parts.names
            mine = (rows >= first) & (rows < stop)
            rows, p, k, contact = rows[mine] - first, p[mine], k[mine], contact[mine]
            limit = limit[first:stop]
            with np.errstate(divide="ignore"):
                ratio = contact / limit[rows, k]  # inf on the head
            flagged = np.where(np.isfinite(ratio), ratio, 1e9)
            at = chunk.start + rows
            np.maximum.at(self.ratio_series, at, flagged)
            self.over_err[at[ratio > 1.0]] = True
            self.over_warn[at[ratio > self.params.warn_fraction]] = True
            P, K = len(parts.names), len(body)
            if not len(ratio):  # no contact in the chunk: the dense ratio's first cell, 0 (never the worst)
                self.worst_of[b].offer(chunk.start * P * K, np.zeros(1), lambda _: (0.0, 0, 0, 0.0, 0.0))
                continue
            i = int(np.argmax(flagged))  # the first of the largest, in C order as over the dense (T, P, K)
            detail = (float(ratio[i]), int(p[i]), int(k[i]), float(contact[i]), float(limit[rows[i], k[i]]))
            self.worst_of[b].offer(chunk.start * P * K + int((rows[i] * P + p[i]) * K + k[i]), flagged[i : i + 1],
                                   lambda _, detail=detail: detail)

    def verdict(self) -> Verdict:
        from ...humans import BODY_REGIONS, LIMITS_SOURCE, scene_bodies  # here: the critic is on demand

        if self.nothing is not None:
            return self.nothing
        params, trajectory = self.params, self.execution.trajectory
        bodies = scene_bodies(self.execution.scene)
        worst = (0.0, 0, 0, 0, None)  # ratio, sample, part, capsule, (body, speed, limit)
        for body, extreme in zip(bodies, self.worst_of):
            if extreme.detail is None:
                continue
            r, p, k, speed, vmax = extreme.detail
            if r > worst[0]:
                per_sample_cells = len(self.parts) * len(body)
                worst = (r, extreme.index // per_sample_cells, p, k, (body, speed, vmax))
        signal = make_signal(trajectory.time, np.minimum(self.ratio_series, 10.0), label="contact speed / ISO/TS 15066 "
                             "limit (worst part and body region)", unit="fraction of limit",
                             warning=params.warn_fraction, error=1.0)  # fmt: skip
        r, t, p, k, found = worst
        if found is None:
            return threshold_verdict(NAME, trajectory, Flag.OK, worst=0, signal=signal, value=0.0, threshold=1.0,
                                     unit="fraction of limit",
                                     message=f"No robot part closes in on a person within {fmt_value(params.near_m)} m.")  # fmt: skip
        body, speed, vmax = found
        region = BODY_REGIONS[body.regions[k]]
        where = (f"the {self.parts[p]} closes in on {body.human}'s {region.label} ({body.names[k]}) at "
                 f"{speed:.3f} m/s at {trajectory.time[t]:.2f} s")  # fmt: skip
        details = {"human": body.human, "region": region.name, "body_capsule": body.names[k], "part": self.parts[p],
                   "speed_m_s": speed, "limit_m_s": vmax, "source": LIMITS_SOURCE}  # fmt: skip
        common = dict(worst=t, links=[self.parts[p]], signal=signal, details=details)
        hint = ("Slow the robot{during} (lib.reduce_speed), or keep it farther from the person's "
                + region.label + ".")  # fmt: skip
        if not region.contact_permitted:
            return threshold_verdict(NAME, trajectory, Flag.ERROR, self.over_err, value=speed, threshold=0.0, unit="m/s",
                                     message=f"{where}: ISO/TS 15066 permits no contact with the {region.label}.",
                                     hint="Keep the robot away from the person's head{during}.", **common)  # fmt: skip
        if r > 1.0:
            flag, samples, said = Flag.ERROR, self.over_err, "above"
        elif r > params.warn_fraction:
            flag, samples, said = Flag.WARNING, self.over_warn, f"above {fmt_value(100 * params.warn_fraction)} % of"
        else:
            return threshold_verdict(NAME, trajectory, Flag.OK, value=speed, threshold=vmax, unit="m/s",
                                     message=f"Contact speeds stay within {fmt_value(100 * params.warn_fraction)} % "
                                     f"of the ISO/TS 15066 limits (at most {100 * r:.0f} %: {where}, limit "
                                     f"{vmax:.3f} m/s).", **common)  # fmt: skip
        return threshold_verdict(NAME, trajectory, flag, samples, value=speed, threshold=vmax, unit="m/s",
                                 message=f"{where}, {said} the ISO/TS 15066 transient-contact limit of {vmax:.3f} m/s "
                                 f"for the {region.label}.", hint=hint, **common)  # fmt: skip


@hookimpl
def register_critics(register):
    register(ContactSpeedCritic())


@hookimpl
def robocritics_repairs(verdict, execution, program):  # type: ignore[no-untyped-def]
    """The flagged moves slowed under the region's limit (no slowdown makes contact with the head acceptable)."""
    if verdict.critic != NAME or not verdict.value or not verdict.threshold:
        return []
    return slow_flagged_moves(verdict, execution, verdict.threshold / verdict.value)
