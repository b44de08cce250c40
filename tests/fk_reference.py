"""Slow, obvious references for forward kinematics: Pinocchio per sample, and capsule endpoints per sample."""

from __future__ import annotations

import numpy as np
import pinocchio as pin


def pinocchio_frames(robot, q, opening=None) -> np.ndarray:
    """``(T, L, 4, 4)``: Pinocchio's body frames per sample of ``q (T, n)``, the fingers slid
    ``(max_opening - opening) / 2`` inwards along tcp y (as ``Robot.forward``); ``opening (T,)`` m or None."""
    data = robot.model.createData()
    ids = [robot.model.getFrameId(name, pin.FrameType.BODY) for name in robot.frame_names]
    out = np.empty((len(q), len(ids), 4, 4))
    for t in range(len(q)):
        pin.framesForwardKinematics(robot.model, data, np.asarray(q[t], dtype=float))
        for i, fid in enumerate(ids):
            out[t, i] = data.oMf[fid].homogeneous
        if opening is not None:
            slide = (robot.max_opening_m - opening[t]) / 2 * out[t, robot.tcp_index, :3, 1]
            for sign, link in zip((1.0, -1.0), robot.finger_links):
                out[t, robot.frame_names.index(link), :3, 3] -= sign * slide
    return out


def capsule_reference(robot, frames) -> tuple[np.ndarray, np.ndarray]:
    """Per sample and capsule: the frame's 4x4 pose times the homogeneous endpoint ``[x; 1]``, ``(T, C, 3)`` each."""
    T, C = len(frames), len(robot.capsules)
    p0, p1 = np.empty((T, C, 3)), np.empty((T, C, 3))
    for t in range(T):
        for c, capsule in enumerate(robot.capsules):
            pose = frames[t, robot.frame_names.index(capsule.frame)]
            p0[t, c] = (pose @ np.append(capsule.p0, 1.0))[:3]
            p1[t, c] = (pose @ np.append(capsule.p1, 1.0))[:3]
    return p0, p1
