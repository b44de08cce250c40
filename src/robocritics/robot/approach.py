"""Approach directions: which way the fingers point when the planner puts the TCP at a point. rad, m.

Every skill moves the TCP "fingers down" on a UR arm. An arm whose wrist cannot point its fingers straight
down everywhere on its table (a 5-joint arm, a long tool on a short arm, a wrist with offsets) approaches
**tilted**: the finger direction ``f`` leans from straight down towards the point's side of the base, by the
tilt ``theta`` in the vertical plane through the base's vertical axis and the point::

    u = (p_xy - s_xy) / |p_xy - s_xy|            horizontal unit vector from the shoulder s out to the point p
    f = cos(theta) (0, 0, -1) + sin(theta) u     (theta = 0: straight down; pi/2: horizontal, pointing outwards)
    R = Rot(u x z, theta) @ fingers_down(yaw)    the fingers-down frame turned about the horizontal u x z

so the fingers reach *over* the object as a person's hand does, and still close along the same yaw. The tilt
is a per-arm list, :attr:`Robot.approach_tilts_rad`: the planner starts at its first and moves on to the next
when a move's target is out of reach at the current one (docs/robots.md, "Approach directions"). The bundled
arms have fingers down only, ``(0,)``; a URDF arm's is given to :meth:`Robot.from_urdf` as
``approach_tilts_rad=`` or inferred (:func:`infer_tilts`: from the least tilt of :data:`TILT_LADDER_RAD` at
which the arm reaches probe points of a tabletop pick, up the ladder). The critics judge the real finger
direction (the TCP frame's z in the trace), tilted or not.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["TILT_LADDER_RAD", "approach_rotation", "fingers_down", "infer_tilts", "probe_points", "turn_rates"]

#: The tilts (rad from straight down) an approach may take, in the order they are tried: 0, 15, ... 90 degrees.
TILT_LADDER_RAD = tuple(math.radians(d) for d in (0, 15, 30, 45, 60, 75, 90))


def fingers_down(yaw_rad: float = 0.0) -> np.ndarray:
    """Rotation with the finger direction (tcp +z) pointing straight down, turned by ``yaw_rad`` about z."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    # Rz(yaw) @ Rx(pi)
    return np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])


def approach_rotation(position, yaw_rad: float, tilt_rad: float, shoulder) -> np.ndarray:
    """The TCP rotation at ``position`` (m) for yaw ``yaw_rad`` and tilt ``tilt_rad`` (module docstring): exactly
    :func:`fingers_down` at tilt 0, or above the shoulder (no side to lean to)."""
    R = fingers_down(yaw_rad)
    if tilt_rad == 0.0:
        return R
    ux, uy = position[0] - shoulder[0], position[1] - shoulder[1]
    norm = math.hypot(ux, uy)
    if norm < 1e-9:
        return R
    # Rodrigues about the horizontal unit h = u x z = (uy, -ux, 0)/|u|: Rot = c I + s [h]x + (1 - c) h hᵀ,
    # written out (the numpy products cost several times this on 3x3 matrices, and tracking calls it per point)
    hx, hy = uy / norm, -ux / norm
    c, s = math.cos(tilt_rad), math.sin(tilt_rad)
    k = 1.0 - c
    rot = np.array([[c + k * hx * hx, k * hx * hy, s * hy],
                    [k * hx * hy, c + k * hy * hy, -s * hx],
                    [-s * hy, s * hx, c]])
    return rot.dot(R)


def turn_rates(robot, q) -> tuple[float, float]:
    """``(base_turn_sign, wrist_yaw_per_rad)`` of :class:`~robocritics.robot.model.Robot` at ``q`` (rad): the
    vertical component of the first and of the last joint's axis in the world, rounded to +-1 (or 0 when the
    axis is more horizontal than vertical), so that the planner turns a posture to face a target exactly."""
    import pinocchio as pin

    model, data = robot.model, robot.model.createData()
    pin.forwardKinematics(model, data, np.asarray(q, float))
    out = []
    for j in (1, model.njoints - 1):
        _, axis = robot._joint_motion[j]
        vertical = float((data.oMi[j].rotation @ (axis / np.linalg.norm(axis)))[2])
        out.append(math.copysign(1.0, vertical) if abs(vertical) > 0.5 else 0.0)
    return out[0], out[1]


def probe_points(robot) -> np.ndarray:
    """Points a tabletop pick visits, scaled as docs/robots.md scales the UR3e's layout (by reach / 0.6 m): 0.35
    and 0.4 x that out in front of the shoulder and 0.3 rad to either side, 2 cm and 17 cm above the table."""
    s = robot.reach_m / 0.6
    out = []
    for radius in (0.35 * s, 0.4 * s):
        for height in (0.02, 0.17):
            for heading in (0.0, 0.3, -0.3):
                out.append((robot.shoulder_m[0] + radius * math.cos(heading), robot.shoulder_m[1] + radius * math.sin(heading), height))
    return np.array(out)


def infer_tilts(robot) -> tuple[float, ...]:
    """The tilts a URDF arm approaches at, in the order the planner tries them: from the least tilt of
    :data:`TILT_LADDER_RAD` at which it reaches every :func:`probe_points` (each seeded from home) up the rest
    of the ladder, then the lesser tilts, nearest first; the whole ladder when no tilt reaches them all (the
    planner then finds each move's own). The lesser tilts stay: a 5-joint arm with a long tool that leans 60
    deg above an object may reach its foot only at 30 deg, and a straight line down turns the fingers between
    the two (:meth:`~robocritics.planning.planner.Planner.retilted_line`)."""
    from ..errors import PlanningError

    points = probe_points(robot)
    for k, tilt in enumerate(TILT_LADDER_RAD):
        try:
            for p in points:
                robot.ik(p, seed=robot.home_q, tilt_rad=tilt)
        except PlanningError:
            continue
        return TILT_LADDER_RAD[k:] + TILT_LADDER_RAD[:k][::-1]
    return TILT_LADDER_RAD
