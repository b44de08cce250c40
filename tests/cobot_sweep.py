"""A sweep of the UR3e past a standing operator, for the collaborative-operation critic tests.

The base joint turns at a constant rate so that the fastest link frame moves at ``speed_m_s`` (the tool, fingers
down, at abdomen height); the operator stands facing the robot's base, placed so that the robot passes
``clearance_m`` in front of their abdomen at the middle of the sweep (or ``distance_m`` from the base instead).
"""

from __future__ import annotations

import math

import numpy as np

from robocritics.execution import Execution
from robocritics.humans import body_model
from robocritics.robot.model import Robot
from robocritics.scene import Human, Scene

ROBOT = Robot.ur3e()
HEIGHT_M, FLOOR_M = 1.75, -0.75
ABDOMEN_Z = FLOOR_M + 0.60 * HEIGHT_M  # the abdomen capsule's axis height (humans.py)
SWEEP_RAD = 1.2  # the base turns from -0.6 to +0.6 rad


def _start_q() -> np.ndarray:
    return np.asarray(ROBOT.ik((0.34, 0.0, ABDOMEN_Z - 0.05)), float)  # fingers down


def sweep(speed_m_s: float, rate_hz: float = 125.0):
    """``(q (T, 6), time (T,))``: the base turning through SWEEP_RAD with the fastest link frame at ``speed_m_s``."""
    q0 = _start_q()
    frames = ROBOT.forward(q0[None])[0]
    radius = float(np.max(np.hypot(frames[:, 0, 3], frames[:, 1, 3])))  # farthest frame origin from the z axis
    omega = speed_m_s / radius
    duration = SWEEP_RAD / omega
    time = np.arange(0.0, duration + 1e-12, 1.0 / rate_hz)
    q = np.tile(q0, (len(time), 1))
    q[:, 0] = q0[0] - SWEEP_RAD / 2 + omega * time
    return q, time


def operator(distance_m: float) -> Human:
    """An operator with their back to the robot (the trunk's back is in the chest, abdomen and pelvis capsules), feet
    ``distance_m`` from the base along +x, facing away from it."""
    return Human(id="operator", position=(distance_m, 0.0), yaw_rad=0.0, height_m=HEIGHT_M, floor_z_m=FLOOR_M)


def execution(speed_m_s: float, *, clearance_m: float | None = 0.02, distance_m: float | None = None) -> Execution:
    """The sweep at ``speed_m_s`` past an operator ``clearance_m`` from the robot (or ``distance_m`` from the base)."""
    q, time = sweep(speed_m_s)
    if distance_m is None:
        distance_m = _distance_for_clearance(clearance_m)
    scene = Scene(humans=[operator(distance_m)])
    trajectory = ROBOT.trajectory(q, time, scene)
    return Execution(trajectory=trajectory, plan=None, events=[], final_scene=scene, scene=scene, robot=ROBOT,
                     source="test sweep")


def _distance_for_clearance(clearance_m: float) -> float:
    """Feet distance from the base at which the robot's closest approach to the abdomen is ``clearance_m``."""
    from robocritics.geometry.kernels import capsule_capsule

    q, _ = sweep(1.0)
    mid = q[len(q) // 2][None]
    p0, p1 = ROBOT.capsule_segments(ROBOT.forward(mid))
    radii = np.array([c.radius_m for c in ROBOT.capsules])

    def gap(d: float) -> float:
        body = body_model(operator(d))
        k = body.names.index("abdomen")
        return float(capsule_capsule(p0[0], p1[0], radii, body.p0[k], body.p1[k], body.radius_m[k]).min())

    lo, hi = 0.3, 1.5
    for _ in range(60):
        mid_d = (lo + hi) / 2
        lo, hi = (mid_d, hi) if gap(mid_d) < clearance_m else (lo, mid_d)
    return (lo + hi) / 2
