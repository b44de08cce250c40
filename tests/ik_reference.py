"""Slow obvious references for numeric IK's Newton-first path (robot/ik_numeric.py, robot/ik_track.py), and the
targets the tests draw near a seed."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from robocritics.robot import ik_numeric


def near_seed_postures(robot, rng, count: int, seed_sd_rad: float, made_sd_rad: float):
    """``count`` pairs ``(seed, made)``: a seed ``seed_sd_rad`` (s.d. per joint) from the robot's home and the
    posture that makes the target ``made_sd_rad`` from the seed, both 0.05 rad inside the limits."""
    inner_lo, inner_hi = robot.lower + 0.05, robot.upper - 0.05
    for _ in range(count):
        seed = np.clip(robot.home_q + rng.normal(0, seed_sd_rad, robot.n), inner_lo, inner_hi)
        yield seed, np.clip(seed + rng.normal(0, made_sd_rad, robot.n), inner_lo, inner_hi)


def dls_attempt(robot, target):
    """``attempt(start) -> (q, position error m, rotation error rad)``: numeric IK's damped least squares towards
    the pose ``target`` from ``start``."""
    model, data, fid = robot.model, robot.data, robot._tcp_frame_id
    oMdes, eye = pin.SE3(target[:3, :3], target[:3, 3]), np.eye(6)

    def attempt(start):
        return ik_numeric._dls(model, data, fid, start, target[:3, 3], oMdes, eye, robot.lower, robot.upper,
                               True, 100, 1e-10, 1e-10, 0.5)

    return attempt


def self_motion_descent(robot, target, seed, start):
    """From the solution ``start`` of the pose ``target``, the re-converged null-space descent towards ``seed``
    (``ik_numeric._towards_seed``)."""
    return ik_numeric._towards_seed(robot.model, robot.data, robot._tcp_frame_id, start, seed, robot.lower,
                                    robot.upper, True, dls_attempt(robot, target), 1e-10, 0.5, 6)


def descent_reference(robot, target, seed, made=None):
    """The slow obvious answer that numeric IK's Newton-first path stands in for: damped least squares from the
    seed (from ``made``, the posture that made the target, where that descent does not converge), then the
    re-converged null-space descent towards the seed."""
    q, dp, dr = dls_attempt(robot, target)(np.asarray(seed, float))
    if not (dp <= 1e-10 and dr <= 1e-10):
        q = made
    return self_motion_descent(robot, target, seed, q)
