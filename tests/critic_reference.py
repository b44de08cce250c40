"""Slow per-sample reference implementations of the five critics, written the obvious way.

Each follows the paper's loops (for every sample, for every link or pair, ...)
in plain Python and returns ``{"flag": Flag, "value": float | None}`` (the
worst measured value in the critic's unit). The vectorised critics must agree
with these; ``benchmarks/bench_critics.py`` times them against each other.
"""

from __future__ import annotations

import math

from scipy.spatial import ConvexHull, QhullError

from robocritics.critic import Flag
from robocritics.robot.model import default_workspace


def ref_joint_speed(traj, params) -> dict:
    """Paper Algorithm 1: per sample pair, per link, |p_t - p_{t-1}| / (tau_t - tau_{t-1})."""
    frames, time, q = traj.frames, traj.time, traj.q
    if params.frames:
        sel = [traj.frame_names.index(n) for n in params.frames]
    else:
        sel = list(range(len(traj.frame_names)))
    limits = traj.limits.velocity_rad_s
    worst_v = 0.0
    worst_ratio, worst_w = -1.0, 0.0
    linear_error = joint_error = warning = False
    for t in range(1, len(time)):
        dt = float(time[t] - time[t - 1])
        for l in sel:
            x0, y0, z0 = (float(frames[t - 1, l, i, 3]) for i in range(3))
            x1, y1, z1 = (float(frames[t, l, i, 3]) for i in range(3))
            v = math.sqrt((x1 - x0) ** 2 + (y1 - y0) ** 2 + (z1 - z0) ** 2) / dt
            worst_v = max(worst_v, v)
            if v > params.max_speed_m_s:
                linear_error = True
            elif v > params.warn_speed_m_s:
                warning = True
        for j in range(q.shape[1]):
            w = abs(float(q[t, j]) - float(q[t - 1, j])) / dt
            ratio = w / limits[j]
            if ratio > worst_ratio:
                worst_ratio, worst_w = ratio, w
            if ratio > 1.0 + params.joint_limit_tolerance:
                joint_error = True
    if linear_error:
        return {"flag": Flag.ERROR, "value": worst_v}
    if joint_error:
        return {"flag": Flag.ERROR, "value": worst_w}
    return {"flag": Flag.WARNING if warning else Flag.OK, "value": worst_v}


def ref_space_usage(traj, scene, params) -> dict:
    """Every link point: outside the workspace sphere is an error; exact hull volume vs 50 % of W."""
    frames = traj.frames
    sel = [traj.frame_names.index(n) for n in params.frames] if params.frames else range(len(traj.frame_names))
    ws = scene.workspace or default_workspace()  # a scene without one: the default arm's reach
    cx, cy, cz = ws.center
    points = set()
    worst_out = -math.inf
    for t in range(len(traj.time)):
        for l in sel:
            p = (float(frames[t, l, 0, 3]), float(frames[t, l, 1, 3]), float(frames[t, l, 2, 3]))
            points.add(p)
            out = math.sqrt((p[0] - cx) ** 2 + (p[1] - cy) ** 2 + (p[2] - cz) ** 2) - ws.radius_m
            worst_out = max(worst_out, out)
    volume = area = 0.0
    if len(points) >= 4:
        try:
            hull = ConvexHull(sorted(points))
            volume, area = float(hull.volume), float(hull.area)
        except (QhullError, ValueError):
            volume = area = 0.0
    if worst_out > params.outside_tolerance_m:
        return {"flag": Flag.ERROR, "value": worst_out, "volume": volume, "area": area}
    limit = params.warn_fraction * ws.volume_m3
    return {"flag": Flag.WARNING if volume > limit else Flag.OK, "value": volume, "volume": volume, "area": area}


def ref_collision(traj, params) -> dict:
    """Every sample, every environment pair not intended at that sample (an intended contact deeper than
    ``contact_tolerance_m`` counts): the closest distance."""
    worst = math.inf
    for t in range(len(traj.time)):
        contacts = set(traj.steps[int(traj.step[t])].contacts) if traj.steps else set()
        held = str(traj.attached[t])
        for k, pair in enumerate(traj.pairs):
            if pair.kind != "environment" or pair.name in params.ignore_pairs:
                continue
            if pair.group_a == "attached" and pair.a != held:
                continue  # that object is not being carried now
            if pair.group_a in ("gripper", "attached") and pair.b_entity != "":
                intended = pair.b_entity in contacts or (held != "" and pair.b_entity == held)
                if intended and float(traj.proximity[t, k]) > -params.contact_tolerance_m:
                    continue  # intended contact, touching within the tolerance
            worst = min(worst, float(traj.proximity[t, k]))
    if worst == math.inf:
        return {"flag": Flag.OK, "value": None}
    if worst <= params.penetration_m:
        flag = Flag.ERROR
    elif worst < params.d_warn_m:
        flag = Flag.WARNING
    else:
        flag = Flag.OK
    return {"flag": flag, "value": worst}


def ref_end_effector_pose(traj, params) -> dict:
    """Every sample: central-difference TCP velocity dotted with the unit finger direction."""
    i = traj.frame_names.index(params.frame or traj.tcp_frame)
    F, time = traj.frames, traj.time
    T = len(time)

    def pos(t):
        return [float(F[t, i, k, 3]) for k in range(3)]

    worst = 0.0
    for t in range(T):
        if T < 2:
            v = [0.0, 0.0, 0.0]
        elif t == 0:
            h = float(time[1] - time[0])
            v = [(b - a) / h for a, b in zip(pos(0), pos(1))]
        elif t == T - 1:
            h = float(time[t] - time[t - 1])
            v = [(b - a) / h for a, b in zip(pos(t - 1), pos(t))]
        else:
            h1 = float(time[t] - time[t - 1])
            h2 = float(time[t + 1] - time[t])
            a = -h2 / (h1 * (h1 + h2))
            b = (h2 - h1) / (h1 * h2)
            c = h1 / (h2 * (h1 + h2))
            v = [a * p0 + b * p1 + c * p2 for p0, p1, p2 in zip(pos(t - 1), pos(t), pos(t + 1))]
        f = [float(F[t, i, k, 2]) for k in range(3)]
        n = math.sqrt(sum(x * x for x in f))
        s = max(0.0, sum(vk * fk / n for vk, fk in zip(v, f)))
        worst = max(worst, s)
    if worst > params.max_speed_m_s:
        flag = Flag.ERROR
    elif worst > params.warn_speed_m_s:
        flag = Flag.WARNING
    else:
        flag = Flag.OK
    return {"flag": flag, "value": worst}


def ref_pinch_point(traj, params) -> dict:
    """Every sample, every self pair (and only those): the closest distance."""
    worst = math.inf
    for t in range(len(traj.time)):
        for k, pair in enumerate(traj.pairs):
            if pair.kind != "self":
                continue
            worst = min(worst, float(traj.proximity[t, k]))
    if worst == math.inf:
        return {"flag": Flag.OK, "value": None}
    if worst < params.d_min_m:
        flag = Flag.ERROR
    elif worst < params.d_max_m:
        flag = Flag.WARNING
    else:
        flag = Flag.OK
    return {"flag": flag, "value": worst}


REFERENCES = {
    "joint_speed": lambda traj, scene, params: ref_joint_speed(traj, params),
    "space_usage": ref_space_usage,
    "collision": lambda traj, scene, params: ref_collision(traj, params),
    "end_effector_pose": lambda traj, scene, params: ref_end_effector_pose(traj, params),
    "pinch_point": lambda traj, scene, params: ref_pinch_point(traj, params),
}
